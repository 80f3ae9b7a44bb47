"""`perchd ctl` is readable by default, JSON with --json, refusals on stderr,
and says in one line why no service answered."""

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from perchd.commands.ctl import abort, lines
from perchd.core.errors import LinkError
from perchd.service.control_client import Unreachable, exchange

ROOT = Path(__file__).resolve().parents[2]


def ctl_status(sock: Path, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "perchd", "ctl", "--socket", str(sock), "status"],
        capture_output=True,
        text=True,
        timeout=30,
        cwd=ROOT,
        check=False,
        **kw,
    )


def test_no_service_says_what_to_check(tmp_path):
    sock = tmp_path / "none.sock"
    done = ctl_status(sock)
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.strip() == (
        f"perchd ctl: no control socket at {sock}: is perchd serve "
        "running, and is --socket its path?"
    )


def test_a_socket_nobody_listens_on_is_named_as_left_behind(tmp_path):
    sock = tmp_path / "stale.sock"
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(sock))  # bound, never listening: what a killed service leaves
        done = ctl_status(sock)
    assert done.returncode == 1
    assert done.stderr.strip().startswith(
        f"perchd ctl: nothing listens on {sock}: a socket left by"
    )


def error_as(uid: int, call) -> str:
    """The LinkError text `call` raises in a forked child running as uid (and gid) `uid`."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: drop to uid, call, report through the pipe, never return
        try:
            os.setgroups([])
            os.setgid(uid)
            os.setuid(uid)
            call()
            out = "no error"
        except LinkError as err:
            out = str(err)
        os.write(w, out.encode())
        os._exit(0)
    os.close(w)
    with os.fdopen(r, "rb") as f:
        text = f.read().decode()
    os.waitpid(pid, 0)
    return text


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to act as another user")
def test_a_socket_this_user_may_not_open_says_permission_denied(tmp_path):
    tmp_path.chmod(0o755)
    sock = tmp_path / "c.sock"
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(sock))
        sock.chmod(0o660)
        s.listen(1)
        text = error_as(65534, lambda: exchange(sock, {"cmd": "status"}))
    assert text == (
        f"permission denied on {sock} for uid 65534: the socket is for its owner and "
        "group (join the group, or [service] allowed_users)"
    )


def test_a_listener_that_never_replies_is_a_timeout_in_one_line(tmp_path):
    sock = tmp_path / "c.sock"
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(sock))
        s.listen(1)  # connections queue, nobody accepts or answers
        with pytest.raises(Unreachable) as err:
            exchange(sock, {"cmd": "status"}, timeout_s=0.2)
    assert str(err.value) == f"perchd serve at {sock} did not answer: waited 0.2 s for its reply"
    assert err.value.server_pid == os.getpid()


def test_an_abort_refused_by_a_process_that_is_not_perchd_serve_is_not_signalled(tmp_path):
    sock = tmp_path / "c.sock"
    with socket.socket(socket.AF_UNIX) as s:  # this test process listens: never signalled
        s.bind(str(sock))
        s.listen(1)
        with pytest.raises(
            LinkError, match="^abort not delivered: perchd serve at .* did not answer"
        ):
            abort(str(sock), timeout_s=0.2)


def test_a_reply_reads_as_key_value_lines():
    reply = {
        "ok": True,
        "state": "idle",
        "vehicle": "cf1",
        "last": {"outcome": "CONTACT", "contact_speed": 0.98765, "detail": None},
    }
    assert lines(reply) == [
        "state: idle",
        "vehicle: cf1",
        "last.outcome: CONTACT",
        "last.contact_speed: 0.9877",
        "last.detail: -",
    ]


def test_mocap_timeout_reaches_the_natnet_connect():
    from perchd.commands.mocap import with_timeout

    assert with_timeout("natnet://h?body=cf1", 1.0) == "natnet://h?body=cf1&timeout=1"
    assert with_timeout("natnet://h?body=cf1&timeout=3", 1.0).endswith("timeout=3")
    assert with_timeout("zmq://h:1?body=cf1", 1.0) == "zmq://h:1?body=cf1"
