"""The control socket server (docs/contracts.md §4) on a real Unix socket, driven by select."""

import json
import os
import select
import socket
import stat
import threading

import pytest

from perchd.core.errors import ConfigError
from perchd.service.control_socket import ControlServer, request


class Served:
    """A ControlServer polled from a thread, as the daemon's loop does."""

    def __init__(self, path, dispatch):
        self.server = ControlServer(path, dispatch)
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self):
        while not self.done.is_set():
            for fd in select.select(self.server.fds(), [], [], 0.05)[0]:
                self.server.handle(fd)

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
    replies = talk(tmp_path / "c.sock", b'{"cmd":"status"}\nnot json\n[1,2]\n{"cmd":"boom"}\n'
                                        b'{"cmd": "status", "x": 1}\n', 5)
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
