"""libmotioncapture's backends: their URI TYPE, own options and up axis, and which ones the
installed library was built with.

The library has no call that lists its backends, and asking `connect` about one is a network
connection that may block for good. Each backend is a C++ class, MotionCapture<Name>, whose
constructor the Python module exports; so the backends built in are those whose mangled
constructor names the module file holds. The options are those libmotioncapture 1.1's
`connect` reads; a misspelt one would be silently ignored by the library, so it is refused.
"""

from __future__ import annotations

import importlib.util
import mmap
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Backend:
    """One libmotioncapture backend.

    kind: the TYPE of motioncapture://TYPE, as libmotioncapture names it.
    cls: its C++ class is MotionCapture<cls>.
    options: the configuration keys the library reads for it.
    up: the axis it streams as up unless the server is set otherwise.
    """

    kind: str
    cls: str
    options: tuple[str, ...]
    up: str = "z"


BACKENDS = (
    Backend("mock", "Mock", ("rigid_bodies", "pointcloud", "frequency")),
    Backend("optitrack", "Optitrack", ("hostname", "interface_ip", "port_command"), up="y"),
    Backend(
        "optitrack_closed_source", "OptitrackClosedSource", ("hostname", "port_command"), up="y"
    ),
    Backend("vicon", "Vicon", ("hostname", "enable_objects", "enable_pointclout")),
    Backend("qualisys", "Qualisys", ("hostname", "port", "enable_objects", "enable_pointcloud")),
    Backend("vrpn", "Vrpn", ("hostname",)),
    Backend("nokov", "Nokov", ("hostname", "enableFrequency", "updateFrequency")),
    Backend("motionanalysis", "MotionAnalysis", ("hostname",)),
    Backend("fzmotion", "FZMotion", ("local_IP", "local_port", "hostname", "remote_port")),
)

INTEGER_OPTIONS = frozenset(
    {"frequency", "port_command", "port", "updateFrequency", "local_port", "remote_port"}
)
"""Options the library parses with std::stoi: checked here, where a bad one is one line."""


def backend(kind: str) -> Backend | None:
    return next((b for b in BACKENDS if b.kind == kind), None)


def built_in() -> tuple[str, ...]:
    """The TYPEs the installed module was built with; every known one if it cannot be read."""
    spec = importlib.util.find_spec("motioncapture")
    try:
        with open(spec.origin, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as m:
            return tuple(b.kind for b in BACKENDS if m.find(_constructor(b)) >= 0)
    except (AttributeError, TypeError, OSError, ValueError):
        return tuple(b.kind for b in BACKENDS)


def _constructor(b: Backend) -> bytes:
    """The length-prefixed name the Itanium C++ ABI gives MotionCapture<cls>'s constructor."""
    name = f"MotionCapture{b.cls}"
    return f"{len(name)}{name}C".encode()
