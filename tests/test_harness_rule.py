"""The harness rule the conftest checks after every test (tests/helpers/stale.py): a flight
reading a pose stream of this machine flies the harness's stale limit."""

from __future__ import annotations

import json
import os
import threading

import pytest
from stale import HARNESS_STALE_S, below_the_harness_limit, harness_config
from svc import PLAN

from perchd.cli import main
from perchd.service.config import load_config


@pytest.fixture(scope="module")
def header(tmp_path_factory) -> dict:
    """The header of a real flight log (sim:// on both links, the simulated clock)."""
    log = tmp_path_factory.mktemp("flown") / "f.jsonl"
    assert (
        main(["fly", str(PLAN), "--driver", "sim://", "--mocap", "sim://", "--log", str(log)]) == 0
    )
    return json.loads(log.read_text().splitlines()[0])


def logged(root, name: str, header: dict, mocap: str, stale_s: float | None) -> None:
    h = json.loads(json.dumps(header))
    h["mocap"], h["config"]["safety"]["stale_timeout_s"] = mocap, stale_s
    (root / f"{name}.jsonl").write_text(json.dumps(h) + "\n")


@pytest.mark.parametrize(
    "mocap, stale_s, flagged",
    [
        ("sim://", None, False),  # the simulated clock: nothing is descheduled
        ("sim://?noise=0.001", 0.03, False),
        ("natnet://127.0.0.1:1511", None, True),  # the default: three mocap periods
        ("zmq://127.0.0.1:5555?body=cf1", 0.03, True),
        ("natnet://127.0.0.1:1511", HARNESS_STALE_S, False),
        ("motioncapture://optitrack?hostname=127.0.0.1", 1.0, False),
    ],
)
def test_a_live_stream_flown_below_the_harness_limit_is_named(
    header, tmp_path_factory, mocap, stale_s, flagged
):
    root = tmp_path_factory.mktemp("logs")  # not tmp_path: the conftest checks that one
    logged(root, "f", header, mocap, stale_s)
    (root / "other.jsonl").write_text('{"not": "a flight log"}\n[1, 2]\n')
    found = below_the_harness_limit(root)
    assert found == ([f"f.jsonl: {mocap}, stale_timeout_s {stale_s}"] if flagged else [])


def test_the_harness_config_holds_the_limit_and_the_tables_given(tmp_path):
    plain = load_config(harness_config(tmp_path)).flight
    assert plain.safety.stale_timeout_s == HARNESS_STALE_S
    own = load_config(harness_config(tmp_path, "[safety]\nstale_timeout_s = 0.04\n")).flight
    assert own.safety.stale_timeout_s == 0.04  # a [safety] of its own replaces the harness's
    replan = load_config(harness_config(tmp_path, '[trigger]\npolicy = "replan"\n')).flight
    assert replan.safety.stale_timeout_s == HARNESS_STALE_S
    assert replan.trigger.policy.value == "replan"


def test_a_fifo_named_like_a_log_is_passed_over_not_opened(tmp_path_factory):
    """Tests make FIFOs to refuse (tests/logs, tests/fuzz): opening one would wait forever."""
    root = tmp_path_factory.mktemp("fifo")
    os.mkfifo(root / "f.jsonl")
    found: list = []
    check = threading.Thread(target=lambda: found.append(below_the_harness_limit(root)))
    check.start()
    check.join(5.0)
    if check.is_alive():  # release the open() so the thread ends
        os.close(os.open(root / "f.jsonl", os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail("the check opened a FIFO and waited for a writer")
    assert found == [[]]
