"""The control socket server (docs/contracts.md §4) on a real Unix socket, driven by select."""

import json
import os
import select
import socket
import stat
import threading
import time

import pytest

from perchd.core.clock import ManualClock
from perchd.core.errors import ConfigError
from perchd.service.control_client import request
from perchd.service.control_socket import RESERVED_SLOTS, RESERVED_WAIT_S, ControlServer


class Served:
    """A ControlServer polled from a thread, as the daemon's loop does."""

    def __init__(self, path, dispatch, **options):
        self.server = ControlServer(path, dispatch, **options)
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self):
        while not self.done.is_set():
            for fd in select.select(self.server.fds(), [], [], 0.05)[0]:
                self.server.handle(fd)
            self.server.expire()

    def close(self):
        self.done.set()
        self.thread.join()
        self.server.close()


@pytest.fixture
def served(tmp_path):
    calls = []

    def dispatch(req):
        calls.append(req)
        if req["cmd"] == "boom":
            raise RuntimeError("kaboom")
        return {"ok": True, "echo": req}

    s = Served(tmp_path / "c.sock", dispatch)
    s.calls = calls
    yield s
    s.close()


def talk(path, payload: bytes, lines: int):
    with socket.socket(socket.AF_UNIX) as c:
        c.settimeout(3)
        c.connect(str(path))
        c.sendall(payload)
        buf = b""
        while buf.count(b"\n") < lines:
            chunk = c.recv(65536)
            if not chunk:
                break
            buf += chunk
    return [json.loads(x) for x in buf.splitlines()]


def test_each_line_gets_one_reply_and_bad_lines_get_errors(served, tmp_path):
    replies = talk(
        tmp_path / "c.sock",
        b'{"cmd":"status"}\nnot json\n[1,2]\n{"cmd":"boom"}\n{"cmd": "status", "x": 1}\n',
        5,
    )
    assert replies[0] == {"ok": True, "echo": {"cmd": "status"}}
    assert replies[1]["ok"] is False and "malformed request" in replies[1]["error"]
    assert replies[2] == {"ok": False, "error": 'a request is a JSON object with a "cmd" string'}
    assert replies[3] == {"ok": False, "error": "RuntimeError: kaboom"}
    assert replies[4]["echo"] == {"cmd": "status", "x": 1}


def test_a_request_split_across_writes_is_one_request(served, tmp_path):
    with socket.socket(socket.AF_UNIX) as c:
        c.connect(str(tmp_path / "c.sock"))
        c.sendall(b'{"cmd":')
        c.sendall(b'"abort"}\n')
        c.settimeout(3)
        assert json.loads(c.recv(4096)) == {"ok": True, "echo": {"cmd": "abort"}}


def test_the_socket_is_mode_0660(served, tmp_path):
    assert stat.S_IMODE(os.stat(tmp_path / "c.sock").st_mode) == 0o660


def test_an_overlong_line_is_refused_and_the_server_keeps_serving(served, tmp_path):
    reply = talk(tmp_path / "c.sock", b"x" * 70000, 1)
    assert "longer than 65536 bytes" in reply[0]["error"]
    assert request(tmp_path / "c.sock", {"cmd": "status"})["ok"] is True


def test_a_stale_socket_file_is_replaced_but_a_live_one_is_not_stolen(served, tmp_path):
    with pytest.raises(ConfigError, match="another perchd serve is listening"):
        ControlServer(tmp_path / "c.sock", dict)
    stale = tmp_path / "stale.sock"
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(stale))  # bound, never listening: what a killed server leaves
    ControlServer(stale, dict).close()
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="exists and is not a socket"):
        ControlServer(tmp_path / "file", dict)


def test_a_socket_in_a_missing_directory_is_one_clear_error(tmp_path):
    with pytest.raises(ConfigError, match="cannot listen: No such file or directory"):
        ControlServer(tmp_path / "no" / "c.sock", dict)


def echo(req):
    return {"ok": True, "echo": req}


@pytest.fixture
def bounded(tmp_path):
    """At most 2 clients, closed after 30 s of silence on a clock the test moves."""
    s = Served(tmp_path / "b.sock", echo, clock=ManualClock(100.0), max_clients=2, idle_s=30.0)
    yield s
    s.close()


def held(s, n):
    """n more connections that send nothing, once the server has taken them all."""
    before = len(s.server.clients)
    conns = [socket.socket(socket.AF_UNIX) for _ in range(n)]
    for c in conns:
        c.settimeout(3)
        c.connect(str(s.server.path))
    wait_until(lambda: len(s.server.clients) >= before + n)
    return conns


def wait_until(cond, timeout=5.0):
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "the server loop never got there"
        time.sleep(0.01)


def test_a_duplicate_key_is_refused_in_one_line(served, tmp_path):
    replies = talk(
        tmp_path / "c.sock",
        b'{"cmd": "status", "cmd": "fly"}\n{"cmd": "status", "x": {"a": 1, "a": 2}}\n',
        2,
    )
    assert replies == [
        {"ok": False, "error": "malformed request: key 'cmd' given twice"},
        {"ok": False, "error": "malformed request: key 'a' given twice"},
    ]
    assert served.calls == []


def test_a_silent_client_is_closed_after_the_idle_timeout_and_a_talking_one_is_not(bounded):
    silent, talking = held(bounded, 2)
    bounded.server.clock.advance(20.0)
    talking.sendall(b'{"cmd": "status"}\n')
    assert json.loads(talking.makefile("rb").readline())["ok"] is True
    bounded.server.clock.advance(15.0)  # silent 35 s, talking 15 s
    assert json.loads(silent.makefile("rb").readline()) == {
        "ok": False,
        "error": "closed: nothing received for 30 s",
    }
    assert silent.recv(10) == b""
    talking.sendall(b'{"cmd": "status"}\n')
    assert json.loads(talking.makefile("rb").readline())["ok"] is True


def test_over_the_bound_only_abort_is_served(bounded):
    conns = held(bounded, 2)
    over = talk(bounded.server.path, b'{"cmd": "status"}\n', 1)[0]
    assert over == {
        "ok": False,
        "error": "2 clients connected already (the bound); over it only "
        "abort is served: try again once one closes",
    }
    assert talk(bounded.server.path, b'{"cmd": "abort"}\n', 1) == [
        {"ok": True, "echo": {"cmd": "abort"}}
    ]
    conns[0].sendall(b'{"cmd": "status"}\n')  # the held ones are served as before
    assert json.loads(conns[0].makefile("rb").readline())["ok"] is True


def test_a_full_reserve_gives_way_to_the_newest_connection(bounded):
    regular = held(bounded, 2)
    reserve = held(bounded, RESERVED_SLOTS)
    assert all(c.reserved for c in list(bounded.server.clients.values())[2:])
    assert talk(bounded.server.path, b'{"cmd": "abort"}\n', 1)[0]["echo"] == {"cmd": "abort"}
    assert json.loads(reserve[0].makefile("rb").readline())["error"].startswith(
        "2 clients connected already (the bound)"
    )
    bounded.server.clock.advance(RESERVED_WAIT_S + 0.1)  # a reserve slot is held briefly
    assert json.loads(reserve[1].makefile("rb").readline())["error"].startswith("closed: nothing")
    regular[0].sendall(b'{"cmd": "status"}\n')  # the bound's own clients were left alone
    assert json.loads(regular[0].makefile("rb").readline())["ok"] is True


def test_a_client_that_never_reads_its_replies_is_dropped_and_others_are_served(served, tmp_path):
    flood = socket.socket(socket.AF_UNIX)
    flood.connect(str(tmp_path / "c.sock"))
    flood.settimeout(10)
    lines = b'{"cmd": "status", "pad": "' + b"x" * 4000 + b'"}\n'
    try:
        for _ in range(2000):  # ~8 MB of replies it never reads
            flood.sendall(lines)
    except OSError:
        pass  # dropped mid-flood: the point
    assert request(tmp_path / "c.sock", {"cmd": "status"})["ok"] is True
    wait_until(lambda: len(served.server.clients) == 0)
    flood.close()
