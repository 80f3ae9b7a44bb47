"""Mocap faults, one at a time, in simulated time: frames that stop, arrive late, out of
order, twice, frozen, displaced, invalid, at 20 % of the rate, or full of NaN and huge
numbers. A fault that leaves the agent more than 3 frame periods without a usable frame ends
the flight as STALE_MOCAP on the next control tick (failsafe sent, log closed); anything
less is flown through and the vehicle still perches."""

from __future__ import annotations

import math

import pytest
from aborts import assert_failsafe_and_closed_log
from faultsim import PERIOD, TICK, fly, report

from perchd.core.types import EndReason
from perchd.flight.config import FlightConfig, LoopSync
from perchd.sim.faults import (
    Corrupt,
    Freeze,
    Invalid,
    Late,
    Outliers,
    RateDrop,
    Reorder,
    Repeat,
    Stop,
)

ONSETS = {"hold": 0.3, "approach": 1.5, "stage1": 3.0, "stage1+": 3.003, "stage2": 4.2}
"""[s] simulated fault onsets: the flight triggers at 2.57 s, switches stage at 4.07 s and
touches at 4.57 s; 3.0 and 3.003 put the onset at two phases of the frame/tick beat."""

STALE = {
    "frames stop": lambda t: Stop(t),
    "frames 30 ms late": lambda t: Late(t, math.inf, 0.030),
    "same frame replayed": lambda t: Freeze(t),
    "tracking lost (invalid)": lambda t: Invalid(t),
    "rate drops to 20 %": lambda t: RateDrop(t, keep_every=5),
    "NaN in every frame": lambda t: Corrupt(t),
    "huge values (1e12 m)": lambda t: Corrupt(t, value=1e12),
    "position jumps 0.5 m for good": lambda t: Outliers(t, every=1),
}


LOOPS = {
    "fixed 100 Hz": (FlightConfig(sync=LoopSync.FIXED), TICK),
    "mocap-sync 120 Hz": (FlightConfig(sync=LoopSync.MOCAP, rate_hz=120.0), 1.5 * PERIOD),
}
"""The two loops (FlightConfig.sync) and the longest gap between their ticks [s]: the fixed
loop's period; the mocap-synchronous loop ticks on every frame, or 1.5 periods without one."""


@pytest.fixture(scope="module")
def nominal(tmp_path_factory):
    return {
        loop: fly(tmp_path_factory.mktemp("nominal"), cfg=cfg).res
        for loop, (cfg, _) in LOOPS.items()
    }


@pytest.mark.parametrize("loop", LOOPS)
@pytest.mark.parametrize("name", STALE)
def test_a_fault_that_starves_the_estimator_is_stale_mocap_on_the_first_tick_after_3_periods(
    name, loop, tmp_path
):
    cfg, tick = LOOPS[loop]
    delays = []
    for phase, onset in ONSETS.items():
        f = fly(tmp_path, STALE[name](onset), cfg=cfg, name=phase)
        assert_failsafe_and_closed_log(f.sim, f.res, EndReason.STALE_MOCAP)
        assert f.sim.world.contact is None
        # more than 3 periods since the newest usable frame, and at most one tick more
        assert 3 * PERIOD - 1e-9 < f.since_last_fused <= 3 * PERIOD + tick + 1e-9, phase
        delays.append(f.since_last_fused)
    report(
        f"mocap: {name} ({loop} loop)",
        "> 3 frame periods (25 ms) without a usable frame, checked every tick",
        "STALE_MOCAP, failsafe",
        "motors off (stop setpoint)",
        delays,
    )


def test_a_gap_of_two_frames_is_flown_through(tmp_path, nominal):
    f = fly(tmp_path, Stop(3.0, 3.0 + 2 * PERIOD))
    assert f.res.outcome is EndReason.CONTACT
    assert f.res.contact_speed == pytest.approx(nominal["fixed 100 Hz"].contact_speed, abs=1e-3)
    report("mocap: 2 frames missing", "none needed", "estimator predicts across the gap", "perches")


@pytest.mark.parametrize(
    "name, faults",
    [
        ("frames 15 ms late", (Late(3.0, 3.3, 0.015),)),
        ("pairs out of order all flight", (Reorder(),)),
        ("every frame 3 times", (Repeat(times=3),)),
        ("outlier (0.5 m) every 10th frame", (Outliers(every=10),)),
        ("outlier (0.5 m) every 3rd frame", (Outliers(every=3),)),
        ("glitch (3 cm) every 37th frame", (Outliers(every=37, jump_m=0.03),)),
        ("glitch (4 cm) every 31st frame", (Outliers(every=31, jump_m=0.04),)),
        ("invalid for 2 frames", (Invalid(3.0, 3.0 + 2 * PERIOD),)),
        ("rate drops to 50 %", (RateDrop(keep_every=2),)),
        ("NaN in every 10th frame", (Corrupt(every=10),)),
        ("inf in every 10th frame", (Corrupt(value=math.inf, every=10),)),
        ("1e12 m in every 10th frame", (Corrupt(value=1e12, every=10),)),
    ],
    ids=lambda v: v if isinstance(v, str) else "",
)
@pytest.mark.parametrize("loop", LOOPS)
def test_faults_within_the_estimator_s_tolerance_still_perch(loop, name, faults, tmp_path, nominal):
    f = fly(tmp_path, *faults, cfg=LOOPS[loop][0])
    assert f.res.outcome is EndReason.CONTACT and not f.res.failsafe_sent
    assert f.res.true_contact_speed == pytest.approx(nominal[loop].true_contact_speed, abs=0.01)
    # the agent's estimate at contact: on frames in swapped pairs (every other one dropped)
    # stage 2's speed loop, as fast as the vehicle's lag allows, moves 0.945-0.996 m/s, and
    # the estimate lags it by up to 0.017 m/s (0.9494 against the true 0.9662)
    assert f.res.contact_speed == pytest.approx(nominal[loop].contact_speed, abs=0.025)
    seqs = [r.pose_seq for r in f.log.rows if r.pose_seq >= 0]
    assert seqs == sorted(seqs)  # an older frame never replaced a newer one
    report(
        f"mocap: {name} ({loop} loop)",
        "per frame (dropped: older, same seq, non-finite, a jump > 10 m/s, or off the track"
        " for one frame)",
        "frame ignored; the filter predicts",
        "perches",
    )


def test_repeated_frames_change_nothing_at_all(tmp_path, nominal):
    f = fly(tmp_path, Repeat(times=3))
    assert f.res.contact_speed == nominal["fixed 100 Hz"].contact_speed
    assert f.res.perch_time == nominal["fixed 100 Hz"].perch_time


def test_a_frozen_tracker_with_fresh_stamps_is_stale_while_the_vehicle_moves(tmp_path):
    """Old position, fresh time: each frame looks new. A body the filter sees moving cannot
    repeat its position to the bit, so those frames are dropped and the flight ends stale
    3 periods later; this fault once flew the vehicle into the wall at 2.1 m/s."""
    delays = []
    for onset in (ONSETS["approach"], ONSETS["stage1+"], 4.1, ONSETS["stage2"]):
        f = fly(tmp_path, Freeze(onset, restamp=True))
        assert_failsafe_and_closed_log(f.sim, f.res, EndReason.STALE_MOCAP)
        assert f.sim.world.contact is None
        assert 3 * PERIOD < f.since_last_fused <= 3 * PERIOD + TICK + 1e-9
        delays.append(f.since_last_fused)
    report(
        "mocap: frozen position, fresh stamps, vehicle moving",
        "bit-identical position while the estimate moves: frame dropped, then > 3 periods",
        "STALE_MOCAP",
        "motors off, short of the wall",
        delays,
    )


def test_a_tracker_frozen_while_hovering_is_stale_once_the_approach_should_move_it(tmp_path):
    """Frozen during the hold the frames are believable (a hovering body), until the
    approach has commanded motion for FROZEN_MAX_S without the position changing a bit."""
    from perchd.flight.endrules import FROZEN_MAX_S

    f = fly(tmp_path, Freeze(ONSETS["hold"], restamp=True))
    assert_failsafe_and_closed_log(f.sim, f.res, EndReason.STALE_MOCAP)
    assert "mocap frozen" in f.res.detail and f.sim.world.contact is None
    approach = next(e.t for e in f.log.events if e.kind == "approach")
    assert FROZEN_MAX_S <= f.end_t - approach <= FROZEN_MAX_S + TICK + 1e-9
    assert f.sim.world.gap(f.sim.world.plant.p) < -4.0  # it had barely started to move
    report(
        "mocap: frozen position, fresh stamps, from the hold",
        f"position bit-identical for > {FROZEN_MAX_S:g} s of approach",
        "STALE_MOCAP ('mocap frozen')",
        "motors off near the start point",
        [f.end_t - approach],
    )


def test_the_stale_limit_counts_mocap_frames_not_the_loop_s_polls():
    """At 120 Hz mocap a 100 Hz loop sees 5 frames in 6; the frame period the stale rule
    multiplies by 3 is still 1/120 s (from the frames' seq numbers), not ~1/100 s."""
    from perchd.core.types import Pose
    from perchd.flight.estimator import Estimator, EstimatorConfig
    from perchd.flight.frame import PerchFrame

    est = Estimator(EstimatorConfig(), PerchFrame.from_surface((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    seen = [k for k in range(120) if k % 6 != 5]
    for k in seen:
        est.offer(Pose("cf1", k + 1, k * PERIOD, (-3.0 + 0.01 * k, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0)))
    assert est.mocap_period == pytest.approx(PERIOD, rel=1e-9)
