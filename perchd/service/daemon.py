"""`perchd serve`: the flight agent as a long-running service (under systemd or not).

One thread runs the service loop: select() on the control socket, its clients and a
self-pipe that signals (signal.set_wakeup_fd) and the flight thread write to. A flight runs
in its own thread through perchd.flight.run.fly, so abort and status stay answerable while it
flies. The links are connected at start-up, which changes nothing on the vehicle; each
flight engages the driver (Driver.engage, in flight.run.fly), so an idle or restarted service
leaves the vehicle in the mode it found it, e.g. the LAND a failsafe commanded
(docs/safety.md "When a flight takes the vehicle"). systemd hears READY=1 once mocap and
driver are connected, WATCHDOG=1 from the
flight's own tick callback while flying and from the service loop while idle and the link is
healthy (a stalled loop stops the pings and gets restarted), STATUS= with the phase, and
STOPPING=1 on the way out. SIGTERM/SIGINT abort a flight with the driver's failsafe (end
reason SIGNAL) and wait for its log to close; SIGTERM is a service's stop request (systemctl
stop), so it exits 0, while SIGINT (Ctrl-C) exits 130 like every command (docs/contracts.md
§6). SIGUSR1 is abort, as `perchd ctl abort` (docs/safety.md "The operator always wins").
SIGHUP reloads the config between flights (RELOADING=1 at once, READY=1 when done:
Type=notify-reload). The control socket is bound here, or taken from systemd's socket
activation (perchd.service.activation).

With [service] realtime the whole process (the flight thread, the links' threads) runs
under SCHED_FIFO from start-up (core/realtime.py); refused, one line says what is missing
and every fly request is refused with it, while the service stays up. The garbage collector
is off during a flight (flight/loop.py); between flights the service collects and freezes
what survives (settle_heap).
"""

from __future__ import annotations

import dataclasses
import os
import select
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

from perchd.core import realtime
from perchd.core.clock import MonotonicClock
from perchd.core.errors import ConfigError, LinkError, PerchdError, PlanError
from perchd.core.interrupts import exit_code
from perchd.core.ports import Driver, PoseSource
from perchd.core.runtime import Runtime
from perchd.core.safefile import confine, kind, read_regular
from perchd.core.types import EndReason
from perchd.flight.config import SurfaceConfig
from perchd.flight.planguard import check_flight_plan
from perchd.flight.run import FlightAbort, fly
from perchd.flight.vehiclestate import VehicleStore, profile_path
from perchd.service.activation import activated_socket
from perchd.service.config import (
    VERSION,
    Config,
    ServiceConfig,
    config_from_dict,
    load_config,
)
from perchd.service.control_socket import ControlServer
from perchd.service.idle_feed import IdleFeed
from perchd.service.sdnotify import Notifier
from perchd.session import Session, open_links
from perchd.tau import load_plan
from perchd.tau.plan import Plan

FLIGHT_DONE = b"\xff"
"""Self-pipe byte the flight thread writes when it ends (signal numbers are < 65)."""
IDLE_POLL_S = 0.25
"""[s] the service loop wakes at least this often to ping the watchdog while idle."""
STOP_JOIN_S = 5.0
"""[s] longest wait for an aborted flight to close its log before the failsafe is forced."""


def say(msg: str) -> None:
    """One line for the journal."""
    print(f"perchd serve: {msg}", file=sys.stderr, flush=True)


class Links:
    """The service's connected driver and pose source. Simulated links (sim:// on both) fly
    a fresh simulated world per flight, paced in real time; real ones keep feeding the
    driver the mocap between flights (service/idle_feed.py)."""

    def __init__(
        self,
        service: ServiceConfig,
        surface: SurfaceConfig | None = None,
        mass_kg: float | None = None,
    ) -> None:
        self.surface = surface  # where a simulated world puts its wall
        self.mass_kg = mass_kg  # the flight config's, bound before the driver connects
        self.driver_uri, self.mocap_uri = service.driver, service.mocap_uri()
        self.session: Session | None = self._open()
        self.simulated = self.session.world is not None
        self.feed = None if self.simulated else IdleFeed(self.source, self.driver)
        self.resume_feed()

    def pause_feed(self) -> None:
        """Someone else feeds the driver from here on: a flight's loop, or new links."""
        if self.feed is not None:
            self.feed.pause()

    def resume_feed(self) -> None:
        if self.feed is not None:
            self.feed.resume()

    def _open(self) -> Session:
        return open_links(
            self.driver_uri, self.mocap_uri, self.surface, MonotonicClock(), self.mass_kg
        )

    @property
    def driver(self) -> Driver:
        return self.session.driver

    @property
    def source(self) -> PoseSource:
        return self.session.source

    @property
    def runtime(self) -> Runtime:
        return self.session.runtime

    def fresh(self) -> None:
        """Before a flight: a new simulated world (a real link is kept)."""
        if self.simulated:
            self.close()
            self.session = self._open()

    def healthy(self) -> bool:
        try:
            return bool(self.driver.health().ok)
        except Exception:  # noqa: BLE001 - a link that cannot say is not healthy
            return False

    def close(self, hand_over: bool = True) -> None:
        """hand_over: Driver.close's (False when new links to the same vehicle feed it)."""
        if self.feed is not None:  # before the driver's close: it hands over to its sentinel
            self.feed.close()
        session, self.session = self.session, None
        if session is not None:
            session.close(hand_over)


class FlightJob(threading.Thread):
    """One flight in its own thread; wakes the service loop through the pipe when done."""

    def __init__(
        self,
        plan: Plan,
        plan_path: Path,
        links: Links,
        cfg: Config,
        log: Path,
        notifier: Notifier,
        wake_fd: int,
    ) -> None:
        super().__init__(name="perchd-flight", daemon=True)

        self.plan, self.plan_path, self.links, self.cfg = plan, plan_path, links, cfg
        self.log, self.notifier, self.wake_fd = log, notifier, wake_fd
        self.abort = FlightAbort()
        self.tick: Any = None
        self.result: dict[str, Any] | None = None
        self._phase = None

    def run(self) -> None:
        svc = self.cfg.service
        key = f"{svc.vehicle} {svc.driver}"  # the vehicle and the calibration it flies with
        directory = Path(svc.state_dir or svc.log_dir) / "vehicles"
        store = VehicleStore(profile_path(key, directory), key, say)
        try:
            flight, visit = store.with_learned_guess(self.cfg.flight)
            self.links.pause_feed()
            res = fly(
                self.plan,
                self.links.driver,
                self.links.source,
                self.links.runtime.clock,
                self.log,
                flight,
                self.abort,
                self.on_tick,
                world=self.links.session.world,
                header={
                    "plan_file": str(self.plan_path),
                    "vehicle": self.cfg.service.vehicle,
                    "mocap": self.links.mocap_uri,
                    "service": True,
                    "uri_params": self.links.session.applied,
                },
            )
            self.result = res.to_json()
            say(store.remember_flight(flight, res, visit).describe())
        except BaseException as err:  # fly has already sent the failsafe and closed the log
            why = EndReason.LOST_LINK if isinstance(err, LinkError) else EndReason.SOFTWARE_ERROR
            self.result = {
                "outcome": why.name,
                "log": str(self.log),
                "detail": f"{type(err).__name__}: {err}",
            }
        finally:
            self.links.resume_feed()  # at once: a failsafe's LAND may be descending
            os.write(self.wake_fd, FLIGHT_DONE)

    def on_tick(self, st: Any) -> None:
        """Called by the control loop after each tick: proof of life for the watchdog."""
        self.tick = st
        self.notifier.watchdog()
        if st.phase is not self._phase:
            self._phase = st.phase
            self.notifier.status(f"{self.cfg.service.vehicle}: flying, {st.phase.value}")


class Daemon:
    def __init__(
        self, config: Config, notifier: Notifier, config_path: str | None, overrides: dict[str, str]
    ) -> None:
        self.config, self.notifier = config, notifier
        self.config_path, self.overrides = config_path, overrides
        self.job: FlightJob | None = None
        self.last: dict[str, Any] | None = None
        self.flights = 0
        self.reload_pending = False
        self.stopping = False
        self.stop_signal: int | None = None
        self.links: Links | None = None
        self.server: ControlServer | None = None
        self.wake_fd = -1  # the self-pipe's write end, open while run() runs
        self.realtime_refused = ""  # why [service] realtime was not granted

    # --- the service loop ---------------------------------------------------------------------
    def run(self) -> int:
        rfd, wfd = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        self.wake_fd = wfd
        previous = {
            s: signal.signal(s, lambda *_: None)
            for s in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP, signal.SIGUSR1)
        }
        old_wakeup = signal.set_wakeup_fd(wfd, warn_on_full_buffer=False)
        try:
            self._start()
            while not self.stopping:
                self._wait(rfd)
        finally:
            self.notifier.stopping()
            self.notifier.status("stopping")
            self._shutdown()
            signal.set_wakeup_fd(old_wakeup)
            for s, h in previous.items():
                signal.signal(s, h)
            os.close(rfd)
            os.close(wfd)
        say("stopped")
        return stop_exit_code(self.stop_signal)

    def _start(self) -> None:
        svc = self.config.service
        check_dirs(svc)  # before READY=1: a service that cannot log a flight is not ready
        self.server = ControlServer(
            svc.socket,
            self.dispatch,
            peers=svc.peer_policy(),
            on_refuse=lambda why: say(f"control socket: refused {why}"),
            listening=activated_socket(),
        )
        if self.server.activated and str(self.server.path) != svc.socket:
            say(f"control socket {self.server.path} from systemd (not {svc.socket})")
        self._realtime(svc.realtime)  # before the links start their threads: they inherit it
        self.notifier.status(f"{svc.vehicle}: connecting {svc.mocap_uri()} and {svc.driver}")
        self.links = Links(svc, self.config.flight.surface, self.config.flight.vehicle.mass_kg)
        realtime.settle_heap()
        self.notifier.ready(f"{svc.vehicle}: idle")
        say(
            f"ready: vehicle {svc.vehicle}, driver {svc.driver}, mocap {svc.mocap_uri()}, "
            f"socket {self.server.path}" + (" (from systemd)" if self.server.activated else "")
        )

    def _realtime(self, cfg: realtime.RealtimeConfig) -> None:
        try:
            realtime.apply(cfg)
        except realtime.RealtimeRefused as err:
            self.realtime_refused = f"[service] realtime refused: {err}"
            say(f"{self.realtime_refused}; flights are refused until it is granted (restart)")
            return
        if cfg.enabled:
            say(f"scheduling: {cfg.describe()}")

    def _wait(self, rfd: int) -> None:
        readable, _, _ = select.select([rfd, *self.server.fds()], [], [], IDLE_POLL_S)
        for fd in readable:
            if fd == rfd:
                self._wakeups(os.read(rfd, 256))
            elif fd in self.server.fds():
                self.server.handle(fd)
        self.server.expire()
        self._reap()
        if self.job is None and self.links.healthy():
            self.notifier.watchdog()

    def _wakeups(self, data: bytes) -> None:
        for byte in data:
            if byte in (signal.SIGTERM, signal.SIGINT):
                say(f"{signal.Signals(byte).name}: stopping")
                self.stopping = True
                self.stop_signal = self.stop_signal or byte
                if self.job is not None:
                    self.job.abort.request(EndReason.SIGNAL)
            elif byte == signal.SIGHUP:
                self._reload_requested()
            elif byte == signal.SIGUSR1:
                self._abort_signalled()
        if self.reload_pending and self.job is None:
            self.reload()

    def _abort_signalled(self) -> None:
        """SIGUSR1 is abort: the way in that no number of connections can block."""
        try:
            reply = self.cmd_abort({})
        except Exception as err:  # noqa: BLE001 - the service loop must survive a failed failsafe
            say(f"SIGUSR1: abort failed: {type(err).__name__}: {err}")
            return
        say(f"SIGUSR1: abort ({'flight aborting' if reply.get('flying') else 'failsafe sent'})")

    def _reap(self) -> None:
        if self.job is None or self.job.is_alive():
            return
        self.job.join()
        self.last = self.job.result
        say(f"flight ended: {self.last.get('outcome')}; log {self.last.get('log')}")
        self.job = None
        realtime.settle_heap()  # the collections the flight went without
        self.notifier.status(
            f"{self.config.service.vehicle}: idle, last flight {self.last.get('outcome')}"
        )
        if self.reload_pending:
            self.reload()

    def _shutdown(self) -> None:
        job = self.job
        if job is not None:
            job.abort.request(EndReason.SIGNAL)
            job.join(STOP_JOIN_S)
            if job.is_alive():  # the loop is stuck: make the vehicle safe from here
                say("flight did not end in time; sending the failsafe directly")
                self.links.driver.failsafe(EndReason.SIGNAL)
            self._reap()
        if self.links is not None:
            self.links.close()
        if self.server is not None:
            self.server.close()

    # --- configuration ------------------------------------------------------------------------
    def _reload_requested(self) -> None:
        """SIGHUP: RELOADING=1 at once (systemd waits for it); the reload itself runs now, or
        once the flight ends: a flight flies the config it started with (systemd/README.md)."""
        if self.reload_pending:
            return  # one reload covers every SIGHUP before it
        self.reload_pending = True
        deferred = self.job is not None
        self.notifier.reloading(
            f"{self.config.service.vehicle}: "
            + ("flying, reload after the flight" if deferred else "reloading")
        )
        if deferred:
            say("SIGHUP: reload deferred until the flight ends")

    def reload(self) -> None:
        """Reload the config, then READY=1 whatever came of it: systemd's reload is over, and
        the service runs on (a refused config leaves the old one, said in STATUS and a line)."""
        self.reload_pending = False
        status = self._reload()
        self.notifier.ready(status)

    def _reload(self) -> str:
        """The reload proper; the STATUS text it leaves."""
        idle = f"{self.config.service.vehicle}: idle"
        if not self.config_path:
            say("SIGHUP: no --config to reload")
            return f"{idle}, no --config to reload"
        try:
            new = apply_overrides(load_config(self.config_path), self.overrides)
            check_dirs(new.service)
            peers = new.service.peer_policy()
            new = self._restart_only(new, "socket")
            new = self._restart_only(new, "realtime")
            moved = self.links.simulated and new.flight.surface != self.links.surface
            if moved or (new.service.driver, new.service.mocap_uri()) != (
                self.links.driver_uri,
                self.links.mocap_uri,
            ):
                self.links = self._replace_links(new)
        except PerchdError as err:
            say(f"SIGHUP: config not reloaded, keeping the old one: {err}")
            return f"{idle}, reload failed: {err}"
        self.config = new
        self.server.peers = peers
        say(f"SIGHUP: reloaded {self.config_path}")
        return f"{new.service.vehicle}: idle, config reloaded"

    def _replace_links(self, new: Config) -> Links:
        """New links connected before the old close, the old feed paused meanwhile (a
        refusal keeps the old ones, feeding again). The same vehicle's landing is not
        handed to the old driver's sentinel: the new feed has it (docs/safety.md, "Between
        flights")."""
        self.links.pause_feed()
        try:
            links = Links(new.service, new.flight.surface, new.flight.vehicle.mass_kg)
        except BaseException:
            self.links.resume_feed()
            raise
        self.links.close(hand_over=links.driver_uri != self.links.driver_uri)
        return links

    def _restart_only(self, new: Config, key: str) -> Config:
        """`new` with [service] `key` kept as it is: it changes only on restart."""
        old = getattr(self.config.service, key)
        if getattr(new.service, key) == old:
            return new
        say(f"SIGHUP: [service] {key} changes only on restart; keeping {old}")
        return dataclasses.replace(new, service=dataclasses.replace(new.service, **{key: old}))

    # --- the control socket (docs/contracts.md §4) -----------------------------------------------------
    def dispatch(self, req: dict[str, Any]) -> dict[str, Any]:
        handler = {"fly": self.cmd_fly, "abort": self.cmd_abort, "status": self.cmd_status}.get(
            req["cmd"]
        )
        if handler is None:
            return {"ok": False, "error": f"unknown cmd {req['cmd']!r} (fly, abort, status)"}
        return handler(req)

    def cmd_fly(self, req: dict[str, Any]) -> dict[str, Any]:
        if self.stopping:
            return {"ok": False, "error": "the service is stopping"}
        if self.job is not None:
            return {"ok": False, "error": "a flight is in progress; abort it or wait"}
        if self.realtime_refused:
            return {"ok": False, "error": self.realtime_refused}
        if not isinstance(req.get("plan"), str) or not req["plan"]:
            return {"ok": False, "error": 'fly needs "plan": a plan file path'}
        try:
            plan, path = self._read_plan(req["plan"])
            check_flight_plan(plan, self.config.flight)  # before the flight engages
        except PlanError as err:  # `perchd ctl fly` exits 2 on it, as `perchd fly` does
            return {"ok": False, "error": str(err), "refused": "plan"}
        except PerchdError as err:
            return {"ok": False, "error": str(err)}
        if not self.links.healthy():
            return {"ok": False, "error": "the link to the vehicle is down"}
        self.links.fresh()
        log = self._log_path(plan)
        self.job = FlightJob(plan, path, self.links, self.config, log, self.notifier, self.wake_fd)
        self.flights += 1
        self.notifier.status(f"{self.config.service.vehicle}: flying {path.name}")
        self.job.start()
        say(f"flying {path}; log {log}")
        return {"ok": True, "flying": True, "plan": str(path), "log": str(log)}

    def _read_plan(self, name: str) -> tuple[Any, Path]:
        """The plan a request names: inside plan_dir once symlinks are resolved, a regular
        file of bounded size (perchd.core.safefile); PlanError naming the refusal."""

        if "\0" in name:
            raise PlanError("plan: a path with a NUL byte")
        path = confine(name, self.config.service.plan_dir, "plan", PlanError)
        return load_plan(path, read_regular(path, "plan", PlanError)), path

    def cmd_abort(self, req: dict[str, Any]) -> dict[str, Any]:
        if self.job is not None:
            self.job.abort.request(EndReason.OPERATOR_ABORT)
            return {"ok": True, "flying": True, "aborting": True, "log": str(self.job.log)}
        # idle: make sure it is safe (a vehicle no flight has engaged is left alone)
        self.links.driver.failsafe(EndReason.OPERATOR_ABORT)
        return {"ok": True, "flying": False, "failsafe_sent": True}

    def cmd_status(self, req: dict[str, Any]) -> dict[str, Any]:
        svc, job = self.config.service, self.job
        out: dict[str, Any] = {
            "ok": True,
            "vehicle": svc.vehicle,
            "state": "flying" if job else "idle",
            "driver": self.links.driver_uri,
            "mocap": self.links.mocap_uri,
            "link_ok": self.links.healthy(),
            "flights": self.flights,
            "config": self.config_path,
            "last": self.last,
            "scheduling": self.realtime_refused or svc.realtime.describe(),
        }
        if job is not None:
            st = job.tick
            out.update(
                log=str(job.log),
                plan=str(job.plan_path),
                phase=st.phase.value if st else "starting",
                t=st and st.t,
                x=st and st.x,
                xdot=st and st.xdot,
                tau=st and st.tau,
                tau_ref=st and st.tau_ref,
            )
        return out

    def _log_path(self, plan: Plan) -> Path:
        stem = f"{time.strftime('%Y%m%d-%H%M%S')}-{self.config.service.vehicle}-{plan.strategy}"
        base = Path(self.config.service.log_dir)
        path, n = base / f"{stem}.jsonl", 1
        while path.exists():
            n += 1
            path = base / f"{stem}-{n}.jsonl"
        return path


def stop_exit_code(signum: int | None) -> int:
    """0 for SIGTERM, a service's normal stop (systemd counts a non-zero exit as a failure
    unless the unit says otherwise); 130 for SIGINT, as any command (docs/contracts.md §6)."""
    return 0 if signum in (None, signal.SIGTERM) else exit_code(signum)


def apply_overrides(
    config: Config, overrides: dict[str, str], environ: dict[str, str] | None = None
) -> Config:
    """Command-line --socket/--driver/--mocap/--log-dir/--plan-dir win over the file; a
    log_dir/plan_dir left at its default follows the unit's LogsDirectory=/StateDirectory=
    (systemd's $LOGS_DIRECTORY, $STATE_DIRECTORY), so perchd@NAME logs to /var/log/perchd/NAME,
    the one log directory its sandbox lets it write."""
    given = {k: v for k, v in overrides.items() if v}
    env = os.environ if environ is None else environ
    defaults = ServiceConfig()
    svc = config.service
    if svc.log_dir == defaults.log_dir and env.get("LOGS_DIRECTORY"):
        given.setdefault("log_dir", env["LOGS_DIRECTORY"].split(":")[0])
    if svc.plan_dir == defaults.plan_dir and env.get("STATE_DIRECTORY"):
        given.setdefault("plan_dir", str(Path(env["STATE_DIRECTORY"].split(":")[0]) / "plans"))
    return dataclasses.replace(config, service=dataclasses.replace(svc, **given))


def check_dirs(svc: ServiceConfig) -> None:
    """plan_dir and log_dir exist (made if missing: they are configured) and are usable:
    plan_dir readable, log_dir writable; else one ConfigError naming the key."""
    for key, need, what in (
        ("plan_dir", os.R_OK | os.X_OK, "readable"),
        ("log_dir", os.W_OK | os.X_OK, "writable"),
    ):
        path = Path(getattr(svc, key))
        try:
            path.mkdir(parents=True, exist_ok=True)
        except FileExistsError:
            raise ConfigError(
                f"[service] {key} = {str(path)!r}: not a directory ({kind(path.stat().st_mode)})"
            ) from None
        except OSError as err:
            raise ConfigError(
                f"[service] {key} = {str(path)!r}: cannot create it "
                f"({err.strerror}); create it or set {key}"
            ) from None
        if not os.access(path, need):
            raise ConfigError(
                f"[service] {key} = {str(path)!r}: not {what} by uid "
                f"{os.geteuid()}; fix its permissions or set {key}"
            )


def serve(config_path: str | None, overrides: dict[str, str]) -> int:

    config = load_config(config_path) if config_path else config_from_dict({"version": VERSION})
    config = apply_overrides(config, overrides)
    notifier = Notifier()
    try:
        return Daemon(config, notifier, config_path, overrides).run()
    finally:
        notifier.close()
