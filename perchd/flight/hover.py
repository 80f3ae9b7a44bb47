"""The hover thrust, learned while the vehicle holds before the approach.

A vehicle's true weight in the driver's newtons is rarely mass_kg * g: the mass is
weighed with another battery, a thrust calibration was made on another airframe (the
Crazyflie firmware-in-the-loop hovers at 38780 units where the default model says 36000).
Each tick the vertical thrust last commanded, scaled by g / (g + measured vertical
acceleration), is one measurement of the thrust that would hold the vehicle still; a
low-pass of them is the estimate the controller feeds forward (Controller.hover_n). It is a
measurement, not an integral of the height error, so it adds no integrator to the z loop.
The approach waits until the estimate has settled (HoverConfig).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from perchd.flight.config import HoverConfig

TAU_S = 0.25
"""[s] time constant of the low-pass on the measured hover thrust."""
SETTLE_S = 0.4
"""[s] the estimate has settled once it stayed within REL_TOL of itself this long, the
height within Z_TOL_M of its reference and |zdot| below VZ_TOL_MPS."""
REL_TOL = 0.01
"""Relative spread of the estimate over SETTLE_S that counts as settled."""
Z_TOL_M = 0.15
"""[m] see SETTLE_S."""
VZ_TOL_MPS = 0.15
"""[m/s] see SETTLE_S."""
RATIO = (0.6, 1.6)
"""A learned hover outside this multiple of mass_kg * g is refused: a wrong mass or
calibration by that much is not flown on."""


@dataclass(frozen=True, slots=True)
class HoverStatus:
    """estimate_n [N]; spread: relative (max - min) / estimate over the settle window so
    far; steady_s [s] the window covered with height and climb rate in tolerance."""

    estimate_n: float
    spread: float
    steady_s: float


class HoverLearner:
    def __init__(self, cfg: HoverConfig, guess_n: float, g: float) -> None:
        self.cfg, self.g = cfg, g
        self.guess_n = guess_n
        self.estimate_n = guess_n
        self._window: deque[tuple[float, float]] = deque()  # (t [s], estimate [N])

    def update(self, t: float, thrust_z_n: float, zddot: float, dt: float) -> None:
        """Fold in one tick: thrust_z_n [N] the vertical thrust commanded on the last tick,
        zddot [m/s^2] the vertical acceleration measured now, dt [s] the tick."""
        if dt <= 0.0:
            return
        sample = thrust_z_n * self.g / max(self.g + zddot, 0.2 * self.g)
        self.estimate_n += dt / (TAU_S + dt) * (sample - self.estimate_n)
        self._window.append((t, self.estimate_n))
        while self._window and self._window[0][0] < t - SETTLE_S:
            self._window.popleft()

    def status(self, t: float, z_err_m: float, zdot: float) -> HoverStatus:
        """The estimate and how settled it is; a height or climb out of tolerance restarts
        the window (the vehicle is not holding, so its thrust says nothing settled)."""
        if abs(z_err_m) > Z_TOL_M or abs(zdot) > VZ_TOL_MPS:
            self._window.clear()
        if not self._window:
            return HoverStatus(self.estimate_n, float("inf"), 0.0)
        values = [v for _, v in self._window]
        spread = (max(values) - min(values)) / self.estimate_n
        return HoverStatus(self.estimate_n, spread, t - self._window[0][0])

    def settled(self, st: HoverStatus) -> bool:
        # The window holds SETTLE_S of ticks, its first a tick inside it: allow 5 % short.
        return st.steady_s >= 0.95 * SETTLE_S and st.spread <= REL_TOL
