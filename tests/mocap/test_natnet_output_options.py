"""The NatNet output's options: the data port is announced as Motive does, a port the
emulator does not hold, and every option is described from the one table."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest
from freeport import free_udp_port

from perchd.core.clock import MonotonicClock
from perchd.core.errors import UriError
from perchd.mocap.natnet.protocol import DEFAULT_DATA_PORT
from perchd.mocap.outputs import NATNET_OPTIONS, natnet_options_help, open_pose_output


def test_the_announced_data_port_is_free_for_a_client_to_bind():
    port = free_udp_port()
    out = open_pose_output(
        f"natnet://127.0.0.1:0?multicast=1&data_port={port}", ["cf1"], MonotonicClock()
    )
    try:
        assert out.server.server_info().data_port == port
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as client:
            client.bind(("0.0.0.0", port))  # exclusive: fails if the emulator held it
    finally:
        out.close()


@pytest.mark.parametrize("query", ["", "?data_port=0"])
def test_an_ephemeral_server_announces_a_free_data_port(query):
    out = open_pose_output(f"natnet://127.0.0.1:0{query}", ["cf1"], MonotonicClock())
    try:
        assert out.server.data_port not in (0, DEFAULT_DATA_PORT)
    finally:
        out.close()


@pytest.mark.parametrize(
    "query, message",
    [
        ("group=10.0.0.1", "group=10.0.0.1 is not a multicast address"),
        ("data_port=70000", "data_port=70000 is outside"),
        ("data_port=1.5", "not a whole port"),
        ("port=1511", "unknown parameter 'port'"),
    ],
)
def test_bad_options_are_one_line(query, message):
    with pytest.raises(UriError, match=message):
        open_pose_output(f"natnet://127.0.0.1:0?{query}", ["cf1"], MonotonicClock())


def test_the_help_names_every_option_with_its_default():
    text = natnet_options_help()
    for name, unit, default, _ in NATNET_OPTIONS:
        assert f"{name}{f' [{unit}]' if unit else ''} ({default})" in text


def test_docs_contracts_lists_every_option_as_the_table_does():
    text = (Path(__file__).resolve().parents[2] / "docs" / "contracts.md").read_text()
    for name, unit, default, meaning in NATNET_OPTIONS:
        assert f"| `{name}` | {unit} | {default} | {meaning} |".replace("|  |", "| |") in text
