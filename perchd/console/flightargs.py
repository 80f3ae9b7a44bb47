"""The flight config a command flies: --config's TOML and the --surface/--normal flags over it,
with the geometry refused before any link opens."""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Sequence

from perchd.console.argcheck import within
from perchd.core.errors import ConfigError
from perchd.flight.config import MAX_COORD_M, FlightConfig, SurfaceConfig
from perchd.service.config import load_flight_config


def load_config(args: argparse.Namespace) -> FlightConfig:
    """FlightConfig from --config (the TOML loader, perchd.service.config) and --surface/--normal."""

    cfg = FlightConfig()
    if args.config:
        cfg = load_flight_config(args.config)
    surface = cfg.surface
    if args.surface:
        surface = dataclasses.replace(surface, point=tuple(args.surface))
    if args.normal:
        surface = dataclasses.replace(surface, normal=tuple(args.normal))
    where = f"in --config {args.config}" if args.config else "default"
    check_geometry(
        surface.point,
        surface.normal,
        "--surface" if args.surface else f"[surface] point ({where})",
        "--normal" if args.normal else f"[surface] normal ({where})",
    )
    return dataclasses.replace(cfg, surface=SurfaceConfig(surface.point, surface.normal))


def check_geometry(
    point: Sequence[float], normal: Sequence[float], point_flag: str, normal_flag: str
) -> None:
    """Refuse non-finite or absurd geometry before any link opens (a NaN surface used to start
    a flight that ended STALE_MOCAP)."""
    within(point_flag, point, -MAX_COORD_M, MAX_COORD_M, "m")
    within(normal_flag, normal, -1e6, 1e6, "")
    if math.sqrt(sum(c * c for c in normal)) < 1e-9:
        raise ConfigError(
            f"{normal_flag} {' '.join(f'{c:g}' for c in normal)}: must be a non-zero direction"
        )


def surface_args(p: argparse.ArgumentParser) -> None:
    """--surface and --normal of a simulated world (defaults: the origin, approach along +X)."""
    p.add_argument(
        "--surface",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        default=(0.0, 0.0, 0.0),
        help="[m] a point on the surface (default 0 0 0)",
    )
    p.add_argument(
        "--normal",
        nargs=3,
        type=float,
        metavar=("NX", "NY", "NZ"),
        default=(1.0, 0.0, 0.0),
        help="approach direction (default 1 0 0)",
    )
