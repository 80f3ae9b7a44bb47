"""SIGHUP with a setting out of its range (flight/bounds.py): the service keeps the config it
flies, and its journal line names the key, the value and the range."""

import signal

import pytest
from svc import Serve, ctl

pytestmark = pytest.mark.slow
REFUSED = "[tau_gains] kp_fast = -50 m/s^2: outside its range 0..200 m/s^2"


def test_a_reload_with_a_wrong_sign_gain_keeps_the_old_config_and_names_the_key(tmp_path, notify):
    serve = Serve(tmp_path, notify, "--driver", "sim://", "--mocap", "sim://")
    try:
        notify.wait_for("READY=1")
        good = serve.config.read_text()
        serve.config.write_text(good + "[tau_gains]\nkp_fast = -50\n")
        serve.proc.send_signal(signal.SIGHUP)
        notify.wait_for(f"STATUS=cf1: idle, reload failed: perchd.toml: {REFUSED}")
        assert ctl(serve.sock, "status")["vehicle"] == "cf1"
        serve.proc.send_signal(signal.SIGTERM)
        code, err = serve.stop()
    finally:
        serve.kill()
    assert code == 0 and "config not reloaded, keeping the old one" in err
    assert REFUSED in err
