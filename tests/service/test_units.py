"""The systemd units pass `systemd-analyze verify` and say what the service needs."""

import configparser
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

SYSTEMD = Path(__file__).resolve().parents[2] / "systemd"
ANALYZE = shutil.which("systemd-analyze") or "/usr/bin/systemd-analyze"


def staged(tmp_path: Path, name: str, as_name: str | None = None, edit=lambda s: s) -> Path:
    """The unit in a temporary directory, ExecStart pointing at an executable that exists."""
    text = (SYSTEMD / name).read_text().replace("/opt/perchd/bin/perchd", sys.executable + " -m perchd")
    out = tmp_path / (as_name or name)
    out.write_text(edit(text))
    return out


def verify(*units: Path) -> subprocess.CompletedProcess:
    if not Path(ANALYZE).exists():
        pytest.skip("systemd-analyze is not installed (.ci/run installs it)")
    return subprocess.run([ANALYZE, "verify", *map(str, units)], capture_output=True,
                          text=True, timeout=60)


def test_both_units_verify_without_a_word(tmp_path):
    done = verify(staged(tmp_path, "perchd.service"),
                  staged(tmp_path, "perchd@.service", "perchd@cf1.service"))
    assert done.returncode == 0 and (done.stdout + done.stderr).strip() == ""


def test_verify_does_complain_about_a_broken_unit(tmp_path):
    broken = staged(tmp_path, "perchd.service", edit=lambda s: s.replace("Type=notify", "Type=notifyy"))
    done = verify(broken)
    assert "Failed to parse service type" in done.stdout + done.stderr


def service_section(name: str) -> dict[str, str]:
    p = configparser.ConfigParser(strict=False, interpolation=None)
    p.optionxform = str
    p.read_string((SYSTEMD / name).read_text())
    return dict(p["Service"])


@pytest.mark.parametrize("name", ["perchd.service", "perchd@.service"])
def test_the_unit_is_a_hardened_notify_service_with_a_watchdog(name):
    s = service_section(name)
    assert s["Type"] == "notify" and s["NotifyAccess"] == "main" and s["WatchdogSec"] == "5"
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
    rules = [r for r in (SYSTEMD / "70-crazyradio.rules").read_text().splitlines()
             if r and not r.startswith("#")]
    products = {r.split('ATTRS{idProduct}=="')[1][:4] for r in rules}
    assert products == {"7777", "0101"}
    assert all('ATTRS{idVendor}=="1915"' in r and 'GROUP="plugdev"' in r and 'MODE="0664"' in r
               for r in rules)
