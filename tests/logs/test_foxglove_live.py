"""`perchd fly --foxglove`: a real Foxglove WebSocket client on loopback subscribes to every
channel during a real-time flight (agent and simulator in their own processes) and what it
receives is, message for message, the flight log's MCAP export (docs/contracts.md §5)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest
from stale import harness_config
from svc import PLAN, SimProcess

from perchd.logs.flightlog import read_log
from perchd.logs.mcapexport import FLIGHT, ROW_STREAMS, messages, payload_bytes, schemas

pytest.importorskip("foxglove")
pytest.importorskip("websockets")
from foxglove_client import serving_url, watch  # noqa: E402 - needs websockets

LOOP = next(s.topic for s in ROW_STREAMS if s.topic.endswith("/loop"))


@pytest.fixture
def sim():
    s = SimProcess()
    yield s
    s.kill()


def test_a_client_subscribed_during_the_flight_receives_the_flight_log_s_values(sim, tmp_path):
    log = tmp_path / "f.jsonl"
    fly = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "perchd",
            "fly",
            str(PLAN),
            "--driver",
            sim.driver,
            "--mocap",
            sim.mocap,
            "--config",
            str(harness_config(tmp_path)),
            "--log",
            str(log),
            "--json",
            "--foxglove",
            "127.0.0.1:0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        subs, got = watch(serving_url(fly))
        out, _ = fly.communicate(timeout=30)
    finally:
        if fly.poll() is None:
            fly.kill()
            fly.communicate()
    assert json.loads(out)["log"] == str(log)  # whatever its outcome: the view is the test
    assert {ch["topic"] for ch in subs.values()} == set(schemas())
    assert all(json.loads(ch["schema"]) == schemas()[ch["topic"]] for ch in subs.values())

    flown = read_log(log)
    export: dict[str, list] = {}
    for m in messages(flown):
        export.setdefault(m.topic, []).append((m.log_time, json.loads(payload_bytes(m.payload))))
    live: dict[str, list] = {}
    for topic, log_time, payload in got:
        live.setdefault(topic, []).append((log_time, payload))
    assert set(live) == set(export)
    rows_seen = [p["k"] for _, p in live[LOOP]]
    assert rows_seen == [r.k for r in flown.rows if r.k >= rows_seen[0]]  # none lost from then
    assert len(rows_seen) > 0.5 * len(flown.rows)
    for topic, received in live.items():
        if topic != FLIGHT:  # from the subscription on, each one the export's, in order
            assert received == export[topic][-len(received) :], topic
    ((t_end, final),) = export[FLIGHT]
    assert live[FLIGHT][-1] == (t_end, final) and final["complete"] is True
    assert all(p["complete"] is False for _, p in live[FLIGHT][:-1])


def test_without_the_extra_the_flag_is_one_line_naming_it(tmp_path):
    """The extra is checked before anything flies; simulated here by hiding the package."""
    code = (
        "import sys; sys.modules['foxglove'] = None; from perchd.cli import main; "
        f"sys.exit(main(['fly', {str(PLAN)!r}, '--driver', 'sim://', '--mocap', 'sim://', "
        f"'--log', {str(tmp_path / 'f.jsonl')!r}, '--foxglove', '0']))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "perchd fly: foxglove is not installed: pip install 'perchd[foxglove]'"
    )
    assert not (tmp_path / "f.jsonl").exists()


@pytest.mark.parametrize(
    "address, message",
    [
        ("taken", "port is taken"),
        ("localhost:http", "expected [HOST:]PORT"),
        ("70000", "expected [HOST:]PORT"),
    ],
)
def test_a_taken_port_or_a_bad_address_is_refused_before_anything_flies(address, message, tmp_path):
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen(1)
        if address == "taken":
            address = f"127.0.0.1:{holder.getsockname()[1]}"
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "perchd",
                "fly",
                str(PLAN),
                "--driver",
                "sim://",
                "--mocap",
                "sim://",
                "--log",
                str(tmp_path / "f.jsonl"),
                "--foxglove",
                address,
            ],
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and message in done.stderr and address in done.stderr
    assert not (tmp_path / "f.jsonl").exists()


def test_ctrl_c_to_the_process_group_still_publishes_the_flight_s_end(sim, tmp_path):
    """Ctrl-C reaches the view's process too: it ignores it and publishes the SIGNAL end."""
    fly = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "perchd",
            "fly",
            str(PLAN),
            "--driver",
            sim.driver,
            "--mocap",
            sim.mocap,
            "--config",
            str(harness_config(tmp_path)),
            "--log",
            str(tmp_path / "f.jsonl"),
            "--json",
            "--foxglove",
            "127.0.0.1:0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    watched: list = []
    try:
        url = serving_url(fly)
        client = threading.Thread(target=lambda: watched.extend(watch(url)), daemon=True)
        client.start()
        time.sleep(1.5)  # holding or approaching
        os.killpg(fly.pid, signal.SIGINT)
        out, _ = fly.communicate(timeout=30)
        client.join(10)
    finally:
        if fly.poll() is None:
            os.killpg(fly.pid, signal.SIGKILL)
            fly.communicate()
    assert fly.returncode == 130 and json.loads(out)["outcome"] == "SIGNAL"
    _, got = watched
    final = [p for topic, _, p in got if topic == FLIGHT][-1]
    assert final["complete"] is True and final["end"]["outcome"] == "SIGNAL"
