"""A Foxglove WebSocket client (the `websockets` package) for `perchd fly --foxglove`: it
reads the URL the command announces, subscribes to every channel it advertises and collects
the messages until the server closes."""

from __future__ import annotations

import json
import re
import struct
import subprocess

from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01  # binary opcode: uint32 subscription id, uint64 log time [ns], payload


def serving_url(proc: subprocess.Popen) -> str:
    """Read the process's stderr up to its `foxglove: serving ws://...` line."""
    for line in proc.stderr:
        found = re.search(r"foxglove: serving (ws://\S+)", line)
        if found:
            return found.group(1)
    raise AssertionError(f"perchd fly never served: exit {proc.wait()}")


def subscribe_all(ws) -> dict[int, dict]:
    """Read serverInfo and advertise; subscribe to every channel: {subscription id: channel}."""
    channels: list[dict] = []
    while not channels:
        op = json.loads(ws.recv(timeout=5))
        assert op["op"] in ("serverInfo", "advertise", "status"), op
        channels = op.get("channels", []) if op["op"] == "advertise" else []
    subs = dict(enumerate(channels, start=1))
    ws.send(
        json.dumps(
            {
                "op": "subscribe",
                "subscriptions": [{"id": n, "channelId": ch["id"]} for n, ch in subs.items()],
            }
        )
    )
    return subs


def receive(ws, subs: dict[int, dict], timeout_s: float = 30.0) -> list[tuple[str, int, dict]]:
    """(topic, log time [ns], payload) of every message until the server closes."""
    got = []
    while True:
        try:
            data = ws.recv(timeout=timeout_s)
        except Exception:  # noqa: BLE001 - closed by the server at the flight's end
            return got
        if isinstance(data, bytes) and data[0] == MESSAGE_DATA:
            sub, log_time = struct.unpack_from("<IQ", data, 1)
            got.append((subs[sub]["topic"], log_time, json.loads(data[13:])))


def watch(url: str) -> tuple[dict[int, dict], list[tuple[str, int, dict]]]:
    """Connect, subscribe to everything, collect until closed: (subscriptions, messages)."""
    with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=5) as ws:
        subs = subscribe_all(ws)
        return subs, receive(ws, subs)
