"""Socket activation: `perchd serve` takes its control socket at fd 3 as systemd passes it
(LISTEN_FDS, LISTEN_PID, LISTEN_FDNAMES), and refuses an fd of the wrong kind in one line."""

import json
import os
import signal
import socket

import pytest
from svc import Serve, ctl

from perchd.core.errors import ConfigError
from perchd.service.activation import activated_socket

pytestmark = pytest.mark.solo  # real-time bounds: see tests/conftest.py


def listening_unix(path) -> socket.socket:
    """What a .socket unit with ListenStream=PATH and SocketMode=0660 holds."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.bind(str(path))
    os.chmod(path, 0o660)
    s.listen(8)
    return s


@pytest.mark.slow
def test_serve_answers_on_the_socket_systemd_passed_and_leaves_it_in_place(tmp_path, notify):
    path = tmp_path / "activated.sock"
    listen = listening_unix(path)
    early = socket.socket(socket.AF_UNIX)  # a client before the service runs: queued
    early.connect(str(path))
    early.sendall(b'{"cmd": "status"}\n')
    serve = Serve(tmp_path, notify, "--driver", "sim://", "--mocap", "sim://", listen=listen)
    try:
        notify.wait_for("READY=1")
        early.settimeout(5)
        assert json.loads(early.makefile().readline())["state"] == "idle"
        assert ctl(path, "status")["ok"] is True
        assert not (tmp_path / "control.sock").exists()  # the configured path was not bound
        serve.proc.send_signal(signal.SIGTERM)
        code, err = serve.stop()
    finally:
        early.close()
        serve.kill()
    assert code == 0
    assert f"socket {path} (from systemd)" in err
    assert path.exists()  # systemd's socket file stays for the next start
    listen.close()


@pytest.mark.parametrize("kind", ["udp", "unix-not-listening"])
def test_a_passed_fd_of_the_wrong_kind_is_refused_in_one_line(tmp_path, notify, kind):
    if kind == "udp":
        wrong = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        wrong.bind(("127.0.0.1", 0))
        said = "fd 3 is AF_INET SOCK_DGRAM"
    else:
        wrong = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        wrong.bind(str(tmp_path / "idle.sock"))
        said = "fd 3 is AF_UNIX SOCK_STREAM, not listening"
    serve = Serve(tmp_path, notify, "--driver", "sim://", "--mocap", "sim://", listen=wrong)
    try:
        code, err = serve.stop()
    finally:
        serve.kill()
        wrong.close()
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("perchd serve: socket activation: ")
    assert said in err and "not a listening AF_UNIX stream socket" in err
    assert notify.count("READY=1") == 0


def test_variables_meant_for_another_process_are_ignored_and_removed():
    env = {"LISTEN_FDS": "1", "LISTEN_PID": str(os.getpid() + 1), "LISTEN_FDNAMES": "control"}
    assert activated_socket(env) is None
    assert env == {}  # not handed on to the processes the service starts


def test_several_fds_need_one_named_control():
    env = {"LISTEN_FDS": "2", "LISTEN_PID": str(os.getpid()), "LISTEN_FDNAMES": "a:b"}
    with pytest.raises(ConfigError, match="not exactly one named 'control'"):
        activated_socket(env)
