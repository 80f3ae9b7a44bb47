"""Issue 17 item 4: a second `perchd sim` on a taken NatNet (or ZMQ) port is refused, exit 2,
instead of sharing the port and stealing the first one's clients."""

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


@pytest.mark.parametrize("scheme,free_port", [("natnet", free_udp_port),
                                              ("zmq", free_tcp_port)], ids=["natnet", "zmq"])
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
        done = subprocess.run([sys.executable, "-m", "perchd", "sim", "--pose-out",
                               f"natnet://127.0.0.1:{port}", "--setpoint-in",
                               "zmq://127.0.0.1:0", "--duration", "1"],
                              capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert done.returncode == 2, done.stderr
    assert "port is taken" in done.stderr and "ready" not in done.stderr
