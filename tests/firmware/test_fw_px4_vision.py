"""Opt-in (PERCHD_PX4 = a PX4 SITL build folder): with GPS off (EKF2_GPS_CTRL 0) and EKF2 on
external vision (EKF2_EV_CTRL 11, EKF2_HGT_REF 3), PX4's own position estimate
(LOCAL_POSITION_NED) is the mocap perchd's driver forwards: it follows the true position
through a climb from the ground. Figures printed with -s."""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import pytest

pytest.importorskip("pymavlink")

from fwvision import PoseFeed, climb_and_compare

from perchd.core.runtime import Runtime
from perchd.drivers.base import open_driver
from perchd.sim.firmware.harness import ProcessGroup
from perchd.sim.firmware.px4 import SIH_MASS_KG, Px4Params, Px4Vehicle

PX4 = os.environ.get("PERCHD_PX4", "")
INSTANCE = int(os.environ.get("PERCHD_FW_INSTANCE", os.environ.get("PERCHD_PX4_INSTANCE", "0")))
pytestmark = [
    pytest.mark.firmware,
    pytest.mark.skipif(
        not (PX4 and os.access(Path(PX4) / "bin" / "px4", os.X_OK)),
        reason="set PERCHD_PX4 to a PX4 SITL build folder (docs/firmware.md)",
    ),
]


def test_px4s_ekf_follows_the_forwarded_mocap_with_gps_off(tmp_path):
    with ProcessGroup() as procs:
        v = Px4Vehicle(
            Px4Params(
                PX4,
                INSTANCE,
                takeoff=False,
                surface_ahead_m=None,
                vision=True,
                log=tmp_path / "px4.log",
            )
        )
        try:
            v.start(procs, threading.Event())
            runtime = Runtime.real()
            drv = open_driver(v.driver_uri() + "&arm=1", runtime)
            feed = PoseFeed(v.truth, drv)
            try:
                drv.connect()
                drv.engage()  # mode and arming: connect alone changes nothing
                figures = climb_and_compare(v.truth, drv, SIH_MASS_KG, runtime.clock.now)
            finally:
                feed.stop()
                drv.close()
        finally:
            v.close()
    print("\n" + json.dumps({"test": "px4-vision", **figures, "load": os.getloadavg()}))
    assert figures["climbed_m"] > 0.5
    # EKF2 on the forwarded mocap: its height trails the climb's start by a few tenths of a
    # second (measured: max 0.13-0.18 m, mean 0.071-0.076 m over six climbs at 0.5 m/s);
    # unfused, with GPS off, it would not follow the climb at all (an error of the whole 1 m)
    assert figures["max_error_m"] < 0.25
    assert figures["mean_error_m"] < 0.1
