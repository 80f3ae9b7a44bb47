"""No perchd command blocks past its stated timeout on a path or socket a user names
(docs/contracts.md §6, "How each command ends"): each is one line on stderr and a non-zero
exit, never a hang, never a traceback.

Paths: every option of perchd/commands that names a file or directory, given a FIFO (where a
plain open() blocks), /dev/zero (where a plain read() never ends) and a directory (or, for a
directory option, a FIFO and /dev/zero). The plan argument of `plan check`, `fly` and `sim
--campaign`, `fly --state` and `fly --log` are swept in test_bounded_inputs.py and
test_outputs_safe.py. Sockets: a UDP port bound by nobody, one bound and never answered, a
TCP port that accepts and never answers, and Unix sockets that are silent, trickle, flood
or answer nonsense, against each command's own timeout."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PLAN = ROOT / "plans" / "case1-ipts-n3.json"
FAKE_CF2 = ROOT / "tests" / "sim" / "fake_cf2.py"

START_S = 8.0
"""[s] the interpreter, imports and argument checks on a loaded 2-core machine, beyond
the command's own timeout."""
AT_ONCE_S = 20.0
"""[s] a refusal that needs no wait: an upper bound that only a hang exceeds."""

SIM = ["--driver", "sim://", "--mocap", "sim://"]
ROBUST = "--tau-s -0.5 --v-contact 0.7 1.0 --v-max 2.5 --a-max 1.4".split()


def perchd(args: list[str], cwd: Path, bound_s: float) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.monotonic()
    try:
        out = subprocess.run(
            [sys.executable, "-m", "perchd", *args],
            capture_output=True,
            text=True,
            timeout=bound_s + 30,
            cwd=cwd,
            stdin=subprocess.DEVNULL,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"perchd {' '.join(args)}: still running {bound_s + 30:g} s on")
    return out, time.monotonic() - t0


def refused(out: subprocess.CompletedProcess, took_s: float, bound_s: float) -> str:
    """Its one line on stderr, once the rest is checked."""
    assert "Traceback" not in out.stderr, out.stderr
    assert out.returncode in (1, 2), out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert lines[0].startswith("perchd "), lines[0]
    assert took_s <= bound_s, f"{took_s:.1f} s, over {bound_s:g} s: {lines[0]}"
    return lines[0]


# -- paths ---------------------------------------------------------------------------------


@pytest.fixture
def places(tmp_path) -> dict[str, str]:
    """A FIFO, /dev/zero and a directory; a flight log and a campaign table to read."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    (tmp_path / "adir").mkdir()
    return {"fifo": str(fifo), "/dev/zero": "/dev/zero", "dir": str(tmp_path / "adir")}


def flown(tmp: Path) -> tuple[Path, Path]:
    """A flight log and a campaign table, made once per test that reads them."""
    log, table = tmp / "f0.jsonl", tmp / "t0.csv"
    for args in (
        ["fly", str(PLAN), *SIM, "--log", str(log)],
        ["sim", "--campaign", str(PLAN), "--flights", "1", "--table", str(table)],
    ):
        out = subprocess.run(
            [sys.executable, "-m", "perchd", *args], capture_output=True, text=True, cwd=tmp
        )
        assert out.returncode == 0, out.stderr
    return log, table


PATH = "{}"
"""Where the swept path goes in an argv."""

FILE_OPTIONS = {
    "plan ipts --out": [
        *"plan ipts --x0 -3 --v0 1.5 --order 3".split(),
        *ROBUST,
        "--out",
        PATH,
    ],
    "plan robust --out": [
        *"plan robust --x0 -3.9 -3.7 --v0 1.8 2.0 --maxiter 1".split(),
        *ROBUST,
        "--out",
        PATH,
    ],
    "plan robust --start": [
        *"plan robust --x0 -3.8 --v0 1.9 --maxiter 1".split(),
        *ROBUST,
        "--start",
        PATH,
        "--out",
        "r.json",
    ],
    "plan library --out": [
        *"plan library --x0 -3.3 -2.7 --v0 1.3 1.7 --nodes 2 2".split(),
        *ROBUST,
        "--out",
        PATH,
    ],
    "plan check --plot": ["plan", "check", str(PLAN), "--plot", PATH],
    "fly --config": ["fly", str(PLAN), *SIM, "--config", PATH, "--log", "f.jsonl"],
    "vehicle show --state": ["vehicle", "show", "v1", "--state", PATH],
    "vehicle forget --state": ["vehicle", "forget", "v1", "--state", PATH],
    "sim --campaign --config": [
        *f"sim --campaign {PLAN} --flights 1 --table t.csv".split(),
        "--config",
        PATH,
    ],
    "sim --campaign --table": [
        *f"sim --campaign {PLAN} --flights 1 --force".split(),
        "--table",
        PATH,
    ],
    "sim report": ["sim", "report", PATH],
    "sim firmware --cf2": ["sim", "firmware", "--cf2", PATH],
    "sim firmware --arducopter": ["sim", "firmware", "--arducopter", PATH],
    "sim firmware --defaults": [
        *f"sim firmware --arducopter {FAKE_CF2}".split(),
        "--defaults",
        PATH,
    ],
    "sim firmware --fw-log": [*f"sim firmware --cf2 {FAKE_CF2}".split(), "--fw-log", PATH],
    "serve --config": ["serve", "--config", PATH],
    "serve --socket": [
        *"serve --driver sim:// --mocap sim:// --log-dir . --plan-dir .".split(),
        "--socket",
        PATH,
    ],
    "ctl --socket": ["ctl", "--socket", PATH, "status"],
    "failsafe --config": ["failsafe", "--config", PATH],
    "log summary": ["log", "summary", PATH],
    "log plot": ["log", "plot", PATH],
    "log plot --out": ["log", "plot", "f0.jsonl", "--out", PATH],
    "log export": ["log", "export", PATH, "--mcap", "x.mcap"],
    "log export --mcap": ["log", "export", "f0.jsonl", "--mcap", PATH],
}
"""Options naming a file, with the rest of a command line that would otherwise run."""

DIR_OPTIONS = {
    "sim --campaign --logs": [
        *f"sim --campaign {PLAN} --flights 1 --table t.csv".split(),
        "--logs",
        PATH,
    ],
    "sim report --plots": ["sim", "report", "t0.csv", "--plots", PATH],
    "sim firmware --px4": ["sim", "firmware", "--px4", PATH],
    "serve --log-dir": [
        *"serve --driver sim:// --mocap sim:// --socket s.sock --plan-dir .".split(),
        "--log-dir",
        PATH,
    ],
    "serve --plan-dir": [
        *"serve --driver sim:// --mocap sim:// --socket s.sock --log-dir .".split(),
        "--plan-dir",
        PATH,
    ],
}
"""Options naming a directory."""

READS_A_LOG = ("log plot --out", "log export --mcap", "sim report --plots")


def sweep(argv: list[str], path: str) -> list[str]:
    return [a.replace(PATH, path) for a in argv]


@pytest.mark.parametrize("kind", ["fifo", "/dev/zero", "dir"])
@pytest.mark.parametrize("option", sorted(FILE_OPTIONS))
def test_a_file_option_naming_a_fifo_a_device_or_a_directory_is_one_line(
    option, kind, places, tmp_path
):
    if option in READS_A_LOG:
        flown(tmp_path)
    out, took = perchd(sweep(FILE_OPTIONS[option], places[kind]), tmp_path, AT_ONCE_S)
    line = refused(out, took, AT_ONCE_S)
    assert places[kind] in line or option.split()[-1] in line, line


@pytest.mark.parametrize("kind", ["fifo", "/dev/zero"])
@pytest.mark.parametrize("option", sorted(DIR_OPTIONS))
def test_a_directory_option_naming_a_fifo_or_a_device_is_one_line(option, kind, places, tmp_path):
    if option in READS_A_LOG:
        flown(tmp_path)
    out, took = perchd(sweep(DIR_OPTIONS[option], places[kind]), tmp_path, AT_ONCE_S)
    line = refused(out, took, AT_ONCE_S)
    assert places[kind] in line, line


# -- sockets -------------------------------------------------------------------------------


class Listeners:
    """Sockets that never answer as a perchd peer would, kept open for the test."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.held: list[socket.socket] = []
        self.closed = threading.Event()

    def silent_tcp(self) -> int:
        """A TCP port that accepts and then says nothing."""
        s = self._keep(socket.socket())
        s.bind(("127.0.0.1", 0))
        s.listen(16)
        self._serve(s, lambda c: None)
        return s.getsockname()[1]

    def silent_udp(self) -> int:
        """A UDP port bound and never answered (no ICMP refusal either)."""
        s = self._keep(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]

    def dead_udp(self) -> int:
        """A UDP port nobody has bound."""
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]

    def unix(self, behaviour: str) -> str:
        """A Unix stream socket that is `silent`, `trickles` a byte every 0.2 s and never
        ends a line, `floods` bytes without one, or answers `nonsense`."""
        path = str(self.tmp / f"{behaviour}.sock")
        s = self._keep(socket.socket(socket.AF_UNIX))
        s.bind(path)
        s.listen(16)
        self._serve(s, getattr(self, f"_{behaviour}"))
        return path

    def _silent(self, c: socket.socket) -> None:
        pass

    def _trickles(self, c: socket.socket) -> None:
        while not self.closed.wait(0.2):
            c.send(b" ")

    def _floods(self, c: socket.socket) -> None:
        while not self.closed.is_set():
            c.send(b"x" * 65536)

    def _nonsense(self, c: socket.socket) -> None:
        c.recv(65536)
        c.send(b"not json\n")

    def _keep(self, s: socket.socket) -> socket.socket:
        self.held.append(s)
        return s

    def _serve(self, s: socket.socket, talk) -> None:
        def accept() -> None:
            while not self.closed.is_set():
                try:
                    c, _ = s.accept()
                except OSError:
                    return
                self._keep(c)
                threading.Thread(target=self._quietly, args=(talk, c), daemon=True).start()

        threading.Thread(target=accept, daemon=True).start()

    @staticmethod
    def _quietly(talk, c: socket.socket) -> None:
        try:
            talk(c)
        except OSError:
            pass  # the client gave up: what is being tested

    def close(self) -> None:
        self.closed.set()
        for s in self.held:
            s.close()


@pytest.fixture
def listeners(tmp_path) -> Iterator[Listeners]:
    net = Listeners(tmp_path)
    yield net
    net.close()


def at(scheme: str, port: int, query: str = "") -> str:
    return f"{scheme}127.0.0.1:{port}{query}"


def socket_cases(net: Listeners) -> dict[str, tuple[list[str], float]]:
    """argv and the command's stated timeout [s] for each URI option against each kind of
    peer that never answers."""
    tcp, udp, dead = net.silent_tcp(), net.silent_udp(), net.dead_udp()
    zmq_mocap = at("zmq://", tcp, "?body=cf1")
    natnet = at("natnet://", udp, "?body=cf1&timeout=1")

    def fly(driver: str, mocap: str, timeout_s: float = 1) -> tuple[list[str], float]:
        return [
            "fly",
            str(PLAN),
            "--log",
            "f.jsonl",
            "--driver",
            driver,
            "--mocap",
            mocap,
        ], timeout_s

    def serve(driver: str, mocap: str, timeout_s: float = 1) -> tuple[list[str], float]:
        where = ["--socket", "s.sock", "--log-dir", ".", "--plan-dir", "."]
        return ["serve", *where, "--driver", driver, "--mocap", mocap], timeout_s

    unix = {how: net.unix(how) for how in ("silent", "trickles", "floods", "nonsense")}
    return {
        # perchd mocap --timeout S
        "mocap zmq silent tcp": (["mocap", zmq_mocap, "--timeout", "1"], 1),
        "mocap natnet silent udp": (
            ["mocap", at("natnet://", udp, "?body=cf1"), "--timeout", "1"],
            1,
        ),
        "mocap natnet dead udp": (
            ["mocap", at("natnet://", dead, "?body=cf1"), "--timeout", "1"],
            1,
        ),
        "mocap natnet silent tcp port": (
            ["mocap", at("natnet://", tcp, "?body=cf1"), "--timeout", "1"],
            1,
        ),
        # perchd fly: each link's wait= / timeout= (docs/contracts.md §7)
        "fly --driver zmq silent tcp": fly(at("zmq://", tcp, "?wait=1"), zmq_mocap),
        "fly --driver mavlink udpout silent": fly(at("mavlink:udpout:", udp, "?wait=1"), zmq_mocap),
        "fly --driver mavlink udpin nobody": fly(at("mavlink:udpin:", dead, "?wait=1"), zmq_mocap),
        "fly --driver mavlink tcp silent": fly(at("mavlink:tcp:", tcp, "?wait=1"), zmq_mocap),
        "fly --driver udp (cflib) nobody": fly(at("udp://", dead, "?wait=1"), zmq_mocap),
        "fly --mocap natnet silent udp": fly(at("zmq://", tcp, "?wait=0"), natnet),
        "fly --mocap motioncapture silent": fly(
            at("zmq://", tcp, "?wait=0"),
            "motioncapture://vicon?hostname=127.0.0.1&body=cf1&timeout=1",
        ),
        # perchd serve connects its links at start-up
        "serve --driver mavlink tcp silent": serve(at("mavlink:tcp:", tcp, "?wait=1"), zmq_mocap),
        "serve --mocap natnet silent udp": serve(at("zmq://", tcp, "?wait=1"), natnet, 2),
        # perchd failsafe --timeout S
        "failsafe mavlink udpout silent": (
            ["failsafe", "--driver", at("mavlink:udpout:", udp), "--timeout", "1"],
            1,
        ),
        "failsafe mavlink tcp silent": (
            ["failsafe", "--driver", at("mavlink:tcp:", tcp), "--timeout", "1"],
            1,
        ),
        "failsafe zmq silent": (["failsafe", "--driver", at("zmq://", tcp), "--timeout", "1"], 1),
        "failsafe udp (cflib) nobody": (
            ["failsafe", "--driver", at("udp://", dead), "--timeout", "1"],
            1,
        ),
        # perchd ctl: 5 s for the whole exchange (perchd/service/control_client.py)
        **{
            f"ctl {cmd} {how}": (["ctl", "--socket", path, cmd], 5)
            for how, path in unix.items()
            for cmd in ("status", "abort")
        },
    }


def _names() -> list[str]:
    """The case names, without opening any socket at collection."""

    class Dry(Listeners):
        def silent_tcp(self) -> int:
            return 1

        def silent_udp(self) -> int:
            return 1

        def dead_udp(self) -> int:
            return 1

        def unix(self, behaviour: str) -> str:
            return behaviour

    return sorted(socket_cases(Dry(Path("."))))


@pytest.mark.solo  # real-time bounds: see tests/conftest.py
@pytest.mark.parametrize("case", _names())
def test_a_uri_nobody_answers_is_one_line_within_its_timeout(case, listeners, tmp_path):
    argv, timeout_s = socket_cases(listeners)[case]
    bound = timeout_s + START_S
    out, took = perchd(argv, tmp_path, bound)
    refused(out, took, bound)
