"""The `mavlink:` driver URI, read into a MavlinkDriver (driver.py).

`mavlink:DEVICE[?mass=KG&arm=1&hover=F&timeout=S&stream=HZ&wait=S&yaw0=DEG&configure=1&sport=P]`
DEVICE: `udpin:127.0.0.1:14540` for PX4 (SITL instance N: 14540+N; PX4 sends to that fixed
port and ignores anyone else), `udpin:`/`udpout:HOST:PORT`/`tcp:HOST:PORT` for ArduPilot, or a
serial device. A `udpout:` link speaks from one source port; a vehicle that locks onto its
first partner (PX4) answers only that one: give it a fixed one with `sport=` (or use udpin).
- mass: the thrust model's mass (drivers.thrust.NormalisedThrust) comes from the flight
  config (`[vehicle] mass_kg`, bind_mass); a mass= here must agree with it, else the flight
  is refused before the mode switch or arming. Only a driver never bound uses it alone.
- hover: normalised hover thrust; default: read MOT_THST_HOVER (ArduPilot) or
  MPC_THR_HOVER (PX4) from the vehicle.
- arm=1: arm after the mode switch (default: never arm; the pilot does).
- timeout [s, default 1.5]: no message from the vehicle this long = link lost. The driver
  asks for ATTITUDE at `stream` Hz (default 50) so a short timeout is usable.
- wait [s, default 5]: how long connect() waits for each answer.
- yaw0 [deg, default 0]: the autopilot's heading (NED yaw, from north) of the world X axis:
  0 when its yaw zero faces mocap X, 90 for an ENU world on a north-referenced autopilot.
  `yaw0=auto`: measured from every pose (yaw0.py), for an autopilot whose heading comes
  from its compass and drifts off the mocap's (PX4 SIH: `perchd sim firmware --px4`).
- configure=1: set the parameters the dialect checks to perchd's values (PARAM_SET, read
  back, logged) instead of refusing to fly.
- vision=0: do not forward mocap to the autopilot nor check its external-navigation setup
  (a vehicle that has its own position source, e.g. GPS outdoors or in SITL).
- tilt=0: send the setpoints as they are. By default (tilt=1) each is rotated by the change
  in the autopilot's tilt error, its attitude estimate (ATTITUDE) less the mocap's
  (tilt.py): the autopilot flies its estimate, and an estimate a degree off leans the
  vehicle a degree off what perchd asked for.
"""

from __future__ import annotations

import math

from perchd.core.errors import UriError
from perchd.core.extras import require
from perchd.core.runtime import Runtime
from perchd.core.uri import Uri
from perchd.core.uriparams import bool_param, float_param, split_query
from perchd.drivers.mavlink.driver import MavlinkDriver
from perchd.drivers.mavlink.px4 import OFFBOARD_PORT


def open_mavlink(uri: Uri, runtime: Runtime) -> MavlinkDriver:
    require("pymavlink", "mavlink")
    device, query = split_query(uri.path)
    if not device.startswith(("udpout:", "udpin:", "udp:", "tcp:", "/dev/", "COM")):
        raise UriError(
            f"{uri.raw}: expected mavlink:udpin:HOST:PORT (PX4: udpin:127.0.0.1:"
            f"{OFFBOARD_PORT}; or udpout:, tcp:, a serial device)"
        )
    _check_network_port(uri.raw, device)
    opts = Uri(uri.raw, uri.scheme, "", None, device, query)
    mass = float_param(opts, "mass", None, 0.01, 50.0, " kg")
    return MavlinkDriver(
        uri.raw,
        device,
        runtime,
        mass_kg=mass,
        hover=float_param(opts, "hover", None, 0.05, 0.95),
        arm=bool_param(opts, "arm"),
        timeout=float_param(opts, "timeout", 1.5, 0.01, 30.0, " s"),
        stream_hz=float_param(opts, "stream", 50.0, 1.0, 500.0, " Hz"),
        wait=float_param(opts, "wait", 5.0, 0.1, 60.0, " s"),
        yaw0=heading_offset(opts),
        configure=bool_param(opts, "configure"),
        sport=source_port(opts, device),
        vision=bool_param(opts, "vision", True),
        tilt=bool_param(opts, "tilt", True),
    )


def _check_network_port(raw: str, device: str) -> None:
    """udpout:/udpin:/udp:/tcp: devices end in :PORT; pymavlink would raise a bare
    ValueError at connect time for anything else."""
    if device.startswith(("/dev/", "COM")):
        return
    port = device.rsplit(":", 1)[1] if device.count(":") >= 2 else ""
    if not (port.isdigit() and 0 < int(port) < 65536):
        raise UriError(f"{raw}: {device!r} needs HOST:PORT with a port 1..65535, got {port!r}")


def heading_offset(opts: Uri) -> float | None:
    """?yaw0=DEG [rad], or None for yaw0=auto."""
    if (opts.param("yaw0") or "").lower() == "auto":
        return None
    return math.radians(float_param(opts, "yaw0", 0.0, -360.0, 360.0, " deg"))


def source_port(opts: Uri, device: str) -> int | None:
    """?sport=PORT: the fixed local port of a udpout: link (None: an ephemeral one)."""
    port = float_param(opts, "sport", None, 1, 65535)
    if port is None:
        return None
    if not device.startswith("udpout:") or port != int(port):
        raise UriError(f"{opts.raw}: sport= is a whole port number, for udpout: links only")
    return int(port)
