"""`perchd ctl` is readable by default, JSON with --json, refusals on stderr,
and says what to check when no service is there."""

import subprocess
import sys
from pathlib import Path

from perchd.commands.ctl import lines

ROOT = Path(__file__).resolve().parents[2]


def test_no_service_says_what_to_check(tmp_path):
    sock = tmp_path / "none.sock"
    done = subprocess.run([sys.executable, "-m", "perchd", "ctl", "--socket", str(sock), "status"],
                          capture_output=True, text=True, timeout=30, cwd=ROOT)
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.strip() == (f"perchd ctl: is perchd serve running? (socket {sock}: "
                                   "No such file or directory)")


def test_a_reply_reads_as_key_value_lines():
    reply = {"ok": True, "state": "idle", "vehicle": "cf1",
             "last": {"outcome": "CONTACT", "contact_speed": 0.98765, "detail": None}}
    assert lines(reply) == ["state: idle", "vehicle: cf1", "last.outcome: CONTACT",
                            "last.contact_speed: 0.9877", "last.detail: -"]


def test_mocap_timeout_reaches_the_natnet_connect():
    from perchd.commands.mocap import with_timeout
    assert with_timeout("natnet://h?body=cf1", 1.0) == "natnet://h?body=cf1&timeout=1"
    assert with_timeout("natnet://h?body=cf1&timeout=3", 1.0).endswith("timeout=3")
    assert with_timeout("zmq://h:1?body=cf1", 1.0) == "zmq://h:1?body=cf1"
