"""The Crazyflie link keeper's process (drivers/cflink.py), started by the driver as
`python -m perchd.service.cflink_main ARGS`. The drivers import no mocap: here the flight's
mocap is opened by its URI for the keeper's closed-loop descent."""

from __future__ import annotations

import sys

from perchd.core.ports import PoseSource
from perchd.core.runtime import Runtime
from perchd.drivers.cflink import main
from perchd.mocap.base import open_source


def open_mocap(uri: str) -> PoseSource:
    """The mocap URI's source, opened (its own modules imported) and not started."""
    return open_source(uri, Runtime.real())


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:], open_mocap))
