"""The sentinel (sentinel.py) from the driver's side: started at the acknowledged switch to
the offboard mode, told whether perchd flies the vehicle, and kept supplied with the brake to
fly (brake.py, renewed from the mocap) and the yaw0 the mocap is to be relayed in."""

from __future__ import annotations

import logging
import time
from typing import Any

from perchd.core.ned import ned_vec
from perchd.drivers.mavlink.brake import WillSchedule, brake_for
from perchd.drivers.mavlink.dialect import Mode
from perchd.drivers.mavlink.link import Connection
from perchd.drivers.mavlink.sentinel import Sentinel

log = logging.getLogger(__name__)


class SentinelGuard:
    """One driver's sentinel, `uri` naming the driver in its warnings."""

    def __init__(self, uri: str) -> None:
        self.uri = uri
        self._sentinel: Sentinel | None = None
        self._will = WillSchedule()
        self._yaw0_told: float | None = None  # the yaw0 the sentinel last heard

    @property
    def started(self) -> bool:
        return self._sentinel is not None

    def flying(
        self,
        link: Connection,
        target: tuple[int, int],
        land: Mode,
        mocap: str | None,
        flight_mode: int,
    ) -> None:
        """perchd flies the vehicle `target` on `link` in `flight_mode` (custom_mode): the
        sentinel, started on the first call, is to `land` it should this process die and
        relay `mocap` (None: nothing). One that cannot start is warned of, not raised."""
        if self._sentinel is None:
            try:
                self._sentinel = Sentinel(link, target, (land.main, land.sub), mocap, flight_mode)
            except (OSError, ValueError) as err:
                log.warning(
                    "%s: no MAVLink sentinel (%s): if this process dies, only the "
                    "autopilot's own failsafe acts",
                    self.uri,
                    err,
                )
                return
            self._yaw0_told = None
        self._sentinel.flying(True)

    def not_flying(self) -> None:
        """The vehicle is landing, or the pilot's: no longer perchd's to land."""
        if self._sentinel is not None:
            self._sentinel.flying(False)

    def renew(self, pose: Any, yaw0: float | None, heading_ned: float, hover: float | None) -> None:
        """Every pose the flight uses: every WILL_PERIOD_S, the brake against its velocity
        at `heading_ned` [rad] with `hover` thrust (None: no brake now), in the frame yaw0
        [rad] (None: none known, no brake), which is told when it changed."""
        now = time.monotonic()
        velocity = self._will.due(pose, now)  # every pose: the velocity stays current
        if velocity is None or self._sentinel is None or yaw0 is None or hover is None:
            return
        self._sentinel.will(brake_for(ned_vec(velocity, yaw0), heading_ned, hover, now))
        if yaw0 != self._yaw0_told:
            self._yaw0_told = yaw0
            self._sentinel.yaw0(yaw0)

    def end(self, hand_over: bool) -> None:
        """hand_over: the sentinel relays the mocap until the landing is over; else it is
        released and exits without acting."""
        sentinel, self._sentinel = self._sentinel, None
        if sentinel is None:
            return
        if hand_over:
            sentinel.hand_over()
        else:
            sentinel.release()
