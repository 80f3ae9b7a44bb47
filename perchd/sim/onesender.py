"""One sender steers the simulated vehicle at a time (docs/safety.md "One vehicle, one agent").

Setpoints and stops carry their driver's sender id (docs/contracts.md §3). The first sender
heard holds the vehicle while it is live: until its own `stop`, or SENDER_LIVE_S without a
message from it (an agent killed without a stop). Meanwhile another sender's setpoints and
stops are refused, so a second agent neither steers the vehicle nor stops the first's flight.
"""

from __future__ import annotations

from dataclasses import dataclass

SENDER_LIVE_S = 1.0
"""[s] a holder silent this long has gone: the next sender takes the vehicle."""


@dataclass
class SenderGate:
    live_s: float = SENDER_LIVE_S
    holder: str | None = None
    last_s: float = float("-inf")  # [s] on the world's clock: the holder's last message

    def admit(self, sender: str, now: float) -> bool:
        """A setpoint from `sender` at `now`: True if it may steer the vehicle."""
        if not self._free_for(sender, now):
            return False
        self.holder, self.last_s = sender, now
        return True

    def stop(self, sender: str, now: float) -> bool:
        """A stop from `sender`: True if it counts (then the vehicle is free again)."""
        if not self._free_for(sender, now):
            return False
        self.holder = None
        return True

    def _free_for(self, sender: str, now: float) -> bool:
        return self.holder in (None, sender) or now - self.last_s > self.live_s
