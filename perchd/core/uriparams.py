"""Typed, bounded driver options read from a URI's query (`?mass=0.03&arm=1`)."""

from __future__ import annotations

from urllib.parse import parse_qsl, urlencode

from perchd.core.errors import UriError
from perchd.core.uri import Uri


def split_query(text: str) -> tuple[str, dict[str, str]]:
    """'udpout:h:p?a=1' -> ('udpout:h:p', {'a': '1'}); for URIs parse_uri keeps whole."""
    head, _, query = text.partition("?")
    return head, dict(parse_qsl(query, keep_blank_values=True))


def without_query(uri: Uri) -> str:
    """The URI as the vehicle library should see it (perchd's options removed)."""
    return uri.raw.partition("?")[0]


def float_param(
    uri: Uri, key: str, default: float | None, lo: float, hi: float, unit: str = ""
) -> float | None:
    """Read `key` as a float in [lo, hi]; a bad value is one UriError naming the key."""
    text = uri.param(key)
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        raise UriError(f"{uri.raw}: {key}={text!r} is not a number") from None
    if not lo <= value <= hi:
        raise UriError(f"{uri.raw}: {key}={value:g}{unit} is outside {lo:g}..{hi:g}{unit}")
    return value


def bool_param(uri: Uri, key: str, default: bool = False) -> bool:
    text = uri.param(key)
    if text is None:
        return default
    if text.lower() in ("1", "true", "yes", "on"):
        return True
    if text.lower() in ("0", "false", "no", "off"):
        return False
    raise UriError(f"{uri.raw}: {key}={text!r} must be 1/0, true/false, yes/no or on/off")


# -- every scheme's parameters, in one place (docs/contracts.md §7, `perchd fly --help`) -------
# (name, unit, default, meaning); the factories read them, Registry.open refuses any other key.
# sim:// is one simulated world behind both links: the vehicle's options go on --driver, the
# mocap's on --mocap, and each side refuses the other's (a key on the wrong side was ignored).
SIM_VEHICLE = (
    ("latency", "s", "0", "setpoint-to-vehicle delay, 0..1"),
    ("attitude_tau", "s", "0.07", "attitude response time constant, 0.005..1"),
    ("motor_tau", "s", "0.03", "motor response time constant, 0.001..1"),
    ("mass", "kg", "0.03", "vehicle mass, 0.005..50"),
    ("drag", "1/s", "0", "linear drag per unit mass, 0..5"),
    ("qdrag", "1/m", "0", "quadratic drag per unit mass (|v| v), 0..5"),
    ("start", "m", "4.5 m before the surface, 1 m up", "start position X,Y,Z"),
    ("draught", "m, m/s^2", "none", "X,A: acceleration A along X from x = X on"),
    ("stall", "s", "none", "AT,FOR: hold the link FOR s at AT s (docs/safety.md)"),
)
SIM_MOCAP = (
    ("mocap_rate", "Hz", "120", "mocap frame rate, 1..1000"),
    ("mocap_latency", "s", "0.004", "mocap latency, 0..0.5"),
    ("noise", "m", "0", "mocap noise std per axis, 0..0.1"),
    ("seed", "", "0", "noise seed"),
    ("body", "", "cf1", "rigid body name"),
)
SIM = SIM_VEHICLE + SIM_MOCAP
"""Every sim:// option: one URI describing a whole world (perchd.session.open_session)."""
CRAZYFLIE = (
    ("hover", "units", "36000", "hover thrust, 1000..60000 of 65535"),
    ("mass", "kg", "0.03", "vehicle mass, 0.010..0.100"),
    ("timeout", "s", "0.5", "no link reply this long = link lost, 0.01..10"),
    ("extpose", "", "0", "1: send mocap poses to the vehicle's estimator"),
    ("wait", "s", "2", "connect() waits this long, 0.05..60"),
)
PARAMS: dict[tuple[str, str], tuple[tuple[str, str, str, str], ...]] = {
    ("driver", "sim"): SIM_VEHICLE,
    ("driver", "radio"): CRAZYFLIE,
    ("driver", "udp"): CRAZYFLIE,
    ("driver", "mavlink"): (
        ("mass", "kg", "the flight config's", "vehicle mass, 0.01..50; must agree with [vehicle]"),
        ("hover", "", "read from the autopilot", "normalised hover thrust, 0.05..0.95"),
        ("arm", "", "0", "1: arm after the mode switch"),
        ("timeout", "s", "1.5", "no message this long = link lost, 0.01..30"),
        ("stream", "Hz", "50", "ATTITUDE stream rate asked for, 1..500"),
        ("wait", "s", "5", "connect() waits this long for each answer, 0.1..60"),
        ("yaw0", "deg", "0", "autopilot heading of world X, or auto (measured from the poses)"),
        ("configure", "", "0", "1: set the autopilot's parameters perchd needs (docs/safety.md)"),
        ("sport", "", "any", "fixed local UDP source port of a udpout: link"),
        ("vision", "", "1", "0: neither forward mocap to the autopilot nor check its EKF set-up"),
        (
            "tilt",
            "",
            "1",
            "0: do not lean setpoints by the change in the autopilot's tilt "
            "error (its attitude estimate less the mocap's)",
        ),
    ),
    ("driver", "zmq"): (
        ("vehicle", "", "cf1", "vehicle name in setpoints"),
        ("bind", "", "0", "1: bind instead of connect"),
        ("public", "", "0", "1: allow a non-loopback bind"),
        ("wait", "s", "2", "connect() waits this long for a subscriber, 0..60"),
    ),
    ("mocap", "sim"): SIM_MOCAP,
    ("mocap", "natnet"): (
        ("body", "", "required", "rigid body name"),
        ("transport", "", "from the server", "unicast or multicast (NatNet 2.x)"),
        ("multicast", "", "239.255.42.99", "multicast group (NatNet 2.x)"),
        ("data_port", "", "1511", "data port (NatNet 2.x)"),
        ("local", "", "0.0.0.0", "local interface address"),
        ("up", "", "y", "the server's up axis, y or z"),
        ("timeout", "s", "2", "server reply timeout, 0.05..60"),
        ("max_age", "s", "0.5", "a pose older than this is stale, 0.001..10"),
    ),
    ("mocap", "zmq"): (
        ("body", "", "required", "rigid body name"),
        ("bind", "", "0", "1: bind instead of connect"),
        ("public", "", "0", "1: allow a non-loopback bind"),
        ("clock", "", "local", "local or remote: whose clock stamps poses"),
        ("max_age", "s", "0.5", "a pose older than this is stale, 0.001..10"),
    ),
}


def query_of(uri: Uri) -> dict[str, str]:
    """The URI's options; `mavlink:udpout:H:P?k=v` keeps them in its path."""
    return uri.query if uri.query or "?" not in uri.path else split_query(uri.path)[1]


def check_params(kind: str, uri: Uri) -> None:
    """UriError naming the first unknown key of a scheme that lists its parameters, and
    the side it belongs to when it is the other side's (sim://)."""
    known = PARAMS.get((kind, uri.scheme))
    if known is None:
        return
    names = [p[0] for p in known]
    unknown = sorted(set(query_of(uri)) - set(names))
    if not unknown:
        return
    other = "mocap" if kind == "driver" else "driver"
    if unknown[0] in names_of(PARAMS.get((other, uri.scheme), ())):
        raise UriError(
            f"{uri.raw}: {unknown[0]!r} is a --{other} parameter of {uri.scheme}:// "
            f"(--{other} {uri.scheme}://?{unknown[0]}=...); --{kind} takes "
            f"{', '.join(names)}"
        )
    check_known(uri, names)


def check_known(uri: Uri, names: tuple[str, ...] | list[str]) -> None:
    """UriError naming the URI's first key not in `names`, and listing them."""
    unknown = sorted(set(query_of(uri)) - set(names))
    if unknown:
        raise UriError(
            f"{uri.raw}: unknown parameter {unknown[0]!r}; {uri.scheme}:// takes "
            f"{', '.join(names)} (perchd fly --help)"
        )


def names_of(params: tuple[tuple[str, str, str, str], ...]) -> tuple[str, ...]:
    return tuple(p[0] for p in params)


def split_sim(uri: Uri) -> tuple[str, str]:
    """A whole-world sim:// URI as (the driver's URI, the mocap's), each with its own keys."""
    query = query_of(uri)
    vehicle, mocap = (
        "sim://" + ("?" + urlencode(part, safe=",") if part else "")
        for part in (
            {k: v for k, v in query.items() if k in names_of(side)}
            for side in (SIM_VEHICLE, SIM_MOCAP)
        )
    )
    return vehicle, mocap


def params_help() -> str:
    """The table for `perchd fly --help`: scheme, then each key [unit] (default) meaning."""
    lines = []
    for (kind, scheme), params in PARAMS.items():
        keys = "; ".join(f"{n}{f' [{u}]' if u else ''} ({d or '-'})" for n, u, d, _ in params)
        lines.append(f"--{kind} {scheme}:  {keys}")
    return "\n".join(lines)
