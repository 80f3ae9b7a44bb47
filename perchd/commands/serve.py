"""`perchd serve [--config perchd.toml] [--socket PATH] [--driver URI] [--mocap URI]`:
the flight agent as a service (systemd Type=notify); see perchd.service.daemon."""

from __future__ import annotations

import argparse

from perchd.service.daemon import serve


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "serve",
        help="run the flight agent as a service (systemd)",
        description=__doc__.splitlines()[0],
    )
    p.add_argument("--config", help="service configuration (TOML, see systemd/perchd.toml)")
    p.add_argument(
        "--socket",
        help="control socket path (default from the config, else /run/perchd/control.sock)",
    )
    p.add_argument("--driver", help="vehicle URI (overrides [service] driver)")
    p.add_argument("--mocap", help="mocap URI (overrides [service] mocap)")
    p.add_argument(
        "--log-dir",
        help="flight log directory (overrides [service] log_dir; "
        "default /var/log/perchd, or the unit's LogsDirectory)",
    )
    p.add_argument(
        "--plan-dir",
        help="plan directory (overrides [service] plan_dir; default "
        "/var/lib/perchd/plans, or the unit's StateDirectory/plans)",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:

    return serve(
        args.config,
        {
            "socket": args.socket,
            "driver": args.driver,
            "mocap": args.mocap,
            "log_dir": args.log_dir,
            "plan_dir": args.plan_dir,
        },
    )
