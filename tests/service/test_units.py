"""The systemd units pass `systemd-analyze verify` and say what the service needs."""

import configparser
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from perchd.commands import failsafe as failsafe_command
from perchd.drivers import cflink
from perchd.service import activation

SYSTEMD = Path(__file__).resolve().parents[2] / "systemd"
ANALYZE = shutil.which("systemd-analyze") or "/usr/bin/systemd-analyze"


def staged(tmp_path: Path, name: str, as_name: str | None = None, edit=lambda s: s) -> Path:
    """The unit in a temporary directory, ExecStart pointing at an executable that exists."""
    text = (
        (SYSTEMD / name)
        .read_text()
        .replace("/opt/perchd/bin/perchd", sys.executable + " -m perchd")
    )
    out = tmp_path / (as_name or name)
    out.write_text(edit(text))
    return out


def require_analyze() -> None:
    if not Path(ANALYZE).exists():
        pytest.skip("systemd-analyze is not installed (.ci/run installs it)")


def verify(*units: Path) -> subprocess.CompletedProcess:
    require_analyze()
    return subprocess.run(
        [ANALYZE, "verify", *map(str, units)], capture_output=True, text=True, timeout=60
    )


UNITS = [
    ("perchd.service", None),
    ("perchd@.service", "perchd@cf1.service"),
    ("perchd.socket", None),
    ("perchd@.socket", "perchd@cf1.socket"),
]
OLDER_SYSTEMD = "Type=notify\nExecReload=/bin/kill -HUP $MAINPID"
"""systemd/README.md's replacement for Type=notify-reload on systemd before 253."""


def systemd_version() -> int:
    out = subprocess.run([ANALYZE, "--version"], capture_output=True, text=True).stdout
    return int(out.split()[1])


def test_every_unit_verifies_without_a_word(tmp_path):
    """Before systemd 253 (Debian 12 has 252) notify-reload is unknown: verify the units as
    the README says to run them there, and that the type is the one thing 252 objects to."""
    require_analyze()
    if systemd_version() >= 253:
        done = verify(*(staged(tmp_path, n, a) for n, a in UNITS))
        assert done.returncode == 0 and (done.stdout + done.stderr).strip() == ""
        return
    as_is = verify(*(staged(tmp_path, n, a) for n, a in UNITS))
    complaints = (as_is.stdout + as_is.stderr).strip().splitlines()
    assert len(complaints) == 2 and all(
        c.endswith("Failed to parse service type, ignoring: notify-reload") for c in complaints
    )
    older = tmp_path / "older"
    older.mkdir()
    done = verify(
        *(
            staged(older, n, a, edit=lambda s: s.replace("Type=notify-reload", OLDER_SYSTEMD))
            for n, a in UNITS
        )
    )
    assert done.returncode == 0 and (done.stdout + done.stderr).strip() == ""


def test_the_readme_gives_the_older_systemd_lines_the_test_verifies():
    assert OLDER_SYSTEMD in (SYSTEMD / "README.md").read_text()


def test_verify_does_complain_about_a_broken_unit(tmp_path):
    broken = staged(
        tmp_path, "perchd.service", edit=lambda s: s.replace("Type=notify-reload", "Type=notifyy")
    )
    done = verify(broken)
    assert "Failed to parse service type" in done.stdout + done.stderr


def section(name: str, table: str = "Service") -> dict[str, str]:
    p = configparser.ConfigParser(strict=False, interpolation=None)
    p.optionxform = str
    p.read_string((SYSTEMD / name).read_text())
    return dict(p[table])


service_section = section


@pytest.mark.parametrize("name", ["perchd.service", "perchd@.service"])
def test_the_unit_is_a_hardened_notify_service_with_a_watchdog(name):
    s = service_section(name)
    assert s["Type"] == "notify-reload" and s["NotifyAccess"] == "main" and s["WatchdogSec"] == "5"
    assert s["Restart"] == "on-failure" and s["User"] == "perchd"
    assert s["SupplementaryGroups"] == "plugdev"
    assert s["NoNewPrivileges"] == "yes" and s["ProtectSystem"] == "strict"
    assert s["ProtectHome"] == "yes" and s["PrivateTmp"] == "yes"
    assert s["RestrictAddressFamilies"].split() == ["AF_UNIX", "AF_INET", "AF_INET6", "AF_NETLINK"]
    for d in ("RuntimeDirectory", "StateDirectory", "LogsDirectory"):
        assert s[d].startswith("perchd")


def test_each_instance_has_its_own_config_socket_and_directories():
    s = service_section("perchd@.service")
    assert "--config /etc/perchd/%i.toml" in s["ExecStart"]
    assert "--socket /run/perchd/%i/control.sock" in s["ExecStart"]
    assert s["RuntimeDirectory"] == "perchd/%i" and s["LogsDirectory"] == "perchd/%i"


def test_the_udev_rule_gives_plugdev_the_crazyradio_and_the_crazyflie():
    rules = [
        r
        for r in (SYSTEMD / "70-crazyradio.rules").read_text().splitlines()
        if r and not r.startswith("#")
    ]
    products = {r.split('ATTRS{idProduct}=="')[1][:4] for r in rules}
    assert products == {"7777", "0101"}
    assert all(
        'ATTRS{idVendor}=="1915"' in r and 'GROUP="plugdev"' in r and 'MODE="0664"' in r
        for r in rules
    )


@pytest.mark.parametrize("name", ["perchd.service", "perchd@.service"])
def test_the_failsafe_runs_after_the_service_with_its_config_and_time_to_land(name):
    s = section(name)
    config = s["ExecStart"].split("--config ")[1].split()[0]
    assert s["ExecStopPost"] == f"/opt/perchd/bin/perchd failsafe --config {config}"
    assert s["KillMode"] == "control-group"  # mixed would SIGKILL the link keeper at once
    keeper_s = cflink.DESCENT_MAX_S + cflink.PING_S
    assert float(s["TimeoutStopSec"]) > keeper_s + failsafe_command.DEFAULT_TIMEOUT_S
    assert s["RuntimeDirectoryPreserve"] == "yes"  # the .socket's file lives there


@pytest.mark.parametrize("name", ["perchd.service", "perchd@.service"])
def test_real_time_is_granted_not_imposed(name):
    s = section(name)
    assert int(s["LimitRTPRIO"]) >= 50 and s["LimitMEMLOCK"] == "infinity"
    assert s["RestrictRealtime"] == "no"
    assert "CPUSchedulingPolicy" not in s and "CPUAffinity" not in s  # commented out
    text = (SYSTEMD / name).read_text()
    assert "#CPUSchedulingPolicy=fifo" in text and "#CPUAffinity=" in text


@pytest.mark.parametrize(
    "service, sock", [("perchd.service", "perchd.socket"), ("perchd@.service", "perchd@.socket")]
)
def test_each_socket_unit_listens_where_its_service_would_bind(service, sock):
    s, k = section(service), section(sock, "Socket")
    assert k["ListenStream"] == s["ExecStart"].split("--socket ")[1].split()[0]
    assert k["FileDescriptorName"] == activation.FD_NAME
    assert (k["SocketMode"], k["SocketUser"], k["SocketGroup"]) == ("0660", s["User"], s["Group"])
    assert "Accept" not in k  # one service for all clients, not one per connection
