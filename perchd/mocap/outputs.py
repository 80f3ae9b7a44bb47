"""Pose outputs: where a simulator (`perchd sim --pose-out URI`) or a bridge sends poses.

    natnet://HOST[:PORT][?version=4.1][&multicast=1][&group=239.255.42.99][&rate=120][&up=y]
        a NatNet server emulator on HOST's command PORT (1510; 0 = any free port)
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
from perchd.mocap.natnet.server import NatNetServer
from perchd.mocap.zmq import ZmqPosePublisher

_NATNET_PARAMS = ("version", "multicast", "group", "rate", "up")


class PoseOutput(Protocol):
    def publish(self, pose: Pose) -> None:
        """Send one world-frame pose (Z up, metres)."""

    def uri(self, body: str) -> str:
        """The mocap URI that reads `body` back from this output."""

    def close(self) -> None:
        ...


def open_pose_output(text: str, bodies: list[str], clock: Clock) -> PoseOutput:
    """Open (and start) the output a URI names; UriError for anything malformed."""
    uri = parse_uri(text)
    if uri.scheme == "zmq":
        if not uri.host or uri.port is None or set(uri.query) - {"public"}:
            raise UriError(f"{text}: a zmq pose output is zmq://HOST:PORT[?public=1]")
        try:
            return ZmqPosePublisher(f"tcp://{uri.host}:{uri.port}",
                                    public=bool_param(uri, "public"))
        except LinkError as err:
            raise port_error(uri.raw, err) from None
    if uri.scheme == "natnet":
        return _natnet_output(uri, bodies, clock)
    raise UriError(f"{text}: a pose output is natnet://HOST[:PORT] or zmq://HOST:PORT")


def _natnet_output(uri, bodies: list[str], clock: Clock):
    unknown = sorted(set(uri.query) - set(_NATNET_PARAMS))
    if unknown:
        raise UriError(f"{uri.raw}: unknown parameter {unknown[0]!r}; "
                       f"known: {', '.join(_NATNET_PARAMS)}")
    if not uri.host:
        raise UriError(f"{uri.raw}: no host to serve on (natnet://127.0.0.1[:PORT])")
    version = _version(uri)
    rate = float_param(uri, "rate", None, 1.0, 1000.0, " Hz")
    try:
        server = NatNetServer(bodies, version, host=uri.host,
                              command_port=1510 if uri.port is None else uri.port,
                              multicast=bool_param(uri, "multicast"),
                              group=uri.param("group", "239.255.42.99") or "239.255.42.99",
                              rate_hz=rate, up=uri.param("up", "y") or "y", clock=clock)
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
