"""`perchd serve` checks plan_dir and log_dir before READY=1 and fails at
start with one line naming the key; the per-instance unit's LogsDirectory is where a default
log_dir goes."""

import configparser
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from svc import NotifyListener

from perchd.service.config import ServiceConfig, config_from_dict
from perchd.service.daemon import apply_overrides

SYSTEMD = Path(__file__).resolve().parents[2] / "systemd"


@pytest.mark.parametrize("key", ["log_dir", "plan_dir"])
def test_an_unusable_directory_stops_the_start_before_ready(tmp_path, key):
    (tmp_path / "file").write_text("not a directory")
    dirs = {
        "log_dir": tmp_path / "logs",
        "plan_dir": tmp_path / "plans",
        key: tmp_path / "file" / "sub",
    }
    config = tmp_path / "perchd.toml"
    config.write_text(
        "version = 1\n[service]\n"
        + f'socket = "{tmp_path / "c.sock"}"\n'
        + "".join(f'{k} = "{v}"\n' for k, v in dirs.items())
    )
    notify = NotifyListener(tmp_path / "notify.sock")
    env = {**os.environ, "NOTIFY_SOCKET": notify.address}
    done = subprocess.run(
        [sys.executable, "-m", "perchd", "serve", "--config", str(config)],
        env=env,
        capture_output=True,
        text=True,
        timeout=30,
    )
    notify.sock.settimeout(0.2)
    try:
        while True:
            notify.messages.append(notify.sock.recv(4096).decode())
    except OSError:
        pass
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and f"[service] {key}" in lines[0] and "cannot create" in lines[0]
    assert not any("READY=1" in m.split("\n") for m in notify.messages)


def test_a_missing_log_dir_is_made(tmp_path):
    from perchd.service.daemon import check_dirs

    svc = ServiceConfig(plan_dir=str(tmp_path / "p"), log_dir=str(tmp_path / "l" / "m"))
    check_dirs(svc)
    assert (tmp_path / "l" / "m").is_dir() and (tmp_path / "p").is_dir()


def test_default_dirs_follow_the_unit():
    config = config_from_dict({"version": 1})
    env = {"LOGS_DIRECTORY": "/var/log/perchd/cf1", "STATE_DIRECTORY": "/var/lib/perchd/cf1"}
    svc = apply_overrides(config, {}, env).service
    assert (svc.log_dir, svc.plan_dir) == ("/var/log/perchd/cf1", "/var/lib/perchd/cf1/plans")
    given = config_from_dict({"version": 1, "service": {"log_dir": "/srv/logs"}})
    assert apply_overrides(given, {}, env).service.log_dir == "/srv/logs"
    assert apply_overrides(given, {"log_dir": "/x"}, env).service.log_dir == "/x"


@pytest.mark.parametrize(
    "unit, logs", [("perchd.service", "perchd"), ("perchd@.service", "perchd/%i")]
)
def test_the_units_logs_directory_agrees_with_the_default_log_dir(unit, logs):
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.read_string((SYSTEMD / unit).read_text())
    assert parser["Service"]["LogsDirectory"] == logs
    default = ServiceConfig().log_dir
    env = {"LOGS_DIRECTORY": "/var/log/" + logs.replace("%i", "cf1")}
    svc = apply_overrides(config_from_dict({"version": 1}), {}, env).service
    if logs == "perchd":
        assert svc.log_dir == default == env["LOGS_DIRECTORY"]
    else:
        assert svc.log_dir == "/var/log/perchd/cf1"
    assert re.search(
        r'log_dir = "' + re.escape(default) + r'"', (SYSTEMD / "perchd.toml").read_text()
    )
