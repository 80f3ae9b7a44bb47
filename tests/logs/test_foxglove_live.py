"""`perchd fly --foxglove`: a real Foxglove WebSocket client on loopback subscribes to every
channel during a real-time flight (agent and simulator in their own processes) and what it
receives is, message for message, the flight log's MCAP export (docs/contracts.md §5)."""

from __future__ import annotations

import json
import re
import struct
import subprocess
import sys
import time

import pytest
from svc import PLAN, SimProcess

from perchd.logs.flightlog import read_log
from perchd.logs.mcapexport import FLIGHT, ROW_STREAMS, messages, payload_bytes, schemas

pytest.importorskip("foxglove")
ws_client = pytest.importorskip("websockets.sync.client")

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01  # binary opcode: uint32 subscription id, uint64 log time [ns], payload
LOOP = next(s.topic for s in ROW_STREAMS if s.topic.endswith("/loop"))


def serving_url(proc: subprocess.Popen) -> str:
    for line in proc.stderr:
        found = re.search(r"foxglove: serving (ws://\S+)", line)
        if found:
            return found.group(1)
    raise AssertionError(f"perchd fly never served: {proc.wait()}")


def subscribe_all(ws) -> dict[int, dict]:
    """Read serverInfo and advertise; subscribe to every channel: {subscription id: channel}."""
    channels: list[dict] = []
    while not channels:
        op = json.loads(ws.recv(timeout=5))
        assert op["op"] in ("serverInfo", "advertise", "status"), op
        channels = op.get("channels", []) if op["op"] == "advertise" else []
    subs = {n: ch for n, ch in enumerate(channels, start=1)}
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [
        {"id": n, "channelId": ch["id"]} for n, ch in subs.items()]}))
    return subs


def receive(ws, subs: dict[int, dict]) -> list[tuple[str, int, dict]]:
    """(topic, log time [ns], payload) of every message until the server closes."""
    got = []
    while True:
        try:
            data = ws.recv(timeout=30)
        except Exception:  # noqa: BLE001 - closed by the server at the flight's end
            return got
        if isinstance(data, bytes) and data[0] == MESSAGE_DATA:
            sub, log_time = struct.unpack_from("<IQ", data, 1)
            got.append((subs[sub]["topic"], log_time, json.loads(data[13:])))


@pytest.fixture
def sim():
    s = SimProcess()
    yield s
    s.kill()


def test_a_client_subscribed_during_the_flight_receives_the_flight_log_s_values(sim, tmp_path):
    log = tmp_path / "f.jsonl"
    fly = subprocess.Popen(
        [sys.executable, "-m", "perchd", "fly", str(PLAN), "--driver", sim.driver, "--mocap",
         sim.mocap, "--log", str(log), "--json", "--foxglove", "127.0.0.1:0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = serving_url(fly)
        with ws_client.connect(url, subprotocols=[SUBPROTOCOL], open_timeout=5) as ws:
            subs = subscribe_all(ws)
            subscribed = time.monotonic()
            got = receive(ws, subs)
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
    assert len(rows_seen) > 0.5 * len(flown.rows), (len(rows_seen), time.monotonic() - subscribed)
    for topic, received in live.items():
        if topic != FLIGHT:  # from the subscription on, each one the export's, in order
            assert received == export[topic][-len(received):], topic
    (t_end, final), = export[FLIGHT]
    assert live[FLIGHT][-1] == (t_end, final) and final["complete"] is True
    assert all(p["complete"] is False for _, p in live[FLIGHT][:-1])


def test_without_the_extra_the_flag_is_one_line_naming_it(tmp_path):
    """The extra is checked before anything flies; simulated here by hiding the package."""
    code = ("import sys; sys.modules['foxglove'] = None; from perchd.cli import main; "
            f"sys.exit(main(['fly', {str(PLAN)!r}, '--driver', 'sim://', '--mocap', 'sim://', "
            f"'--log', {str(tmp_path / 'f.jsonl')!r}, '--foxglove', '0']))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip() == ("perchd fly: foxglove is not installed: "
                                   "pip install 'perchd[foxglove]'")
    assert not (tmp_path / "f.jsonl").exists()
