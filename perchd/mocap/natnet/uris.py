"""`natnet://` pose sources (OptiTrack Motive) and the NatNet server emulator.

    natnet://HOST[:PORT]?body=NAME|ID[&transport=auto|multicast|unicast]
        [&multicast=239.255.42.99][&data_port=1511][&local=IP][&up=y|z]
        [&timeout=2.0][&max_age=0.5]

PORT is Motive's command port (1510). `multicast=` names the group (and implies multicast);
`local=` is this machine's address on the mocap network; `up=` the axis Motive streams as up.
The pieces: natnet_wire (bounded reads); natnet_frame, natnet_models, natnet_protocol (the
codec); natnet_clock (clock sync); natnet_client (the source); natnet_server (the emulator).
"""

from __future__ import annotations

import ipaddress

from perchd.core.errors import UriError
from perchd.core.runtime import Runtime
from perchd.core.uri import Uri
from perchd.core.uriparams import float_param
from perchd.mocap.frames import UpAxis
from perchd.mocap.natnet.client import NatNetConfig, NatNetSource
from perchd.mocap.natnet.protocol import DEFAULT_COMMAND_PORT
from perchd.mocap.natnet.server import NatNetServer
from perchd.mocap.stream import PoseLimits

__all__ = [
    "NatNetConfig",
    "NatNetServer",
    "NatNetSource",
    "check_address",
    "config_from_uri",
    "open_natnet",
    "port_param",
]

_PARAMS = ("body", "transport", "multicast", "data_port", "local", "up", "timeout", "max_age")


def open_natnet(uri: Uri, runtime: Runtime) -> NatNetSource:
    """Registry factory for `natnet://` (not started yet)."""
    return NatNetSource(config_from_uri(uri), runtime.clock)


def config_from_uri(uri: Uri) -> NatNetConfig:
    where = uri.raw
    unknown = sorted(set(uri.query) - set(_PARAMS))
    if unknown:
        raise UriError(f"{where}: unknown parameter {unknown[0]!r}; known: {', '.join(_PARAMS)}")
    if not uri.host:
        raise UriError(f"{where}: no server host (natnet://HOST[:PORT]?body=NAME)")
    body = uri.param("body") or ""
    if not body:
        raise UriError(f"{where}: body=NAME (or numeric id) is required")
    group = uri.param("multicast")
    transport = uri.param("transport", "multicast" if group else "auto") or "auto"
    if transport not in ("auto", "multicast", "unicast"):
        raise UriError(f"{where}: transport={transport!r} must be auto, multicast or unicast")
    if group is not None:
        check_address(group, "multicast", where, multicast=True)
    local = uri.param("local", "0.0.0.0") or "0.0.0.0"
    check_address(local, "local", where)
    return NatNetConfig(
        server=uri.host,
        body=body,
        command_port=uri.port or DEFAULT_COMMAND_PORT,
        transport=transport,
        multicast_group=group,
        data_port=port_param(uri, "data_port"),
        local=local,
        up=UpAxis.parse(uri.param("up", "y") or "y", where),
        connect_timeout_s=float_param(uri, "timeout", 2.0, 0.05, 60.0, " s"),
        limits=PoseLimits(max_age_s=float_param(uri, "max_age", 0.5, 0.001, 10.0, " s")),
    )


def port_param(uri: Uri, key: str, lowest: int = 1) -> int | None:
    """The whole port number `key` names, lowest..65535; None when absent."""
    value = float_param(uri, key, None, lowest, 65535)
    if value is not None and value != int(value):
        raise UriError(f"{uri.raw}: {key}={value:g} is not a whole port number")
    return None if value is None else int(value)


def check_address(text: str, key: str, where: str, multicast: bool = False) -> None:
    """UriError unless `text` is an IPv4 address (a multicast one when `multicast`)."""
    try:
        address = ipaddress.IPv4Address(text)
    except ValueError:
        raise UriError(f"{where}: {key}={text!r} is not an IPv4 address") from None
    if multicast and not address.is_multicast:
        raise UriError(f"{where}: {key}={text} is not a multicast address (224.0.0.0/4)")
