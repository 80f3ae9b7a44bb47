"""The service configuration: a versioned TOML file onto ServiceConfig + FlightConfig.

    version = 1
    [service]   vehicle, driver, mocap, body, socket, plan_dir, log_dir,
                allowed_users, allowed_groups,
                realtime = { priority, cpu, lock_memory }  (or a [service.realtime] table)
    [flight]    rate_hz, tilt_limit_deg, post_contact, post_contact_s, idle_thrust_n
    [vehicle] [surface] [tau_gains] [lateral.y] [lateral.z] [approach] [trigger] [safety]
    [estimator]  the FlightConfig sections, keys named as its fields

Every table and key maps onto a dataclass field, so anything else is an unknown key. A field
in radians (`*_rad`) may be given in degrees as `*_deg` instead (not both: refused). Errors
name file, table and key: "perchd.toml: [safety] tilt_max_deg: expected a number, got 'x'".
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import grp
import math
import os
import pwd
import tomllib
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from perchd.core.errors import ConfigError
from perchd.core.realtime import RealtimeConfig
from perchd.core.safefile import read_regular, safe_name
from perchd.flight.config import FlightConfig
from perchd.service.control_socket import PeerPolicy

if TYPE_CHECKING:
    from perchd.service.control_socket import PeerPolicy

VERSION = 1
FLIGHT_TOP = "flight"  # FlightConfig's own scalar fields live in [flight]


@dataclass(frozen=True)
class ServiceConfig:
    """vehicle: a name for logs and STATUS; driver, mocap: link URIs; body: mocap rigid body
    (added to the mocap URI as ?body= when it names none); socket: control socket path;
    plan_dir: plans in `fly` requests must lie here (relative names resolve here); log_dir:
    flight logs. state_dir: where vehicles.json keeps each vehicle's learned hover thrust
    (flight/vehiclestate.py; empty: log_dir). allowed_users, allowed_groups: names or numeric ids let onto the control
    socket besides the service's own user and root (checked by SO_PEERCRED). realtime: how
    the service's process is scheduled (core/realtime.py: SCHED_FIFO priority, CPU pin,
    locked memory), granted at start-up; refused, the service runs and refuses flights."""

    vehicle: str = "cf1"
    driver: str = "sim://"
    mocap: str = "sim://"
    body: str = ""
    socket: str = "/run/perchd/control.sock"
    plan_dir: str = "/var/lib/perchd/plans"
    log_dir: str = "/var/log/perchd"
    state_dir: str = ""
    allowed_users: tuple[int | str, ...] = ()
    allowed_groups: tuple[int | str, ...] = ()
    realtime: RealtimeConfig = RealtimeConfig()

    def __post_init__(self) -> None:
        # the vehicle names each flight's log file: it must not lead out of log_dir
        safe_name(self.vehicle, "[service] vehicle", ConfigError)

    def peer_policy(self, name: str = "perchd.toml") -> PeerPolicy:
        """The control socket's PeerPolicy; ConfigError naming an unknown user or group."""

        uids = _ids(
            self.allowed_users, lambda n: pwd.getpwnam(n).pw_uid, name, "allowed_users", "user"
        )
        gids = _ids(
            self.allowed_groups, lambda n: grp.getgrnam(n).gr_gid, name, "allowed_groups", "group"
        )
        return PeerPolicy.owner(uids, gids)

    def mocap_uri(self) -> str:
        if not self.body or "body=" in self.mocap:
            return self.mocap
        return f"{self.mocap}{'&' if '?' in self.mocap else '?'}body={self.body}"


@dataclass(frozen=True)
class Config:
    service: ServiceConfig
    flight: FlightConfig
    path: str = ""


def _ids(
    values: tuple[int | str, ...], lookup: Any, name: str, key: str, kind: str
) -> frozenset[int]:
    out = set()
    for v in values:
        try:
            out.add(v if isinstance(v, int) else lookup(v))
        except KeyError:
            raise ConfigError(
                f"{name}: [service] {key}: no {kind} named {v!r} on this host"
            ) from None
    return frozenset(out)


def load_config(path: str | os.PathLike) -> Config:
    """Parse and check a perchd.toml; raise ConfigError naming the key on any problem.
    The file must be a regular file of at most 1 MiB of UTF-8 (perchd.core.safefile)."""

    name = Path(path).name
    text = read_regular(path, "config", ConfigError)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{name}: not valid TOML: {err}") from None
    except ValueError as err:  # an integer of more digits than Python converts
        raise ConfigError(f"{name}: not valid TOML: {err}") from None
    except RecursionError:
        raise ConfigError(f"{name}: not valid TOML: nested too deeply") from None
    return config_from_dict(doc, name, str(path))


def load_flight_config(path: str | os.PathLike) -> FlightConfig:
    """The flight part only (what `perchd fly --config` needs)."""
    return load_config(path).flight


def config_from_dict(doc: dict[str, Any], name: str = "perchd.toml", path: str = "") -> Config:
    doc = dict(doc)
    version = doc.pop("version", None)
    if version != VERSION:
        raise ConfigError(
            f"{name}: version: expected {VERSION}, got {_shown(version)}"
            + (" (missing)" if version is None else "")
        )
    service = _build(ServiceConfig, doc.pop("service", {}), name, "service")
    service.peer_policy(name)  # unknown users and groups fail here, not when serving
    flight_doc = doc.pop(FLIGHT_TOP, {})
    if not isinstance(flight_doc, dict):
        raise ConfigError(f"{name}: [{FLIGHT_TOP}] must be a table, got {_shown(flight_doc)}"[:200])
    flight_doc = dict(flight_doc)
    sections = {
        f.name
        for f in dataclasses.fields(FlightConfig)
        if dataclasses.is_dataclass(_hints(FlightConfig)[f.name])
    }
    for key, value in doc.items():
        if key not in sections:
            raise ConfigError(
                f"{name}: unknown table or key '{key}' (tables: service, "
                f"{FLIGHT_TOP}, {', '.join(sorted(sections))})"
            )
        if key in flight_doc:
            raise ConfigError(f"{name}: [{FLIGHT_TOP}] {key}: set it as a table [{key}]")
        flight_doc[key] = value
    flight = _build(FlightConfig, flight_doc, name, FLIGHT_TOP)
    return Config(service, flight, path)


@functools.cache  # resolving annotations is most of a load's time; the classes never change
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _build(cls: type, table: Any, name: str, where: str, base: Any = None) -> Any:
    """A `cls` from a TOML table onto `base` (default cls()): known keys only, values
    coerced to the field's type."""
    if not isinstance(table, dict):
        raise ConfigError(f"{name}: [{where}] must be a table, got {_shown(table)}")
    hints = _hints(cls)
    fields = {f.name for f in dataclasses.fields(cls)}
    base = cls() if base is None else base
    values: dict[str, Any] = {}
    for key, raw in table.items():
        field = key
        if key.endswith("_deg") and key[:-4] + "_rad" in fields:
            field = key[:-4] + "_rad"
            if field in table:  # neither silently wins
                raise ConfigError(
                    f"{name}: [{where}] {key} and {field}: give one of them, not both"
                )
        if field not in fields:
            raise ConfigError(
                f"{name}: [{where}] {key}: unknown key (known: "
                f"{', '.join(sorted(_public_keys(fields)))})"
            )
        sub = where if where != FLIGHT_TOP else ""
        dotted = f"{sub}.{key}".lstrip(".")
        if dataclasses.is_dataclass(hints[field]):
            value = _build(hints[field], raw, name, dotted, getattr(base, field))
        else:
            value = _coerce(hints[field], raw, name, where, key)
        values[field] = math.radians(value) if field != key else value
    try:
        return dataclasses.replace(base, **values)
    except ConfigError as err:  # FlightConfig's own range checks
        raise ConfigError(f"{name}: {err}") from None


def _public_keys(fields: set[str]) -> list[str]:
    return [f[:-4] + "_deg|" + f if f.endswith("_rad") else f for f in fields]


def _coerce(tp: Any, raw: Any, name: str, where: str, key: str) -> Any:
    def bad(expected: str) -> ConfigError:
        return ConfigError(f"{name}: [{where}] {key}: expected {expected}, got {_shown(raw)}")

    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in args if a is not type(None)]
        return _coerce(inner[0], raw, name, where, key)
    if tp is bool:
        if not isinstance(raw, bool):
            raise bad("true or false")
        return raw
    if tp is int:
        if isinstance(raw, bool) or not isinstance(raw, int) or abs(raw) >= 1 << 63:
            raise bad("an integer")
        return raw
    if tp is float:
        if not _number(raw):
            raise bad("a number")
        return float(raw)  # NaN and inf too: FlightConfig's range check names them
    if tp is str:
        if not isinstance(raw, str):
            raise bad("a string")
        return raw
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        choices = [m.value for m in tp]
        if raw not in choices:
            raise bad(" or ".join(repr(c) for c in choices))
        return tp(raw)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return _coerce_ids(raw, bad)
    if origin is tuple:
        if not isinstance(raw, list) or len(raw) != len(args) or not all(_number(v) for v in raw):
            raise bad(f"a list of {len(args)} numbers")
        return tuple(float(v) for v in raw)
    raise bad(f"a value of type {tp}")  # a FlightConfig field type this loader lacks


def _shown(raw: Any) -> str:
    """repr(raw), at most 200 characters; a TOML hex integer may have more digits than
    Python will write in decimal (ValueError)."""
    try:
        return repr(raw)[:200]
    except ValueError:
        return "a value too long to show"


def _number(raw: Any) -> bool:
    """A number a float holds (NaN and inf too: the range check names them)."""
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        return False
    return not isinstance(raw, int) or abs(raw) < 1e308


def _coerce_ids(raw: Any, bad: Any) -> tuple[int | str, ...]:
    """A list of user/group names or numeric ids (allowed_users, allowed_groups)."""
    expected = "a list of names or numeric ids"
    if not isinstance(raw, list):
        raise bad(expected)
    for v in raw:
        number = isinstance(v, int) and not isinstance(v, bool) and 0 <= v < 2**32
        if not (number or (isinstance(v, str) and v.strip() == v and v and ":" not in v)):
            raise bad(expected)
    return tuple(raw)
