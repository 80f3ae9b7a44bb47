"""`perchd bench loop --json` reports every loop figure with min/median/p99/max, from runs
that really happened (ticks, flights, matched poses); it never judges the timings."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

SPREAD = {"min_us", "median_us", "p99_us", "max_us"}


def bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "perchd", "bench", "loop", *args],
        capture_output=True,
        text=True,
        timeout=120,
    )


def assert_spread(s: dict) -> None:
    assert set(s) == SPREAD
    assert 0.0 <= s["min_us"] <= s["median_us"] <= s["p99_us"] <= s["max_us"]


@pytest.mark.slow
def test_a_short_json_run_has_every_figure_and_they_come_from_real_runs():
    out = bench("--json", "--seconds", "0.4")
    assert out.returncode == 0, out.stderr
    fig = json.loads(out.stdout)
    assert set(fig) == {
        "seconds",
        "load_before",
        "agent_compute_hot",
        "fixed_500hz",
        "fixed_100hz",
        "zmq_mocap",
        "zmq_fixed",
        "zmq_echo",
        "idle_500hz",
        "load_after",
    }
    assert fig["seconds"] == 0.4

    for key, hz in (("fixed_500hz", 500), ("fixed_100hz", 100)):
        f = fig[key]
        for name in ("lateness", "period_deviation", "agent_compute", "tick_compute"):
            assert_spread(f[name])
        # every deadline in the run was either ticked or counted as missed
        assert f["ticks"] + f["missed"] == pytest.approx(hz * f["seconds"], abs=3)
        assert 0 <= f["overruns"] <= f["ticks"] and 0.0 < f["cpu_fraction"] <= 2.0
        assert f["overruns_per_min"] == pytest.approx(60 * f["overruns"] / f["seconds"])
        assert f["gc_collections"] == 0 and f["steal_ms"] >= 0.0

    hot = fig["agent_compute_hot"]
    assert hot["ticks"] == 5000
    assert_spread({k: v for k, v in hot.items() if k != "ticks"})

    for mode, sync, mocap_hz in (("zmq_mocap", "mocap", 100.0), ("zmq_fixed", "fixed", 120.0)):
        z = fig[mode]
        assert (z["sync"], z["rate_hz"], z["mocap_hz"]) == (sync, 100.0, mocap_hz)
        assert z["flights"] == len(z["outcomes"]) >= 1
        assert set(z["outcomes"]) <= {"SIGNAL", "CONTACT"}  # cut short, or perched
        assert z["setpoints_matched"] >= 50  # >= 1 s of flight at 100 Hz, poses matched
        for key in ("latency_sockets", "latency_agent", "tick_compute", "agent_compute", "jitter"):
            assert_spread(z[key])
        # a setpoint cannot reach the rig before its pose reached the agent
        assert z["latency_sockets"]["min_us"] > z["latency_agent"]["min_us"] > 0.0
        assert 0.0 < z["cpu_fraction"] < 1.0

    echo = fig["zmq_echo"]  # the sockets alone: an echo, not an agent, so no loop summary
    assert echo["sync"] == "echo" and echo["setpoints_matched"] >= 50
    assert_spread(echo["latency_sockets"])
    assert echo["outcomes"] == [None] * echo["flights"] and echo["cpu_fraction"] == 0.0

    idle = fig["idle_500hz"]
    assert_spread(idle["lateness"])
    assert idle["ticks"] + idle["missed"] == pytest.approx(500 * idle["seconds"], abs=3)


def test_the_text_report_names_each_figure_and_its_target():
    from perchd.bench.loop import rows, text

    s = {"min_us": 1.0, "median_us": 2.0, "p99_us": 3.0, "max_us": 4.0}
    z = {
        "sync": "mocap",
        "rate_hz": 100.0,
        "mocap_hz": 100.0,
        "flights": 1,
        "outcomes": ["CONTACT"],
        "setpoints_matched": 400,
        "overruns": 0,
        "cpu_fraction": 0.05,
        "latency_sockets": s,
        "latency_agent": s,
        "tick_compute": s,
        "agent_compute": s,
        "jitter": s,
    }
    fig = {
        "load_before": 0.1,
        "load_after": 0.2,
        "agent_compute_hot": {"ticks": 5, **s},
        "fixed_500hz": {
            "lateness": s,
            "period_deviation": s,
            "agent_compute": s,
            "ticks": 2500,
            "seconds": 5.0,
            "overruns": 0,
            "missed": 0,
            "cpu_fraction": 0.04,
            "rate_hz": 500.0,
            "overruns_per_min": 0.0,
            "steal_ms": 0.0,
            "gc_collections": 0,
        },
        "fixed_100hz": {
            "lateness": s,
            "period_deviation": s,
            "agent_compute": s,
            "ticks": 500,
            "seconds": 5.0,
            "overruns": 1,
            "missed": 1,
            "cpu_fraction": 0.01,
            "rate_hz": 100.0,
            "overruns_per_min": 12.0,
            "steal_ms": 30.0,
            "gc_collections": 0,
        },
        "zmq_mocap": z,
        "zmq_fixed": {**z, "sync": "fixed", "mocap_hz": 120.0},
        "zmq_echo": {**z, "sync": "echo"},
        "idle_500hz": {
            "lateness": s,
            "ticks": 2500,
            "seconds": 5.0,
            "overruns": 0,
            "overruns_per_min": 0.0,
            "steal_ms": 10.0,
        },
    }
    report = text(fig)
    for name, _, target in rows(fig):
        assert f"{name}" in report and target in report
    assert "500 Hz loop: 2500 ticks in 5.0 s, 0 overruns (0.0 per minute, target 0)" in report
    assert "100 Hz loop: 500 ticks in 5.0 s, 1 overruns (12.0 per minute, target 0)" in report
    assert "agent CPU 5.0 % of a core" in report


def test_a_seconds_value_out_of_range_is_one_line_and_exit_2():
    out = bench("--seconds", "0")
    assert out.returncode == 2
    assert out.stderr.strip() == "perchd bench: --seconds 0 is outside 0.1..3600 s"
