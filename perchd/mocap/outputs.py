"""Pose outputs: where a simulator (`perchd sim --pose-out URI`) or a bridge sends poses.

natnet://HOST[:PORT][?version=4.1][&multicast=1][&group=239.255.42.99][&data_port=1511]
    [&rate=120][&up=y]
    a NatNet server emulator on HOST's command PORT (1510; 0 = any free port); its
    options, with unit and default, are NATNET_OPTIONS (`perchd sim --help` prints them)
zmq://HOST:PORT[?public=1]
    a ZMQ publisher bound there (docs/contracts.md §3 topic `pose`); loopback unless public=1

out = open_pose_output("natnet://127.0.0.1:0", ["cf1"], clock)
out.publish(pose); out.uri("cf1")  # the URI `perchd fly --mocap` opens to read it back
out.close()
"""

from __future__ import annotations

from typing import Protocol

from perchd.core.clock import Clock
from perchd.core.errors import LinkError, UriError
from perchd.core.netbind import port_error
from perchd.core.types import Pose
from perchd.core.uri import parse_uri
from perchd.core.uriparams import bool_param, float_param
from perchd.mocap.natnet.protocol import DEFAULT_MULTICAST
from perchd.mocap.natnet.server import NatNetServer
from perchd.mocap.natnet.uris import check_address, port_param
from perchd.mocap.zmq import ZmqPosePublisher

# (name, unit, default, meaning) of every natnet:// output option; the one table the parser
# checks keys against and `perchd sim --help` and docs/contracts.md describe
NATNET_OPTIONS = (
    ("version", "", "4.1", "NatNet version spoken, 2.0..4.1"),
    (
        "multicast",
        "",
        "0",
        "1: frames by multicast to group:data_port; 0: unicast to each client's command socket",
    ),
    ("group", "", DEFAULT_MULTICAST, "multicast group announced and sent to"),
    (
        "data_port",
        "",
        "1511; a free one when PORT is 0",
        "data port announced (clients bind it, the emulator does not), 0..65535",
    ),
    ("rate", "Hz", "none: a frame per pose", "frame rate, 1..1000"),
    ("up", "", "y", "up axis streamed, y (Motive's default) or z"),
)


def natnet_options_help() -> str:
    """The natnet:// output options, one per line: name [unit] (default) meaning."""
    return "\n".join(
        f"{name}{f' [{unit}]' if unit else ''} ({default}) {meaning}"
        for name, unit, default, meaning in NATNET_OPTIONS
    )


class PoseOutput(Protocol):
    def publish(self, pose: Pose) -> None:
        """Send one world-frame pose (Z up, metres)."""

    def uri(self, body: str) -> str:
        """The mocap URI that reads `body` back from this output."""

    def close(self) -> None: ...


def open_pose_output(text: str, bodies: list[str], clock: Clock) -> PoseOutput:
    """Open (and start) the output a URI names; UriError for anything malformed."""
    uri = parse_uri(text)
    if uri.scheme == "zmq":
        if not uri.host or uri.port is None or set(uri.query) - {"public"}:
            raise UriError(f"{text}: a zmq pose output is zmq://HOST:PORT[?public=1]")
        try:
            return ZmqPosePublisher(
                f"tcp://{uri.host}:{uri.port}", public=bool_param(uri, "public")
            )
        except LinkError as err:
            raise port_error(uri.raw, err) from None
    if uri.scheme == "natnet":
        return _natnet_output(uri, bodies, clock)
    raise UriError(f"{text}: a pose output is natnet://HOST[:PORT] or zmq://HOST:PORT")


def _natnet_output(uri, bodies: list[str], clock: Clock):
    known = [name for name, *_ in NATNET_OPTIONS]
    unknown = sorted(set(uri.query) - set(known))
    if unknown:
        raise UriError(f"{uri.raw}: unknown parameter {unknown[0]!r}; known: {', '.join(known)}")
    if not uri.host:
        raise UriError(f"{uri.raw}: no host to serve on (natnet://127.0.0.1[:PORT])")
    version = _version(uri)
    rate = float_param(uri, "rate", None, 1.0, 1000.0, " Hz")
    group = uri.param("group", DEFAULT_MULTICAST) or DEFAULT_MULTICAST
    check_address(group, "group", uri.raw, multicast=True)
    try:
        server = NatNetServer(
            bodies,
            version,
            host=uri.host,
            command_port=1510 if uri.port is None else uri.port,
            data_port=port_param(uri, "data_port", lowest=0),
            multicast=bool_param(uri, "multicast"),
            group=group,
            rate_hz=rate,
            up=uri.param("up", "y") or "y",
            clock=clock,
        )
    except OSError as err:
        raise port_error(uri.raw, err) from None
    except ValueError as err:
        raise UriError(f"{uri.raw}: cannot serve NatNet: {err}") from None
    return _NatNetOutput(server.start())


def _version(uri) -> tuple[int, int]:
    text = uri.param("version", "4.1") or "4.1"
    try:
        major, minor = (int(part) for part in text.split("."))
    except ValueError:
        raise UriError(f"{uri.raw}: version={text!r} is not MAJOR.MINOR (e.g. 3.0)") from None
    if not (2, 0) <= (major, minor) <= (4, 1):
        raise UriError(f"{uri.raw}: version={text} outside the NatNet 2.0..4.1 perchd speaks")
    return major, minor


class _NatNetOutput:
    """A started NatNetServer seen as a PoseOutput."""

    def __init__(self, server) -> None:
        self.server = server

    def publish(self, pose: Pose) -> None:
        self.server.publish(pose)

    def uri(self, body: str) -> str:
        return self.server.uri + f"&body={body}"

    def close(self) -> None:
        self.server.close()
