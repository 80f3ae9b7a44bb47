"""Security of the service's inputs: who may use the control socket (mode 0660, SO_PEERCRED),
nothing is ever evaluated or unpickled, plan and config paths are validated, and ZMQ binds
only to loopback unless a URI opts in."""

from __future__ import annotations

import ast
import json
import os
import re
import select
import shutil
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest
from served import Service

from perchd.core.errors import ConfigError, UriError
from perchd.core.netbind import check_bind, is_loopback
from perchd.core.runtime import Runtime
from perchd.mocap.base import open_source
from perchd.mocap.zmq import ZmqPosePublisher
from perchd.service.config import config_from_dict
from perchd.service.control_socket import ControlServer, PeerPolicy

ROOT = Path(__file__).resolve().parents[2]
PLAN = ROOT / "plans" / "case1-ipts-n3.json"
NOBODY = 65534
as_root = pytest.mark.skipif(os.geteuid() != 0, reason="needs root to act as another user")


# ------------------------------------------------------------------ who may connect


def connect_as(path: Path, uid: int, gid: int) -> dict | str:
    """Connect from a forked child running as uid/gid and ask for status: the reply, or the
    name of the error connect() gave."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: drop to uid/gid, talk, report through the pipe, never return
        try:
            os.setgroups([])
            os.setgid(gid)
            os.setuid(uid)
            with socket.socket(socket.AF_UNIX) as c:
                c.settimeout(3)
                c.connect(str(path))
                try:
                    c.sendall(b'{"cmd": "status"}\n')
                except BrokenPipeError:  # refused and closed already: its reason is waiting
                    pass
                out = c.makefile("rb").readline()
        except OSError as err:
            out = json.dumps(type(err).__name__).encode()
        os.write(w, out)
        os._exit(0)
    os.close(w)
    with os.fdopen(r, "rb") as f:
        data = f.read()
    os.waitpid(pid, 0)
    return json.loads(data)


class Served:
    """A ControlServer in a directory anyone may enter, polled from a thread."""

    def __init__(self, peers: PeerPolicy | None = None) -> None:
        self.dir = Path(tempfile.mkdtemp())
        self.dir.chmod(0o755)
        self.path = self.dir / "c.sock"
        self.refusals: list[str] = []
        self.server = ControlServer(
            self.path,
            lambda req: {"ok": True, "cmd": req["cmd"]},
            peers=peers,
            on_refuse=self.refusals.append,
        )
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while not self.done.is_set():
            for fd in select.select(self.server.fds(), [], [], 0.02)[0]:
                self.server.handle(fd)

    def close(self) -> None:
        self.done.set()
        self.thread.join()
        self.server.close()
        shutil.rmtree(self.dir)


@pytest.fixture
def served(request):
    s = Served(getattr(request, "param", None))
    yield s
    s.close()


def test_the_socket_is_0660_even_under_umask_0(tmp_path):
    service = Service(tmp_path)
    try:
        assert stat.S_IMODE(os.stat(service.sock).st_mode) == 0o660
    finally:
        service.stop()


def test_by_default_the_services_own_user_and_root_are_let_in(served):
    assert served.server.peers.uids == {os.geteuid(), 0} and not served.server.peers.gids
    assert connect_as(served.path, os.geteuid(), os.getegid()) == {"ok": True, "cmd": "status"}


@pytest.mark.parametrize("served", [PeerPolicy(frozenset({12345}))], indirect=True)
def test_a_peer_whose_uid_is_not_allowed_gets_one_error_line_and_is_closed(served):
    me = os.geteuid()
    with socket.socket(socket.AF_UNIX) as c:
        c.settimeout(3)
        c.connect(str(served.path))
        reply = json.loads(c.makefile("rb").readline())
        assert c.recv(10) == b""  # closed after the refusal
    assert reply == {
        "ok": False,
        "error": f"uid {me} (gid {os.getegid()}) may not use this control "
        "socket; allow it with [service] allowed_users or allowed_groups",
    }
    assert served.refusals == [reply["error"]] and served.server.clients == {}


@as_root
def test_another_user_outside_the_group_is_stopped_by_the_file_mode(served):
    assert connect_as(served.path, NOBODY, NOBODY) == "PermissionError"


@as_root
def test_another_user_in_the_sockets_group_is_refused_by_peer_credentials(served):
    reply = connect_as(served.path, NOBODY, 0)
    assert reply["ok"] is False and reply["error"].startswith(f"uid {NOBODY} (gid 0) may not use")


@as_root
@pytest.mark.parametrize(
    "served",
    [PeerPolicy.owner(uids=frozenset({NOBODY})), PeerPolicy.owner(gids=frozenset({0}))],
    indirect=True,
)
def test_a_configured_user_or_group_is_let_in(served):
    assert connect_as(served.path, NOBODY, 0) == {"ok": True, "cmd": "status"}


def test_more_clients_than_the_cap_are_refused_and_the_others_still_served(served):
    from perchd.service.control_socket import MAX_CLIENTS

    held = [socket.socket(socket.AF_UNIX) for _ in range(MAX_CLIENTS)]
    try:
        for c in held:
            c.connect(str(served.path))
        deadline = time.monotonic() + 5
        while len(served.server.clients) < MAX_CLIENTS and time.monotonic() < deadline:
            time.sleep(0.01)
        refused = connect_as(served.path, os.geteuid(), os.getegid())
        assert refused["ok"] is False
        assert refused["error"].startswith(f"{MAX_CLIENTS} clients connected already (the bound)")
        held[0].sendall(b'{"cmd": "status"}\n')
        assert json.loads(held[0].makefile("rb").readline()) == {"ok": True, "cmd": "status"}
    finally:
        for c in held:
            c.close()


def test_allowed_users_and_groups_resolve_names_and_ids():
    svc = config_from_dict(
        {"version": 1, "service": {"allowed_users": ["nobody", 4321], "allowed_groups": ["root"]}}
    ).service
    assert svc.peer_policy() == PeerPolicy(
        frozenset({os.geteuid(), 0, NOBODY, 4321}), frozenset({0})
    )


@pytest.mark.parametrize(
    "value, message",
    [
        (
            ["no-such-user-here"],
            "[service] allowed_users: no user named 'no-such-user-here' on this host",
        ),
        ("root", "[service] allowed_users: expected a list of names or numeric ids, got 'root'"),
        ([-1], "[service] allowed_users: expected a list of names or numeric ids, got [-1]"),
        ([True], "[service] allowed_users: expected a list of names or numeric ids, got [True]"),
        ([""], "[service] allowed_users: expected a list of names or numeric ids, got ['']"),
    ],
)
def test_a_bad_allowed_users_entry_is_one_config_error(value, message):
    with pytest.raises(ConfigError) as err:
        config_from_dict({"version": 1, "service": {"allowed_users": value}})
    assert str(err.value) == "perchd.toml: " + message


@as_root
def test_the_service_refuses_another_user_until_a_reload_allows_it():
    tmp = Path(tempfile.mkdtemp())
    tmp.chmod(0o755)
    service = Service(tmp)
    try:
        assert connect_as(service.sock, NOBODY, 0)["ok"] is False
        service.reload('allowed_users = ["nobody"]\n')
        assert connect_as(service.sock, NOBODY, 0)["state"] == "idle"
    finally:
        err = service.stop()
        shutil.rmtree(tmp)
    assert f"control socket: refused uid {NOBODY} (gid 0) may not use" in err


# ------------------------------------------------------------------ nothing is evaluated

FORBIDDEN_MODULES = {
    "pickle",
    "cPickle",
    "_pickle",
    "marshal",
    "shelve",
    "dill",
    "cloudpickle",
    "yaml",
}
FORBIDDEN_CALLS = {
    "eval",
    "exec",
    "compile",
    "__import__",
    "os.system",
    "os.popen",
    "yaml.load",
    "pickle.loads",
    "pickle.load",
    "marshal.loads",
}


def _literal_only(call: ast.Call) -> bool:
    """exec or eval of a string literal (and constant namespaces): code written here, which
    no input reaches (cli's exit clears an interpreter mark with exec("pass", {}))."""
    name = ast.unparse(call.func)
    return (
        name in ("exec", "eval")
        and bool(call.args)
        and isinstance(call.args[0], ast.Constant)
        and isinstance(call.args[0].value, str)
        and all(isinstance(a, ast.Dict) and not a.keys for a in call.args[1:])
        and not call.keywords
    )


def dangers(source: str) -> list[str]:
    """Every use of evaluation, unpickling or a shell in Python source."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [
                f"import {a.name}" for a in node.names if a.name.split(".")[0] in FORBIDDEN_MODULES
            ]
        elif (
            isinstance(node, ast.ImportFrom)
            and (node.module or "").split(".")[0] in FORBIDDEN_MODULES
        ):
            found.append(f"from {node.module} import")
        elif isinstance(node, ast.Call):
            name = ast.unparse(node.func)
            if name in FORBIDDEN_CALLS and not _literal_only(node):
                found.append(f"{name}()")
            if any(
                k.arg == "shell"
                and not (isinstance(k.value, ast.Constant) and k.value.value is False)
                for k in node.keywords
            ):
                found.append(f"{name}(shell=...)")
    return found


def test_the_scanner_finds_each_kind_of_danger():
    source = (
        "import pickle\nfrom yaml import load\neval(s)\nexec(s)\nos.system('ls')\n"
        "subprocess.run('ls', shell=True)\nyaml.load(s)\nexec('pass', {})\nexec(s, {})\n"
        "exec('x=1', g)\n"
    )
    assert dangers(source) == [
        "import pickle",
        "from yaml import",
        "eval()",
        "exec()",
        "os.system()",
        "subprocess.run(shell=...)",
        "yaml.load()",
        "exec()",
        "exec()",
    ]  # not exec('pass', {}): a literal in an empty namespace


def test_no_input_is_ever_evaluated_unpickled_or_given_to_a_shell():
    files = sorted((ROOT / "perchd").rglob("*.py")) + sorted((ROOT / "drivers").rglob("*.py"))
    assert len(files) > 50
    found = {str(f.relative_to(ROOT)): d for f in files if (d := dangers(f.read_text()))}
    assert found == {}
    text = "\n".join(f.read_text() for f in files)  # and by plain grep, for what ast might miss
    for needle in (
        r"pickle\.load",
        r"yaml\.load\(",
        r"shell\s*=\s*True",
        r"(?<![\w.])(?<!def )eval\(",
        r"(?<![\w.])(?<!def )exec\((?![\"']\w*[\"'], \{\}\))",  # but of a literal, as above
        r"literal_eval",
        r"import\s+pickle",
    ):
        assert re.findall(needle, text) == [], needle


# ------------------------------------------------------------------ plan and config paths


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("paths")
    s = Service(tmp)
    shutil.copy(PLAN, s.plans / "good.json")
    shutil.copy(PLAN, tmp / "outside.json")
    (s.plans / "escape.json").symlink_to(tmp / "outside.json")
    (s.plans / "inside.json").symlink_to(s.plans / "good.json")
    os.mkfifo(s.plans / "fifo.json")
    (s.plans / "dir.json").mkdir()
    (s.plans / "big.json").write_bytes(b" " * (1 << 20) + PLAN.read_bytes())
    yield s
    s.stop()


def fly(service: Service, plan: str) -> dict:
    return service.talk(json.dumps({"cmd": "fly", "plan": plan}).encode() + b"\n", 1)[0]


def test_a_plan_outside_the_plan_directory_is_refused(service):
    outside = service.tmp / "outside.json"
    assert fly(service, str(outside)) == {
        "ok": False,
        "refused": "plan",
        "error": f"plan {outside}: outside the plan "
        f"directory {service.plans} (plan_dir in [service])",
    }
    assert fly(service, "../outside.json")["error"].startswith(
        f"plan {service.plans}/../outside.json: outside"
    )
    assert fly(service, "/dev/zero")["error"] == (
        f"plan /dev/zero: outside the plan directory {service.plans} (plan_dir in [service])"
    )


def test_a_symlink_escaping_the_plan_directory_is_refused(service):
    assert fly(service, "escape.json")["error"] == (
        f"plan {service.plans}/escape.json (a symlink to {service.tmp}/outside.json): outside the "
        f"plan directory {service.plans} (plan_dir in [service])"
    )


@pytest.mark.parametrize(
    "name, why",
    [
        ("fifo.json", "not a regular file (a FIFO)"),
        ("dir.json", "not a regular file (a directory)"),
        (
            "big.json",
            f"{(1 << 20) + PLAN.stat().st_size} bytes, over the 1048576 byte limit by {PLAN.stat().st_size}",
        ),
        ("missing.json", "cannot read (No such file or directory)"),
    ],
)
def test_a_fifo_a_directory_an_oversized_or_missing_plan_is_one_refusal(service, name, why):
    assert fly(service, name) == {
        "ok": False,
        "refused": "plan",
        "error": f"plan {service.plans / name}: {why}",
    }
    assert service.talk(b'{"cmd": "status"}\n', 1)[0]["state"] == "idle"  # the FIFO did not hang it


def test_a_plan_inside_the_directory_flies_by_name_absolute_path_or_inner_symlink(service):
    for name in ("good.json", str(service.plans / "good.json"), "inside.json"):
        started = fly(service, name)
        assert started["ok"] and started["plan"] == str(service.plans / "good.json"), started
        assert service.talk(b'{"cmd": "abort"}\n', 1)[0]["aborting"] is True
        while service.talk(b'{"cmd": "status"}\n', 1)[0]["state"] == "flying":
            pass


def test_ctl_fly_outside_the_plan_directory_prints_one_refusal_and_exits_2(service):
    """A refused plan is the caller's input, so exit 2 (docs/contracts.md §6)."""
    argv = [
        sys.executable,
        "-m",
        "perchd",
        "ctl",
        "--socket",
        str(service.sock),
        "fly",
        str(service.tmp / "outside.json"),
    ]
    done = subprocess.run(argv + ["--json"], capture_output=True, text=True, timeout=30)
    assert done.returncode == 2 and done.stderr == ""
    assert json.loads(done.stdout)["error"].endswith(
        f"outside the plan directory {service.plans} (plan_dir in [service])"
    )
    done = subprocess.run(argv, capture_output=True, text=True, timeout=30)  # readable: on stderr
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith("perchd ctl: ") and done.stderr.count("\n") == 1
    assert done.stderr.strip().endswith("(plan_dir in [service])")


@pytest.mark.parametrize(
    "make, why",
    [
        (lambda p: os.mkfifo(p), "not a regular file (a FIFO)"),
        (lambda p: p.mkdir(), "not a regular file (a directory)"),
        (
            lambda p: p.write_bytes(b"version = 1\n" + b"#" * (1 << 20)),
            "1048588 bytes, over the 1048576 byte limit by 12",
        ),
        (lambda p: p.write_bytes(b"version = 1\n\xff\n"), "not UTF-8 text (byte 12)"),
    ],
)
def test_a_config_path_that_is_no_regular_small_text_file_is_one_line_exit_2(tmp_path, make, why):
    config = tmp_path / "perchd.toml"
    make(config)
    for args in (
        ["serve", "--config", str(config), "--socket", str(tmp_path / "s")],
        ["fly", str(PLAN), "--driver", "sim://", "--mocap", "sim://", "--config", str(config)],
    ):
        done = subprocess.run(
            [sys.executable, "-m", "perchd", *args], capture_output=True, text=True, timeout=30
        )
        assert (done.returncode, done.stderr.count("\n")) == (2, 1), done.stderr
        assert done.stderr.strip().endswith(f"config {config}: {why}")


# ------------------------------------------------------------------ ZMQ binds


@pytest.mark.parametrize("host", ["127.0.0.1", "127.0.0.53", "localhost", "::1", "[::1]"])
def test_loopback_hosts_may_be_bound(host):
    assert is_loopback(host)
    check_bind(host, False, "test")


@pytest.mark.parametrize("host", ["0.0.0.0", "*", "::", "192.168.1.10", "eth0", "mocap.lan"])
def test_any_other_bind_needs_public(host):
    with pytest.raises(UriError) as err:
        check_bind(host, False, "zmq://x")
    assert str(err.value) == (
        f"zmq://x: refusing to bind {host}, which is not loopback; add public=1 "
        "to the URI to listen on the network"
    )
    check_bind(host, True, "test")


def test_the_pose_publisher_binds_loopback_by_default_and_refuses_the_network():
    with ZmqPosePublisher() as pub:
        assert pub.endpoint.startswith("tcp://127.0.0.1:")
    with pytest.raises(UriError, match="pose publisher tcp://0.0.0.0:0: refusing to bind 0.0.0.0"):
        ZmqPosePublisher("tcp://0.0.0.0:0")


def test_a_binding_zmq_source_or_driver_needs_public_off_loopback():
    from perchd.drivers.base import open_driver

    runtime = Runtime.real()
    with pytest.raises(
        UriError, match=r"zmq://0.0.0.0:5555\?body=cf1&bind=1: refusing to bind 0.0.0.0"
    ):
        open_source("zmq://0.0.0.0:5555?body=cf1&bind=1", runtime)
    with pytest.raises(UriError, match=r"zmq://\*:5556\?bind=1: refusing to bind \*"):
        open_driver("zmq://*:5556?bind=1", runtime)
    # the opt-in is accepted (not started: tests never bind off loopback); connecting needs none
    assert (
        open_source("zmq://0.0.0.0:5555?body=cf1&bind=1&public=1", runtime).endpoint
        == "tcp://0.0.0.0:5555"
    )
    assert open_source("zmq://10.0.0.7:5555?body=cf1", runtime).endpoint == "tcp://10.0.0.7:5555"
    assert open_driver("zmq://0.0.0.0:5556?bind=1&public=1", runtime).bind is True


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["--pose-out", "zmq://0.0.0.0:0", "--setpoint-in", "zmq://127.0.0.1:0"],
            "pose publisher tcp://0.0.0.0:0: refusing to bind 0.0.0.0, which is not loopback",
        ),
        (
            ["--pose-out", "zmq://127.0.0.1:0", "--setpoint-in", "zmq://0.0.0.0:0"],
            "--setpoint-in zmq://0.0.0.0:0: refusing to bind 0.0.0.0, which is not loopback",
        ),
    ],
)
def test_perchd_sim_refuses_a_network_bind_without_public(args, message):
    done = subprocess.run(
        [sys.executable, "-m", "perchd", "sim", *args], capture_output=True, text=True, timeout=30
    )
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and message in done.stderr
