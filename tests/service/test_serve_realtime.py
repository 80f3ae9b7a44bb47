"""[service] realtime: `perchd serve` puts its whole process under SCHED_FIFO at start-up;
where the system refuses, the service still runs, says once what is missing, and refuses
every flight with that line."""

from __future__ import annotations

import os
import shutil
import signal

import pytest
from svc import PLAN, NotifyListener, Serve, ctl

from perchd.core.errors import ConfigError
from perchd.core.realtime import RealtimeConfig
from perchd.service.config import config_from_dict

ROOT_USER = os.geteuid() == 0
REALTIME = "[service.realtime]\npriority = {prio}\nlock_memory = true\n"


@pytest.fixture
def notify(tmp_path):
    n = NotifyListener(tmp_path / "notify")
    yield n
    n.close()


def test_the_config_takes_an_inline_table_or_a_table_and_checks_it():
    inline = config_from_dict({"version": 1, "service": {"realtime": {"priority": 50, "cpu": 1}}})
    assert inline.service.realtime == RealtimeConfig(50, 1, True)
    assert config_from_dict({"version": 1}).service.realtime == RealtimeConfig()
    with pytest.raises(ConfigError, match=r"\[service.realtime\] priority: expected an integer"):
        config_from_dict({"version": 1, "service": {"realtime": {"priority": "high"}}})
    with pytest.raises(ConfigError, match="priority 120 is outside 0..99"):
        config_from_dict({"version": 1, "service": {"realtime": {"priority": 120}}})
    with pytest.raises(ConfigError, match="unknown key"):
        config_from_dict({"version": 1, "service": {"realtime": {"policy": "fifo"}}})


@pytest.mark.slow
def test_refused_the_service_runs_says_why_once_and_refuses_flights(tmp_path, notify):
    if shutil.which("prlimit") is None or (ROOT_USER and shutil.which("setpriv") is None):
        pytest.skip("needs util-linux prlimit and setpriv")
    drop = ("setpriv", "--inh-caps=-sys_nice", "--bounding-set=-sys_nice") if ROOT_USER else ()
    serve = Serve(
        tmp_path,
        notify,
        "--driver",
        "sim://",
        "--mocap",
        "sim://",
        tables=REALTIME.format(prio=50),
        prefix=("prlimit", "--rtprio=0", *drop),
    )
    try:
        notify.wait_for("READY=1")
        refused = ctl(serve.sock, "fly", str(PLAN))
        assert refused["ok"] is False
        assert refused["error"].startswith(
            "[service] realtime refused: SCHED_FIFO priority 50 refused"
        )
        assert "LimitRTPRIO=50" in refused["error"]
        assert ctl(serve.sock, "status")["scheduling"] == refused["error"]
        serve.proc.send_signal(signal.SIGTERM)
        code, err = serve.stop()
    finally:
        serve.kill()
    assert code == 0, err
    said = [line for line in err.splitlines() if "realtime refused" in line]
    assert len(said) == 1 and "flights are refused" in said[0]
    assert not (tmp_path / "logs").exists() or not list((tmp_path / "logs").iterdir())


@pytest.mark.slow
@pytest.mark.skipif(not ROOT_USER, reason="granted only with CAP_SYS_NICE (root here)")
def test_granted_every_thread_of_the_service_runs_fifo(tmp_path, notify):
    serve = Serve(
        tmp_path, notify, "--driver", "sim://", "--mocap", "sim://", tables=REALTIME.format(prio=1)
    )
    try:
        notify.wait_for("READY=1")
        status = ctl(serve.sock, "status")
        tids = [int(t) for t in os.listdir(f"/proc/{serve.proc.pid}/task")]
        policies = {os.sched_getscheduler(t) for t in tids}
        serve.proc.send_signal(signal.SIGTERM)
        code, err = serve.stop()
    finally:
        serve.kill()
    assert status["scheduling"] == "SCHED_FIFO priority 1, memory locked"
    assert policies == {os.SCHED_FIFO}
    assert code == 0 and "scheduling: SCHED_FIFO priority 1, memory locked" in err
