"""A stalled control loop gets restarted by systemd's watchdog: `perchd serve` pings
WATCHDOG=1 from the flight's own tick, so while a tick hangs (here: a simulated link that
hangs, `sim://?stall=AT,FOR`) no ping arrives for longer than WatchdogSec, and systemd
(played here by the test's notify socket) would restart the service. If it is not restarted,
the loop resumes, the pings come back, and the flight still ends properly."""

from __future__ import annotations

import signal
import time

import pytest
from svc import PLAN, NotifyListener, Serve, ctl

from perchd.core.clock import ManualClock, MonotonicClock
from perchd.core.errors import UriError
from perchd.core.uri import parse_uri
from perchd.logs.flightlog import read_log
from perchd.sim.stall import Stall
from perchd.sim.world import SimWorld, WorldParams, world_params_from_uri

WATCHDOG_S = 2.0
"""WatchdogSec of the test service (svc.Serve sets WATCHDOG_USEC=2000000)."""
STALL = (0.3, 3.0)
"""[s] the link hangs 0.3 s into the flight (hovering at the start) for 3 s > WATCHDOG_S."""


# --- the stall option itself -------------------------------------------------------------
def test_a_stall_holds_the_next_caller_once_for_its_length_on_the_worlds_clock():
    clock = ManualClock(10.0)
    world = SimWorld(WorldParams(stall=Stall(0.5, 2.0)), clock)
    clock.advance(0.4)
    world.latest_pose()
    assert clock.now() == pytest.approx(10.4)  # not yet
    clock.advance(0.2)
    world.latest_pose()
    assert clock.now() == pytest.approx(12.6)  # the call took 2 s of simulated time
    world.latest_pose()
    assert clock.now() == pytest.approx(12.6)  # once only
    assert world.latest_pose().t > 12.5  # and the world caught up afterwards


def test_on_the_real_clock_a_stalled_call_really_blocks():
    world = SimWorld(WorldParams(stall=Stall(0.0, 0.2)), MonotonicClock())
    t0 = time.monotonic()
    world.latest_pose()
    assert time.monotonic() - t0 >= 0.2


@pytest.mark.parametrize(
    "text, words",
    [
        ("1", "stall='1' must be AT,FOR in seconds"),
        ("1,x", "stall='1,x' must be AT,FOR in seconds"),
        ("-1,2", "stall AT=-1 s is outside 0..3600 s"),
        ("1,0", "stall FOR=0 s is outside 0..60 s (above 0)"),
        ("1,61", "stall FOR=61 s is outside 0..60 s"),
    ],
)
def test_a_bad_stall_option_is_one_error_naming_it(text, words):
    with pytest.raises(UriError, match=words.replace("(", r"\(").replace(")", r"\)")):
        world_params_from_uri(parse_uri(f"sim://?stall={text}"))


def test_without_the_option_nothing_stalls():
    assert world_params_from_uri(parse_uri("sim://?latency=0.02")).stall is None
    assert world_params_from_uri(parse_uri("sim://?stall=1.5,3")).stall == Stall(1.5, 3.0)


# --- perchd serve under a watchdog ---------------------------------------------------------
class Pings:
    """Arrival times [s, time.monotonic()] of WATCHDOG=1 on the test's notify socket."""

    def __init__(self, listener: NotifyListener) -> None:
        self.listener, self.times = listener, []

    def collect(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            self.listener.sock.settimeout(left)
            try:
                msg = self.listener.sock.recv(4096).decode()
            except TimeoutError:
                return
            self.listener.messages.append(msg)
            if "WATCHDOG=1" in msg.split("\n"):
                self.times.append(time.monotonic())

    def gaps(self, start: float = 0.0, end: float = float("inf")) -> list[float]:
        ts = [t for t in self.times if start <= t <= end]
        return [b - a for a, b in zip(ts, ts[1:])]


def phase_after(serve: Serve, pings: Pings, phases: set[str], timeout: float) -> dict:
    """Poll the status (collecting pings meanwhile) until the flight is in one of `phases`."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        st = ctl(serve.sock, "status")
        if st.get("phase") in phases or st["state"] != "flying":
            return st
        pings.collect(0.05)
    raise AssertionError(f"never reached {phases}: {st}")


@pytest.mark.slow
def test_a_stalled_control_loop_stops_the_watchdog_and_a_resumed_one_pings_again(tmp_path, notify):
    at, length = STALL
    serve = Serve(tmp_path, notify, "--driver", f"sim://?stall={at},{length}", "--mocap", "sim://")
    pings = Pings(notify)
    try:
        notify.wait_for("READY=1")
        pings.collect(1.2)  # idle: the service loop pings
        flying_at = time.monotonic()
        started = ctl(serve.sock, "fly", str(PLAN))
        assert started["ok"], started
        pings.collect(at + 0.5)  # now inside the stall
        frozen = ctl(serve.sock, "status")  # the service still answers...
        pings.collect(1.0)
        still = ctl(serve.sock, "status")
        assert still["state"] == "flying" and still["t"] == frozen["t"]  # ...the loop does not
        resumed = phase_after(serve, pings, {"approach", "stage1"}, 5.0)
        assert resumed["state"] == "flying" and resumed["t"] > frozen["t"]
        pings.collect(0.6)  # flying again: ticks ping again
        back_at = time.monotonic()
        assert ctl(serve.sock, "abort")["aborting"] is True
        pings.collect(1.2)  # idle again
        serve.proc.send_signal(signal.SIGTERM)
        code, err = serve.stop()
    finally:
        serve.kill()
    assert code == 0, err
    longest = max(pings.gaps(flying_at))
    assert WATCHDOG_S < longest < length + 0.6  # systemd would have restarted it
    # Pings every WATCHDOG_USEC / 4 = 0.5 s when healthy; the bound that matters is < 2 s.
    assert max(pings.gaps(end=flying_at)) < 1.0
    stall_end = next(b for a, b in zip(pings.times, pings.times[1:]) if b - a == longest)
    after = [t for t in pings.times if stall_end <= t <= back_at]
    assert len(after) >= 2 and max(pings.gaps(stall_end)) < 1.0  # resumed, idle after too
    log = read_log(started["log"])
    assert log.complete and log.end["outcome"] == "OPERATOR_ABORT"
    assert log.end["summary"]["failsafe_sent"] is True
    row_gaps = [b.t - a.t for a, b in zip(log.rows, log.rows[1:])]
    assert length - 0.05 < max(row_gaps) < length + 0.2  # the stalled tick, in the log
    assert log.end["summary"]["loop"]["missed"] >= 100 * length - 10  # 100 Hz deadlines skipped


@pytest.mark.slow
def test_sigterm_while_the_loop_is_stalled_ends_the_flight_once_it_resumes(tmp_path, notify):
    at, length = STALL
    # The fixed-rate loop: the stalled link holds a tick, which then ends the flight. (The
    # default mocap-synchronous loop is held waiting for the stalled world's next frame, and
    # its first tick after the stall ends it.)
    serve = Serve(
        tmp_path,
        notify,
        "--driver",
        f"sim://?stall={at},{length}",
        "--mocap",
        "sim://",
        tables='[flight]\nsync = "fixed"\n',
    )
    try:
        notify.wait_for("READY=1")
        started = ctl(serve.sock, "fly", str(PLAN))
        time.sleep(at + 0.5)  # inside the stall
        frozen = ctl(serve.sock, "status")["t"]
        sent = time.monotonic()
        serve.proc.send_signal(signal.SIGTERM)
        code, err = serve.stop()
        took = time.monotonic() - sent
    finally:
        serve.kill()
    assert code == 0, err
    assert "flight ended: SIGNAL" in err and "sending the failsafe directly" not in err
    assert 1.0 < took < length  # waited for the stall, no longer
    log = read_log(started["log"])
    assert log.complete and log.end["outcome"] == "SIGNAL"
    assert log.end["summary"]["failsafe_sent"] is True
    assert log.rows[-1].end == "SIGNAL"  # the stalled tick ended the flight
    assert frozen < log.rows[-1].t - log.rows[0].t < frozen + 0.05  # the tick after `frozen`
