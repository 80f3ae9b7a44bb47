"""Map a NatNet server's high-resolution clock onto the agent's clock.

Cristian's method with a minimum-round-trip filter: each echo request carries the agent's
send time, the server answers with its clock ticks on reception, and the estimate
offset = server_time - (sent + received) / 2 is trusted in proportion to how short the round
trip was. Of the last `window` echoes, the one with the shortest round trip wins, so a burst
of network delay does not move the estimate. Its error is at most half that round trip.
"""

from __future__ import annotations

from collections import deque


class ClockSync:
    """Server ticks -> agent seconds, once at least one echo came back."""

    def __init__(self, clock_hz: int, window: int = 16) -> None:
        if clock_hz <= 0:
            raise ValueError(f"server clock frequency must be > 0 Hz, got {clock_hz}")
        self.clock_hz = clock_hz
        self._samples: deque[tuple[float, float]] = deque(maxlen=window)  # (rtt, offset)
        self._pending: dict[int, float] = {}
        self._next_stamp = 1

    def request(self, now: float) -> int:
        """A stamp to send in an echo request made at agent time `now` [s]."""
        stamp = self._next_stamp
        self._next_stamp += 1
        self._pending[stamp] = now
        if len(self._pending) > 64:  # answers that never came
            self._pending.pop(min(self._pending))
        return stamp

    def response(self, stamp: int, server_ticks: int, now: float) -> bool:
        """Use an echo response received at agent time `now`; False if it matches no request."""
        sent = self._pending.pop(stamp, None)
        if sent is None or now < sent:
            return False
        server_s = server_ticks / self.clock_hz
        self._samples.append((now - sent, server_s - (sent + now) / 2.0))
        return True

    @property
    def synced(self) -> bool:
        return bool(self._samples)

    @property
    def round_trip_s(self) -> float | None:
        """[s] the round trip of the echo the estimate rests on."""
        return min(self._samples)[0] if self._samples else None

    def to_agent(self, server_ticks: int) -> float:
        """Agent time [s] of a server clock reading; requires `synced`."""
        return server_ticks / self.clock_hz - min(self._samples)[1]
