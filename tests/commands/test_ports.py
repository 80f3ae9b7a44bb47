"""A port (or control socket) already taken is bad input, exit 2 (docs/contracts.md §6): a
second listener is refused instead of sharing the port and stealing the first one's clients."""

import socket
import subprocess
import sys
from pathlib import Path

import pytest

from perchd.core.clock import MonotonicClock
from perchd.core.errors import UriError
from perchd.mocap.outputs import open_pose_output

ROOT = Path(__file__).resolve().parents[2]


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize(
    "scheme,free_port", [("natnet", free_udp_port), ("zmq", free_tcp_port)], ids=["natnet", "zmq"]
)
def test_a_second_pose_output_on_a_taken_port_is_refused_as_bad_input(scheme, free_port):
    uri = f"{scheme}://127.0.0.1:{free_port()}"
    first = open_pose_output(uri, ["cf1"], MonotonicClock())
    try:
        with pytest.raises(UriError, match="port is taken"):
            open_pose_output(uri, ["cf1"], MonotonicClock())
    finally:
        first.close()


def test_perchd_sim_on_a_taken_natnet_port_exits_2():
    port = free_udp_port()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind(("127.0.0.1", port))
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "perchd",
                "sim",
                "--pose-out",
                f"natnet://127.0.0.1:{port}",
                "--setpoint-in",
                "zmq://127.0.0.1:0",
                "--duration",
                "1",
            ],
            capture_output=True,
            text=True,
            timeout=60,
            cwd=ROOT,
        )
    assert done.returncode == 2, done.stderr
    assert "port is taken" in done.stderr and "ready" not in done.stderr


def perchd(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "perchd", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )


@pytest.mark.parametrize("side", ["mocap", "driver"])
def test_perchd_fly_binding_a_taken_zmq_port_exits_2_naming_the_uri(side, tmp_path):
    """docs/contracts.md §6: a taken port is bad input (2), not a failed link (1)."""
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen(1)
        taken = holder.getsockname()[1]
        mocap = f"zmq://127.0.0.1:{taken if side == 'mocap' else free_tcp_port()}?body=cf1&bind=1"
        driver = f"zmq://127.0.0.1:{taken if side == 'driver' else free_tcp_port()}?bind=1&wait=0.1"
        done = perchd(
            "fly",
            "plans/case1-ipts-n3.json",
            "--driver",
            driver,
            "--mocap",
            mocap,
            "--log",
            str(tmp_path / "f.jsonl"),
            "--state",
            str(tmp_path / "v.json"),
        )
    uri = mocap if side == "mocap" else driver
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "port is taken" in done.stderr
    assert uri in done.stderr


def serve_once(tmp: Path, sock: Path) -> subprocess.Popen:
    config = tmp / "perchd.toml"
    config.write_text(
        f'version = 1\n[service]\nsocket = "{sock}"\nplan_dir = "{tmp}"\n'
        f'log_dir = "{tmp / "logs"}"\n'
    )
    return subprocess.Popen(
        [sys.executable, "-m", "perchd", "serve", "--config", str(config)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )


def test_a_second_perchd_serve_on_a_live_control_socket_exits_2_naming_it(tmp_path):
    sock = tmp_path / "control.sock"
    first = serve_once(tmp_path, sock)
    try:
        while not sock.exists():
            assert first.poll() is None, first.stderr.read()
        second = serve_once(tmp_path, sock)
        _, err = second.communicate(timeout=60)
    finally:
        first.terminate()
        first.communicate(timeout=20)
    assert second.returncode == 2, err
    assert err.count("\n") == 1 and str(sock) in err and "another perchd serve" in err
    assert first.returncode == 0  # SIGTERM: a service's normal stop


def test_a_control_socket_path_too_long_for_af_unix_is_one_line_naming_it(tmp_path):
    deep = tmp_path / ("d" * 60) / ("e" * 60)
    deep.mkdir(parents=True)
    sock = deep / "control.sock"
    proc = serve_once(tmp_path, sock)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2, err
    assert err.count("\n") == 1 and str(sock) in err and "too long" in err and "107" in err
    assert "None" not in err
