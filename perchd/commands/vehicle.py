"""`perchd vehicle show NAME [--state F] [--json]`, `perchd vehicle forget NAME [--state F]`:
see or remove what flights learned of a vehicle (its profile, flight/profile.py).

NAME is the name `perchd fly --vehicle` gave (else its driver URI); the profile is
$XDG_STATE_HOME/perchd/vehicles/NAME.json unless --state names the file. `show` exits 1
when there is none; `forget` removes only a profile of perchd's own (anything else at the
path: exit 2, left as it is) and exits 0 when there was none.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from perchd.flight.profile import VehicleProfile
from perchd.flight.vehiclestate import VehicleStore, profile_path


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "vehicle",
        help="see or forget what flights learned of a vehicle",
        description=__doc__.splitlines()[0],
    )
    actions = p.add_subparsers(dest="action", required=True)
    show = actions.add_parser("show", help="print the vehicle's profile")
    forget = actions.add_parser("forget", help="remove the vehicle's profile")
    for sub in (show, forget):
        sub.add_argument("name", metavar="NAME", help="the vehicle's name (perchd fly --vehicle)")
        sub.add_argument(
            "--state",
            metavar="F",
            help="the profile file (default $XDG_STATE_HOME/perchd/vehicles/NAME.json)",
        )
    show.add_argument("--json", action="store_true", help="print the profile's JSON")
    show.set_defaults(run=run_show)
    forget.set_defaults(run=run_forget)


def store(args: argparse.Namespace) -> VehicleStore:
    """The named vehicle's profile, checked to be perchd's own (or missing)."""
    path = Path(args.state) if args.state else profile_path(args.name)
    found = VehicleStore(path, args.name, lambda line: print(line, file=sys.stderr))
    found.check()
    return found


def run_show(args: argparse.Namespace) -> int:
    profile = (s := store(args)).read()
    if profile is None:
        print(f"perchd vehicle: no profile for {args.name!r} at {s.path}", file=sys.stderr)
        return 1
    print(json.dumps(profile.to_doc(), indent=1) if args.json else text(s.path, profile))
    return 0


def text(path: Path, p: VehicleProfile) -> str:
    """The profile in words, one line per property."""
    lines = [f"vehicle profile: {path}", f"vehicle: {p.name}"]
    if p.hover:
        h = p.hover
        lines.append(
            f"hover: {h.thrust_n:.4f} N ({h.ratio:.3f} x the weight of "
            f"{h.mass_kg:g} kg) from {h.flights} flight(s)"
        )
    if p.response:
        r = p.response
        lines.append(
            f"response: lag {r.lag_s:.3f} s ({r.time_constant_s:.3f} s of it "
            f"first-order), drag {r.drag_per_s:.3f} 1/s, the latest of "
            f"{r.flights} flight(s) (each flight identifies its own)"
        )
    return "\n".join(lines if len(lines) > 2 else [*lines, "nothing learned yet"])


def run_forget(args: argparse.Namespace) -> int:
    s = store(args)
    print(f"perchd vehicle: {'forgot' if s.forget() else 'nothing to forget at'} {s.path}")
    return 0
