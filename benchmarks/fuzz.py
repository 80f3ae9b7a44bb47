"""Fuzzing at volume, with a fixed seed: NatNet packets into the parser and the client's
receive path, control-socket lines into a running `perchd serve`, and plan, config and
flight-log files into their readers.

    python benchmarks/fuzz.py [--natnet 1000000] [--udp 100000] [--requests 1000000]
                              [--lines 100000] [--files 100000] [--seed 8] [--json]

(about a minute; the target is at least 1e5 of each kind of input.)

natnet: recorded Motive packets (tests/fixtures/natnet: 3 servers, NatNet 2.5 to 3.0),
    each mutated (bit flips, cuts, inserts, extreme words, a lying length field) or replaced
    by random bytes. Each goes through the decoders (accepted = decoded, rejected =
    MalformedPacket, crash = any other exception) and through NatNetSource.handle_datagram
    (poses taken, packets dropped).
udp: the first --udp of them sent over real loopback UDP to a started NatNet client
    (connected to perchd's server emulator); afterwards the emulator's next pose must still
    reach it (else a crash).
requests: control lines (as below) through the control socket's request handling in this
    process (ControlServer.answer: the parser, duplicate keys, the abort-only reserve over the
    bound, a dispatch that raises). accepted = {"ok": true}, rejected = {"ok": false} with a
    one-line error; crash = an exception, or a reply of any other shape.
lines: random bytes, mutated requests, requests with a key given twice, any JSON, hostile plan paths, deep nesting, in
    batches of 25 on one connection, a status request after each batch, and every 40th batch
    an overlong line (counted as an input too), to `perchd serve` (sim://) over its Unix socket. accepted = {"ok": true} reply,
    rejected = {"ok": false} reply (or the overlong-line drop); crash = a line without its
    reply, a status request unanswered, or the service not exiting 0 on SIGTERM.
files: --files inputs each for the plan reader (load_plan), the config reader
    (load_flight_config) and the flight-log reader (read_log), each written to a real file
    and read from it: shipped plans, the example config and a short flight log, mutated
    byte-wise (as NatNet packets are) or with their numbers replaced by extreme or ill-typed
    tokens (1e999, 400 and 5000 digits, NaN, booleans, strings), or random bytes. accepted =
    read, rejected = one-line PerchdError; crash = any other exception or a multi-line error.
    A hang would stop the run (the reads are bounded and non-blocking).
Throughput [inputs/s]: for the in-process NatNet passes the median over chunks of 10^4
inputs; for UDP and control lines the whole run (their pacing is part of the path).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import random
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from perchd.core.clock import ManualClock, MonotonicClock
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.core.uri import parse_uri
from perchd.mocap.natnet import models as natdefs
from perchd.mocap.natnet import protocol as proto
from perchd.mocap.natnet.client import NatNetConfig, NatNetSource
from perchd.mocap.natnet.clock import ClockSync
from perchd.mocap.natnet.frame import decode_frame
from perchd.mocap.natnet.uris import NatNetServer, open_natnet
from perchd.mocap.natnet.wire import MalformedPacket
from perchd.service.control_socket import ControlServer

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "helpers"))
from logseed import log_seed  # noqa: E402 - the seeds the fuzz tests use
from mutate import NASTY_TOKENS, NUMBER  # noqa: E402

FIXTURES = ROOT / "tests" / "fixtures" / "natnet"
OLD_MOTIVE = {"1.5.0": (2, 5), "1.7.2": (2, 7), "1.9.0": (2, 9)}  # NatNet of each Motive 1.x
EXTREME_WORDS = [
    b"\xff\xff\xff\x7f",
    b"\0\0\0\x80",
    b"\0\0\0\0",
    b"\xff\xff\xff\xff",
    b"\x01\0\0\0",
]


@dataclass
class Tally:
    inputs: int = 0
    accepted: int = 0
    rejected: int = 0
    crashes: int = 0
    seconds: float = 0.0
    rates: list[float] = field(default_factory=list)  # [inputs/s] per chunk of CHUNK inputs
    examples: list[str] = field(default_factory=list)  # the first few crashes, for a bug report

    def crash(self, what: str) -> None:
        self.crashes += 1
        if len(self.examples) < 5:
            self.examples.append(what[:300])

    @property
    def rate(self) -> float:
        """[inputs/s] median over chunks where there are chunks, else over the whole run."""
        if self.rates:
            return statistics.median(self.rates)
        return self.inputs / self.seconds if self.seconds else 0.0

    def line(self, name: str, extra: str = "") -> str:
        return (
            f"{name:14s} inputs {self.inputs:7d}  accepted {self.accepted:7d}  rejected "
            f"{self.rejected:7d}  crashes {self.crashes}  {self.rate:9.0f} /s{extra}"
        )


# ------------------------------------------------------------------ NatNet inputs


def seeds() -> list[tuple[bytes, tuple[int, int]]]:
    """Every recorded server-to-client packet with the NatNet version it was sent in."""
    out = []
    for path in sorted((FIXTURES / "motive-2.1-session" / "packets").glob("*_msg*_151*to*.bin")):
        out.append((path.read_bytes(), (3, 0)))
    for path in sorted((FIXTURES / "motive-2.1-natnet-3.0").glob("*.bin")):
        out.append((path.read_bytes(), (2, 10) if path.stem.endswith("v2") else (3, 0)))
    for path in sorted((FIXTURES / "motive-1.x-natnet-2.x").glob("*.bin")):
        out.append((path.read_bytes(), OLD_MOTIVE[path.stem.split("-")[2]]))
    return out


def mutate(rng: random.Random, data: bytes) -> bytes:
    data = bytearray(data)
    for _ in range(rng.randint(1, 6)):
        at = rng.randrange(max(1, len(data)))
        kind = rng.randrange(5)
        if kind == 0 and data:
            data[at] ^= 1 << rng.randrange(8)
        elif kind == 1:
            del data[at : at + rng.randint(1, 64)]
        elif kind == 2:
            data[at:at] = rng.randbytes(rng.randint(1, 16))
        elif kind == 3:
            data[at : at + 4] = rng.choice(EXTREME_WORDS)
        elif len(data) >= 4:  # the length field lies
            data[2:4] = rng.randrange(0x10000).to_bytes(2, "little")
    return bytes(data)


CHUNK = 10_000


def natnet_chunks(seed: int, n: int):
    """The same n inputs for every pass (one seed), made CHUNK at a time to bound memory."""
    rng, pool = random.Random(seed), seeds()
    for first in range(0, n, CHUNK):
        yield natnet_inputs(rng, pool, first, min(n, first + CHUNK))


def natnet_inputs(
    rng: random.Random, pool, first: int, end: int
) -> list[tuple[bytes, tuple[int, int]]]:
    out = []
    for i in range(first, end):
        if i % 5 == 4:  # one in five: random bytes, sometimes behind a valid frame header
            junk = rng.randbytes(rng.randint(0, 600))
            if rng.random() < 0.5:
                junk = proto.pack(proto.NAT_FRAMEOFDATA, junk)
            out.append((junk, rng.choice(pool)[1]))
        else:
            data, version = rng.choice(pool)
            out.append((mutate(rng, data), version))
    return out


def decode(datagram: bytes, version: tuple[int, int]) -> None:
    """Every decoder a client runs on a server's packet; MalformedPacket for a bad one."""
    message_id, payload = proto.unpack(datagram)
    if message_id == proto.NAT_FRAMEOFDATA:
        decode_frame(payload, version)
    elif message_id == proto.NAT_MODELDEF:
        natdefs.decode_model_defs(payload, version)
    elif message_id == proto.NAT_SERVERINFO:
        proto.decode_server_info(payload)
    elif message_id == proto.NAT_ECHORESPONSE:
        proto.decode_echo_response(payload)


def run_chunk(tally: Tally, inputs: list, judge, show) -> None:
    """judge(x) for each input: True accepted, False rejected, an exception a crash
    (show(x) names the input); the chunk's rate kept."""
    tally.inputs += len(inputs)
    start = time.perf_counter()
    for x in inputs:
        try:
            if judge(x):
                tally.accepted += 1
            else:
                tally.rejected += 1
        except Exception as err:  # noqa: BLE001 - this is what is being counted
            tally.crash(f"{type(err).__name__}: {err} on {show(x)}")
    took = time.perf_counter() - start
    tally.seconds += took
    tally.rates.append(len(inputs) / took)


def _decoded(item: tuple[bytes, tuple[int, int]]) -> bool:
    try:
        decode(*item)
    except MalformedPacket:
        return False
    return True


def fuzz_parser(chunks) -> Tally:
    tally = Tally()
    for inputs in chunks:
        run_chunk(tally, inputs, _decoded, lambda item: item[0].hex())
    return tally


def fuzz_client(chunks) -> Tally:
    """NatNetSource.handle_datagram, as its receive thread calls it (no socket)."""
    source = NatNetSource(NatNetConfig("127.0.0.1", "RaceQuad"), ManualClock(1.0e6))
    source.info = type("Info", (), {"version": (3, 0)})()
    source._body_id, source._sync = 2, ClockSync(3312787)
    tally = Tally()
    for inputs in chunks:
        tally.inputs += len(inputs)
        start = time.perf_counter()
        for datagram, version in inputs:
            source.info.version = version
            try:
                source.handle_datagram(datagram, 1.0e6)
            except Exception as err:  # noqa: BLE001 - it promises never to raise
                tally.crash(f"handle_datagram raised {type(err).__name__}: {err}")
        took = time.perf_counter() - start
        tally.seconds += took
        tally.rates.append(len(inputs) / took)
    stats = source.stats()
    tally.accepted, tally.rejected = stats.poses, stats.dropped
    if stats.received != tally.inputs:
        tally.crash(f"{stats.received} datagrams counted of {tally.inputs}")
    return tally


def fuzz_udp(inputs) -> Tally:
    """Datagrams over real loopback UDP into a started client; then a good pose must arrive."""
    clock = MonotonicClock()
    tally = Tally(len(inputs))
    with NatNetServer({"cf1": 1}, (3, 0)) as server:
        source = open_natnet(parse_uri(server.uri + "&body=cf1&transport=unicast"), Runtime(clock))
        source.start()
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            target = source._command.getsockname()
            before = source.stats().received
            start = time.perf_counter()
            for i, (datagram, _) in enumerate(inputs):
                sender.sendto(datagram, target)
                if i % 200 == 199:  # let the receive thread keep up: UDP drops what overflows
                    while source.stats().received - before < i - 100:
                        time.sleep(0.0005)
            deadline = time.monotonic() + 10
            while source.stats().received - before < len(inputs) and time.monotonic() < deadline:
                time.sleep(0.001)
            tally.seconds = time.perf_counter() - start
            stats = source.stats()
            got = stats.received - before
            if got < len(inputs):
                tally.crash(f"only {got} of {len(inputs)} datagrams reached the client")
            tally.accepted, tally.rejected = stats.poses, stats.dropped
            last, pose, deadline = source.latest(), None, time.monotonic() + 3.0
            while pose is None and time.monotonic() < deadline:
                # streamed, as Motive does: after a fuzzed "models changed" flag the client
                # skips frames until it has the definitions again, and after a fuzzed huge frame
                # number it drops real frames as out of order until it resynchronises
                server.publish(Pose("cf1", 0, clock.now(), (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0)))
                time.sleep(0.01)
                pose = source.latest() if source.latest() is not last else None
            if pose is None or pose.p != (1.0, 2.0, 3.0):
                tally.crash(f"no good pose after the flood (got {pose})")
        finally:
            sender.close()
            source.close()
    return tally


# ------------------------------------------------------------------ control lines

HOSTILE_PLANS = [
    "../../../etc/passwd",
    "/etc/shadow",
    "/dev/zero",
    "/dev/stdin",
    "/proc/self/environ",
    "",
    ".",
    "..",
    "/",
    "a" * 4000,
    "x\0y",
    "~root/p.json",
    "*.json",
    "fifo",
]
GOOD = [b'{"cmd": "status"}', b'{"cmd": "abort"}', b'{"cmd": "status", "extra": [1, 2]}']


def random_json(rng: random.Random, depth: int = 0):
    kind = rng.randrange(9 if depth < 3 else 6)
    if kind == 0:
        return None
    if kind == 1:
        return rng.random() < 0.5
    if kind == 2:
        return rng.choice([0, -1, 2**64, 1e308, -1e-308, rng.randint(-(10**9), 10**9)])
    if kind == 3:
        return rng.uniform(-1e6, 1e6)
    if kind in (4, 5):
        return "".join(chr(rng.randrange(1, 0x2FF)) for _ in range(rng.randint(0, 12)))
    if kind in (6, 7):
        return {
            str(rng.random())[2:6]: random_json(rng, depth + 1) for _ in range(rng.randint(0, 4))
        }
    return [random_json(rng, depth + 1) for _ in range(rng.randint(0, 4))]


def duplicate_key(rng: random.Random) -> bytes:
    """A request with one key written twice (the second value any JSON)."""
    req = {"cmd": rng.choice(["abort", "status", "fly"]), "plan": rng.choice(HOSTILE_PLANS)}
    key = rng.choice(sorted(req))
    return (json.dumps(req)[:-1] + ", " + json.dumps({key: random_json(rng)})[1:]).encode()


def control_line(rng: random.Random) -> bytes:
    kind = rng.randrange(9)
    if kind == 8:
        return duplicate_key(rng)
    if kind == 0:
        return rng.randbytes(rng.randint(0, 300)).replace(b"\n", b"")
    if kind == 1:  # a good request mutated byte-wise
        line = bytearray(rng.choice(GOOD))
        for _ in range(rng.randint(1, 4)):
            line[rng.randrange(len(line))] = rng.randrange(256)
        return bytes(line).replace(b"\n", b"")
    if kind == 2:
        return json.dumps(random_json(rng)).encode()
    if kind in (3, 4):
        req = {"cmd": rng.choice(["fly", "abort", "status", "Fly", "", "eval", random_json(rng)])}
        if rng.random() < 0.7:
            req["plan"] = rng.choice(HOSTILE_PLANS + [random_json(rng)])
        return json.dumps(req).encode()
    if kind == 5:
        return rng.choice(
            [b"[" * 60000, b"{" * 1000, b'{"cmd":' * 3000, b"\xff\xfe\xfd", b"\0" * 64]
        )
    return rng.choice(GOOD)


def _dispatch(req: dict) -> dict:
    if req["cmd"] == "eval":
        raise RuntimeError("a dispatch that fails")
    return {"ok": True, "cmd": req["cmd"]}


def fuzz_requests(rng: random.Random, n: int) -> Tally:
    """n lines through ControlServer.answer, CHUNK at a time; every 7th as over the bound."""
    tally = Tally()
    with tempfile.TemporaryDirectory(prefix="perchd-fuzz-") as tmp:
        server = ControlServer(Path(tmp) / "c.sock", _dispatch)
        try:
            for first in range(0, n, CHUNK):
                lines = [control_line(rng) for _ in range(min(CHUNK, n - first))]
                _answer_all(server, lines, first, tally)
        finally:
            server.close()
    return tally


def _answer_all(server: ControlServer, lines: list[bytes], first: int, tally: Tally) -> None:
    tally.inputs += len(lines)
    start = time.perf_counter()
    for i, line in enumerate(lines, first):
        try:
            reply = server.answer(line, reserved=i % 7 == 6)
        except Exception as err:  # noqa: BLE001 - this is what is being counted
            tally.crash(f"{type(err).__name__}: {err} on {line[:200]!r}")
            continue
        if reply.get("ok") is True:
            tally.accepted += 1
        elif isinstance(reply.get("error"), str) and reply["error"] and "\n" not in reply["error"]:
            tally.rejected += 1
        else:
            tally.crash(f"reply {reply!r:.200} to {line[:200]!r}")
    took = time.perf_counter() - start
    tally.seconds += took
    tally.rates.append(len(lines) / took)


class Service:
    """`perchd serve` on sim:// in a scratch directory; plan_dir holds only a FIFO."""

    def __init__(self) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="perchd-fuzz-"))
        (self.dir / "plans").mkdir()
        os.mkfifo(self.dir / "plans" / "fifo")
        self.sock = self.dir / "control.sock"
        config = self.dir / "perchd.toml"
        config.write_text(
            f'version = 1\n[service]\nsocket = "{self.sock}"\n'
            f'plan_dir = "{self.dir / "plans"}"\nlog_dir = "{self.dir / "logs"}"\n'
        )
        self.log = open(self.dir / "stderr", "wb")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "perchd", "serve", "--config", str(config)],
            stdout=subprocess.DEVNULL,
            stderr=self.log,
        )
        deadline = time.monotonic() + 30
        while not self.sock.exists():
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise SystemExit(f"perchd serve did not start: {(self.dir / 'stderr').read_text()}")
            time.sleep(0.05)

    def exchange(self, lines: list[bytes]) -> list[dict] | None:
        """Send the lines on one connection; their replies, or None if any is missing."""
        with socket.socket(socket.AF_UNIX) as c:
            c.settimeout(10)
            c.connect(str(self.sock))
            c.sendall(b"".join(line + b"\n" for line in lines))
            reader = c.makefile("rb")
            replies = []
            for _ in lines:
                raw = reader.readline()
                if not raw.endswith(b"\n"):
                    return None
                replies.append(json.loads(raw))
            return replies

    def overlong(self) -> dict | None:
        """A line over the 64 KiB limit: one error reply, then the server hangs up."""
        with socket.socket(socket.AF_UNIX) as c:
            c.settimeout(10)
            c.connect(str(self.sock))
            try:
                c.sendall(b"x" * 70_000)
            except OSError:
                pass
            raw = c.makefile("rb").readline()
        return json.loads(raw) if raw.endswith(b"\n") else None

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGTERM)
        try:
            code = self.proc.wait(30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = -9
        self.log.close()
        shutil.rmtree(self.dir)
        return code


def fuzz_lines(rng: random.Random, n: int, batch: int = 25) -> tuple[Tally, int]:
    lines = [control_line(rng) for _ in range(n)]
    service = Service()
    tally, status_checks = Tally(n), 0
    start = time.perf_counter()
    try:
        for i in range(0, n, batch):
            chunk = lines[i : i + batch]
            try:
                replies = service.exchange(chunk)
            except OSError as err:
                replies = None
                tally.crash(f"lines {i}..: {err}")
            if replies is None:
                tally.crash(f"a line in {chunk!r:.200} got no reply")
                continue
            for reply in replies:
                if reply.get("ok") is True:
                    tally.accepted += 1
                else:
                    tally.rejected += 1
            if (i // batch) % 40 == 39:  # now and then a line too long to read
                tally.inputs += 1
                reply = service.overlong()
                if reply is None or "longer than" not in reply.get("error", ""):
                    tally.crash(f"overlong line: {reply}")
                tally.rejected += 1
            status = service.exchange([b'{"cmd": "status"}'])
            status_checks += 1
            if not status or status[0].get("state") != "idle":
                tally.crash(f"status after lines {i}..: {status}")
    finally:
        tally.seconds = time.perf_counter() - start
        if (code := service.stop()) != 0:
            tally.crash(f"perchd serve exited {code} on SIGTERM")
    return tally, status_checks


# ------------------------------------------------------------------ files


def file_input(rng: random.Random, seeds: list[bytes]) -> bytes:
    kind = rng.randrange(5)
    if kind == 0:
        return rng.randbytes(rng.randint(0, 400))
    data = rng.choice(seeds)
    if kind in (1, 2):
        return mutate(rng, data)
    for _ in range(rng.randint(1, 3)):  # numbers replaced by extreme or ill-typed tokens
        spans = [m.span() for m in NUMBER.finditer(data)]
        if spans:
            start, end = rng.choice(spans)
            data = data[:start] + rng.choice(NASTY_TOKENS) + data[end:]
    return data


def fuzz_reader(rng: random.Random, n: int, seeds: list[bytes], read, path: Path) -> Tally:
    from perchd.core.errors import PerchdError

    def judge(data: bytes) -> bool:
        path.write_bytes(data)
        try:
            read(path)
        except PerchdError as err:
            if "\n" in str(err) or not str(err):
                raise AssertionError(f"an error of {len(str(err).splitlines())} lines") from None
            return False
        return True

    tally = Tally()
    for first in range(0, n, CHUNK):
        inputs = [file_input(rng, seeds) for _ in range(min(CHUNK, n - first))]
        run_chunk(tally, inputs, judge, lambda data: repr(data[:200]))
    return tally


def fuzz_files(seed: int, n: int) -> dict[str, Tally]:
    from perchd.logs.flightlog import read_log
    from perchd.service.config import load_flight_config
    from perchd.tau.planfile import load_plan

    plans = [p.read_bytes() for p in sorted((ROOT / "plans").glob("*.json"))]
    configs = [(ROOT / "systemd" / "perchd.toml").read_bytes()]
    shm = "/dev/shm" if os.path.isdir("/dev/shm") else None  # the files, not the disk, are fuzzed
    with tempfile.TemporaryDirectory(prefix="perchd-fuzz-", dir=shm) as tmp:
        logs = [log_seed(Path(tmp) / "seed.jsonl")]
        (Path(tmp) / "seed.jsonl").unlink()
        return {
            "plan file": fuzz_reader(
                random.Random(seed), n, plans, load_plan, Path(tmp) / "p.json"
            ),
            "config file": fuzz_reader(
                random.Random(seed + 1), n, configs, load_flight_config, Path(tmp) / "perchd.toml"
            ),
            "log file": fuzz_reader(
                random.Random(seed + 2), n, logs, read_log, Path(tmp) / "f.jsonl"
            ),
        }


# ------------------------------------------------------------------ main


def _without_rates(items) -> dict:
    return {k: v for k, v in items if k != "rates"}


NOTES = {
    "natnet parser": "  (accepted = decoded, rejected = MalformedPacket)",
    "natnet client": "  (accepted = poses, rejected = dropped)",
    "natnet udp": "  (then a good pose still arrives)",
    "control parse": "  (in-process: accepted = ok, rejected = error)",
    "control lines": "  ({checks} status checks between batches)",
    "plan file": "  (accepted = read, rejected = one-line PerchdError)",
    "config file": "  (accepted = read, rejected = one-line PerchdError)",
    "log file": "  (accepted = read, rejected = one-line PerchdError)",
}


def _network(args: argparse.Namespace) -> tuple[dict[str, Tally], int]:
    results = {
        "natnet parser": fuzz_parser(natnet_chunks(args.seed, args.natnet)),
        "natnet client": fuzz_client(natnet_chunks(args.seed, args.natnet)),
        "natnet udp": fuzz_udp([x for c in natnet_chunks(args.seed, args.udp) for x in c]),
        "control parse": fuzz_requests(random.Random(args.seed + 2), args.requests),
    }
    results["control lines"], checks = fuzz_lines(random.Random(args.seed + 1), args.lines)
    return results, checks


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--natnet", type=int, default=1_000_000, help="NatNet packets (default 1e6)"
    )
    parser.add_argument(
        "--udp", type=int, default=100_000, help="of them also sent over UDP (default 1e5)"
    )
    parser.add_argument(
        "--requests",
        type=int,
        default=1_000_000,
        help="control lines through the request handling in-process (default 1e6)",
    )
    parser.add_argument("--lines", type=int, default=100_000, help="control lines (default 1e5)")
    parser.add_argument(
        "--files",
        type=int,
        default=100_000,
        help="plan, config and flight-log files, each (default 1e5)",
    )
    parser.add_argument("--only-files", action="store_true", help="the file readers alone")
    parser.add_argument("--seed", type=int, default=8)
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = parser.parse_args(argv)
    logging.getLogger("perchd").setLevel(logging.ERROR)  # every drop is expected here
    results, checks = ({}, 0) if args.only_files else _network(args)
    results.update(fuzz_files(args.seed + 3, args.files))
    crashes = sum(t.crashes for t in results.values())
    if args.json:
        print(
            json.dumps(
                {
                    "seed": args.seed,
                    "crashes": crashes,
                    "status_checks": checks,
                    **{
                        k: {**asdict(t, dict_factory=_without_rates), "rate": t.rate}
                        for k, t in results.items()
                    },
                }
            )
        )
    else:
        print(f"fuzz, seed {args.seed}")
        for name, t in results.items():
            print(t.line(name, NOTES.get(name, "").format(checks=checks)))
        for name, t in results.items():
            for example in t.examples:
                print(f"  {name} crash: {example}")
        print(f"crashes: {crashes}")
    return 1 if crashes else 0


if __name__ == "__main__":
    sys.exit(main())
