"""Phases timed on the wall clock by a helper thread or process (the MAVLink sentinel's
brake, the Crazyflie keeper's descent), asserted as the vehicle received them.

A late wakeup on a shared, loaded machine only lengthens such a phase: each ends on a
sleep that can overrun, none on one that can fall short. So a phase is bounded tightly
from below (it was not cut short) and by LATE_S from above (it did end)."""

from __future__ import annotations

LATE_S = 0.15
"""[s] the most late wakeups add to one phase on two loaded cores (the longest seen: a
0.5 s level phase received over 0.58 s)."""


def assert_lasted(
    measured_s: float, nominal_s: float, early_s: float = 0.0, late_s: float = LATE_S
) -> None:
    """measured_s [s] within nominal_s - early_s (the send period's rounding) and
    nominal_s + late_s."""
    lo, hi = nominal_s - early_s, nominal_s + late_s
    assert lo <= measured_s <= hi, f"lasted {measured_s:.3f} s, not within {lo:.3f}..{hi:.3f} s"
