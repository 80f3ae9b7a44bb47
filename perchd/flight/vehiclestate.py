"""Where a vehicle's profile (flight/profile.py) lives, and reading and writing it.

One file per vehicle: $XDG_STATE_HOME/perchd/vehicles/NAME.json (default
~/.local/state/perchd/vehicles/), or the file `perchd fly --state F` names; the service
keeps them under its state_dir. NAME is the vehicle's name (`perchd fly --vehicle`, else
the driver URI); a name that is not a plain file name is kept under a readable stem and a
hash of it, so two names never share a file.

The file is read by core/safefile.py's bounded regular-file rule and written by its
write_atomic. Only a profile of perchd's own is ever replaced: anything else at the path (a
plan, a FIFO, /dev/zero, a file of another schema) is refused before a flight by check()
and left as it is. Reading or writing never fails a flight: a missing, unreadable or
malformed file is no memory, an unwritable one a warning; each is said on the flight's
summary line (Visit.describe).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from perchd.core.errors import PerchdError
from perchd.core.safefile import OutputError, read_regular, write_text
from perchd.flight.config import FlightConfig
from perchd.flight.profile import SCHEMA, VehicleProfile, from_doc, is_profile

if TYPE_CHECKING:
    from perchd.flight.run import FlightResult

_PLAIN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")


def default_dir() -> Path:
    """$XDG_STATE_HOME/perchd/vehicles (default ~/.local/state/perchd/vehicles)."""
    base = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    return Path(base) / "perchd" / "vehicles"


def file_stem(name: str) -> str:
    """The profile's file name without .json: the name itself when plain, else its plain
    characters and 8 hex digits of its hash (a URI's '/' or '?' never leads elsewhere)."""
    if _PLAIN.fullmatch(name):
        return name
    readable = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._-")[:40]
    digest = hashlib.sha256(name.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    return f"{readable}-{digest}" if readable else digest


def profile_path(name: str, directory: Path | None = None) -> Path:
    """The profile file of the vehicle `name` under `directory` (default default_dir())."""
    return (default_dir() if directory is None else directory) / f"{file_stem(name)}.json"


@dataclass(frozen=True)
class Visit:
    """What a flight did with the profile: read (what it held, None: nothing), written
    (kept the flight's), why_not (why it was not written, None: written or nothing new)."""

    path: Path
    read: VehicleProfile | None
    written: bool = False
    why_not: str | None = None

    def describe(self) -> str:
        """'vehicle profile: PATH (read: hover 0.2950 N from 4 flights; written)'."""
        read = f"read: {self.read.describe()}" if self.read else "none yet"
        done = "written" if self.written else f"not written: {self.why_not or 'nothing learned'}"
        return f"vehicle profile: {self.path} ({read}; {done})"


@dataclass(frozen=True)
class VehicleStore:
    """The profile of the vehicle `name` at `path`; warn: where a warning line goes."""

    path: Path
    name: str
    warn: Callable[[str], None]

    def check(self) -> None:
        """OutputError (one line, before anything flies) unless the path is missing or a
        profile of perchd's own: a flight must never replace what is there."""
        try:
            os.lstat(self.path)
        except (FileNotFoundError, NotADirectoryError):
            return
        except (OSError, ValueError) as err:  # too long, a NUL byte, no permission
            why = err.strerror if isinstance(err, OSError) else err
            raise OutputError(f"--state {self.path}: cannot read ({why})") from None
        if self._doc() is None:
            raise OutputError(
                f"--state {self.path}: not a perchd vehicle profile "
                f"(schema {SCHEMA}); give another path"
            )

    def _doc(self) -> dict[str, Any] | None:
        """The profile's JSON; {} when there is none, None when the path holds something
        else (unreadable, not a regular file, not JSON, another schema)."""
        if not os.path.lexists(self.path):
            return {}
        try:
            doc = json.loads(read_regular(self.path, "", PerchdError))
        except (PerchdError, ValueError, RecursionError):
            return None
        return doc if is_profile(doc) else None

    def read(self) -> VehicleProfile | None:
        """The kept profile, None when there is none (or not one of perchd's)."""
        doc = self._doc()
        return from_doc(doc, self.name) if doc else None

    def with_learned_guess(self, cfg: FlightConfig) -> tuple[FlightConfig, Visit]:
        """cfg with the kept hover as its initial guess, unless the config gives one
        (vehicle.hover_thrust_n overrides the memory); the Visit records what was read."""
        kept = self.read()
        guess = kept.hover_guess_n(cfg.vehicle) if kept else None
        if guess is not None and cfg.vehicle.hover_thrust_n is None:
            cfg = replace(cfg, vehicle=replace(cfg.vehicle, hover_thrust_n=guess))
        return cfg, Visit(self.path, kept)

    def remember_flight(self, cfg: FlightConfig, res: FlightResult, visit: Visit) -> Visit:
        """Keep what the flight learned of the vehicle: the hover its hold learned and the
        lag and drag it identified; the visit, completed."""
        if res.hover_n is None and res.lag_model is None:
            return visit
        profile = (self.read() or VehicleProfile(self.name)).learned(
            cfg.vehicle, res.hover_n, res.lag_model
        )
        try:
            if self._doc() is None:
                raise OutputError(f"{self.path}: not a perchd vehicle profile; left as it is")
            self.path.parent.mkdir(parents=True, exist_ok=True)
            write_text(
                self.path, json.dumps(profile.to_doc(), indent=1) + "\n", "--state", force=True
            )
        except OSError as err:
            why = str(err) if isinstance(err, PerchdError) else err.strerror or str(err)
            self.warn(f"warning: vehicle profile {self.path} not written: {why}")
            return Visit(visit.path, visit.read, False, why)
        return Visit(visit.path, visit.read, True)

    def forget(self) -> bool:
        """Remove the profile; False when there was none. OutputError when the path holds
        something else (it is left as it is)."""
        self.check()
        if not os.path.lexists(self.path):
            return False
        os.unlink(self.path)
        return True
