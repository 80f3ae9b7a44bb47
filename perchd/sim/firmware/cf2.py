"""The Crazyflie's SITL firmware (cf2) flown against our physics, in real time.

cf2 is a UDP *client*: it sends a 0xF3 hello to `cf2 PORT ADDRESS` from an ephemeral port
and then runs its stabilizer one step per sensor packet (src/hal/src/sensors_sitl.c), on
the wall clock. So this module binds PORT first, answers the hello, and from then on runs
one thread that every millisecond of real time:
  - drains cf2's datagrams (motor PWM; the "calibrated" packet; CRTP for cflib, relayed),
  - forwards at most 2 of cflib's packets (cf2's link queue holds 5 and drops the rest),
  - steps the quadrotor (perchd.sim.firmware.quadrotor) with the latest PWM,
  - sends the IMU sample (1 kHz: it is the firmware's stabilizer clock), the external pose
    (ext_pose_hz, what the on-board Kalman filter fuses) and the barometer (baro_hz).
Protocol details: perchd.sim.firmware.cf2wire; timing and start-up: docs/firmware.md.

Start-up: cf2 finds its gyro bias from 1024 still IMU samples after 1 s of uptime, tells
us with the packet 90 01, then averages the accelerometer for another second; only then
is it ready. Some launches stall before the bias is found (docs/firmware.md, "start-up
hang"): no 90 01 within calibration_timeout_s means kill that cf2 and launch another.
"""

from __future__ import annotations

import math
import random
import socket
import threading
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from perchd.core.clock import Clock, MonotonicClock
from perchd.core.errors import LinkError, UriError
from perchd.core.types import Vec3
from perchd.sim.firmware import cf2wire as wire
from perchd.sim.firmware.harness import (
    FirmwareVehicle,
    Interrupted,
    ProcessGroup,
    Truth,
    contact_json,
    default_log,
    line_buffered,
    wait_or_cancel,
)
from perchd.sim.firmware.quadrotor import QuadModel, Quadrotor
from perchd.sim.firmware.relay import ClientRelay
from perchd.sim.world import Contact

STEP_S = 0.001
TRACK_EVERY = 10
"""steps between samples of the summary's truth track (100 Hz)."""
TRACK_MAX = 12000
"""samples kept (the last 2 minutes): [monotonic s, true z m, any motor PWM > 0]."""
"""[s] physics step and IMU period: the firmware's controllers count IMU packets as ms."""
CLIENT_PER_STEP = 2
"""cflib packets forwarded per step: with the IMU, pose and baro that is at most 5 per ms,
the depth of cf2's link queue."""
LATE_SKIP_S = 0.02
"""[s] a step this late still integrates but sends no IMU: a burst of stale samples would
overflow cf2's queue and run its controllers on old data."""
RESYNC_S = 1.0
"""[s] behind by more than this (the process was stopped): restart the schedule from now."""


@dataclass(frozen=True, slots=True)
class SensorNoise:
    """Gaussian std per axis per sample: gyro_rad_s [rad/s], acc_mps2 [m/s^2],
    baro_mbar [mbar]. Zero (the default) is a noiseless sensor, as CrazySim's IMU is."""

    gyro_rad_s: float = 0.0
    acc_mps2: float = 0.0
    baro_mbar: float = 0.0


@dataclass(frozen=True, slots=True)
class Surface:
    """A plane the vehicle perches on: point [m] on it, normal (the approach direction)."""

    point: Vec3 = (0.0, 0.0, 0.0)
    normal: Vec3 = (1.0, 0.0, 0.0)

    def gap(self, p: Vec3 | list[float]) -> float:
        """[m] signed distance along the normal, < 0 before the surface."""
        n = math.sqrt(sum(c * c for c in self.normal))
        return sum((p[i] - self.point[i]) * self.normal[i] for i in range(3)) / n

    def speed(self, v: Vec3 | list[float]) -> float:
        n = math.sqrt(sum(c * c for c in self.normal))
        return sum(v[i] * self.normal[i] for i in range(3)) / n


@dataclass(frozen=True, slots=True)
class Cf2Params:
    """binary: path of the cf2 executable; fw_port: UDP port cf2 sends to (0: a free one;
    CrazySim uses 19950); link: where cflib's udp:// connects (CrazySim: 19850);
    start [m] on the floor when z = 0; yaw [rad]; ext_pose_hz, baro_hz [Hz];
    handshake_timeout_s, calibration_timeout_s [s] per launch; settle_s [s] after the
    bias for the accelerometer scale; launches: attempts before giving up;
    surface: perched on touching it (None: no surface); log: cf2's stdout."""

    binary: str
    fw_port: int = 0
    link: str = "udp://127.0.0.1:19850"
    start: Vec3 = (-4.5, 0.0, 0.0)
    yaw: float = 0.0
    model: QuadModel = QuadModel()
    noise: SensorNoise = SensorNoise()
    ext_pose_hz: float = 100.0
    baro_hz: float = 50.0
    handshake_timeout_s: float = 5.0
    calibration_timeout_s: float = 3.0
    settle_s: float = 1.2
    launches: int = 5
    surface: Surface | None = Surface()
    log: Path | None = None
    seed: int = 0


@dataclass
class LoopStats:
    """What the sim thread measured (real time, monotonic)."""

    steps: int = 0
    imu_sent: int = 0
    imu_first_t: float | None = None
    imu_last_t: float | None = None
    late_max_s: float = 0.0
    late_over_1ms: int = 0
    late_skipped: int = 0
    resyncs: int = 0
    motor_packets: int = 0
    to_firmware: int = 0
    extposes: int = 0
    handshakes: int = 0
    step_cpu_max_s: float = 0.0
    step_cpu_sum_s: float = 0.0

    def imu_rate_hz(self) -> float | None:
        if self.imu_first_t is None or self.imu_last_t is None or self.imu_sent < 2:
            return None
        span = self.imu_last_t - self.imu_first_t
        return (self.imu_sent - 1) / span if span > 0 else None


@dataclass
class _Launch:
    """One cf2 process and what it said."""

    proc: Any = None
    addr: tuple[str, int] | None = None
    handshake: threading.Event = field(default_factory=threading.Event)
    calibrated: threading.Event = field(default_factory=threading.Event)
    calibrated_t: float | None = None
    imu_from_t: float | None = None


class Cf2Vehicle(FirmwareVehicle):
    name = "cf2"

    def __init__(self, params: Cf2Params, clock: Clock | None = None) -> None:
        if params.surface is not None and params.surface.gap(params.start) >= 0.0:
            raise UriError(
                f"start {params.start} is on or past the surface (point "
                f"{params.surface.point}, normal {params.surface.normal})"
            )
        self.params = params
        self.clock = clock or MonotonicClock()
        self.log = params.log or default_log("cf2")
        self.body = Quadrotor(params.model, params.start, params.yaw)
        self.stats = LoopStats()
        self.launches: list[dict[str, Any]] = []
        self._rng = random.Random(params.seed)
        self._pwm = [0, 0, 0, 0]
        self._track: deque[tuple[float, float, bool]] = deque(maxlen=TRACK_MAX)
        self._launch = _Launch()
        self._contact: Contact | None = None
        self._truth: Truth | None = None
        self._t0 = self.clock.now()
        self.fw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.fw.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            self.fw.bind(("127.0.0.1", params.fw_port))
        except OSError as err:
            self.fw.close()
            raise LinkError(f"cannot bind the firmware port {params.fw_port}: {err}") from None
        self.fw.setblocking(False)
        self.fw_port = self.fw.getsockname()[1]
        try:
            self.relay = ClientRelay(params.link)
        except BaseException:
            self.fw.close()
            raise
        self._halt = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="cf2-physics", daemon=True)
        self._thread.start()

    # -- FirmwareVehicle ----------------------------------------------------------------
    def start(self, procs: ProcessGroup, cancel: threading.Event) -> None:
        p = self.params
        argv = line_buffered([p.binary, str(self.fw_port), "127.0.0.1"])
        for _ in range(p.launches):
            launch = _Launch()
            self._pwm = [0, 0, 0, 0]
            self._launch = launch  # the sim thread now answers this process's hello
            launch.proc = procs.launch(argv, self.log)
            t_launch = self.clock.now()
            record = {"pid": launch.proc.pid, "outcome": "ready"}
            self.launches.append(record)
            try:
                if not wait_or_cancel(launch.handshake, p.handshake_timeout_s, cancel):
                    record["outcome"] = (
                        "exited" if launch.proc.poll() is not None else "no handshake"
                    )
                elif not wait_or_cancel(launch.calibrated, p.calibration_timeout_s, cancel):
                    record["outcome"] = "calibration stalled"  # the start-up hang
                else:
                    record["calibrated_after_s"] = launch.calibrated_t - t_launch
                    if not wait_or_cancel(threading.Event(), p.settle_s, cancel):
                        if launch.proc.poll() is None:
                            return
                        record["outcome"] = "exited"
            except Interrupted:
                record["outcome"] = "interrupted"
                procs.stop(launch.proc)
                raise
            procs.stop(launch.proc)
        raise LinkError(
            f"cf2 ({p.binary}) was not ready after {p.launches} launches "
            f"({', '.join(r['outcome'] for r in self.launches)}); its log: {self.log}"
        )

    def truth(self) -> Truth | None:
        return self._truth

    def driver_uri(self) -> str:
        """cflib's udp:// URI, with the hover thrust of this model for the driver's default
        mass (the flight config's): docs/firmware.md, "thrust"."""
        return f"{self.relay.uri}?hover={round(self.params.model.hover_pwm, -1):.0f}"

    def contact(self) -> Contact | None:
        return self._contact

    def summary(self) -> dict[str, Any]:
        s = self.stats
        truth = self._truth
        return {
            "firmware": "cf2",
            "binary": self.params.binary,
            "log": str(self.log),
            "launches": self.launches,
            "imu": {
                "sent": s.imu_sent,
                "rate_hz": s.imu_rate_hz(),
                "late_max_ms": 1e3 * s.late_max_s,
                "late_over_1ms": s.late_over_1ms,
                "skipped_late": s.late_skipped,
                "resyncs": s.resyncs,
                "step_cpu_mean_us": 1e6 * s.step_cpu_sum_s / max(s.steps, 1),
                "step_cpu_max_us": 1e6 * s.step_cpu_max_s,
            },
            "motor_packets": s.motor_packets,
            "ext_poses": s.extposes,
            "to_firmware": s.to_firmware,
            "handshakes": s.handshakes,
            "client": vars(self.relay.counts).copy(),
            "contact": contact_json(self._contact, self._t0),
            "final": None if truth is None else {"p": list(truth.p), "v": list(truth.v)},
            "track": [list(x) for x in list(self._track)],  # [t monotonic s, z m, motors on]
        }

    def close(self) -> None:
        self._halt.set()
        self._thread.join(timeout=2.0)
        self.relay.close()
        self.fw.close()

    # -- the sim thread -----------------------------------------------------------------
    def _loop(self) -> None:
        p, clock, s = self.params, self.clock, self.stats
        pose_every = max(1, round(1.0 / (p.ext_pose_hz * STEP_S)))
        baro_every = max(1, round(1.0 / (p.baro_hz * STEP_S)))
        due, k = clock.now(), 0
        while not self._halt.is_set():
            now = clock.now()
            if now < due:
                clock.sleep_until(due)
                continue
            late = now - due
            if late > RESYNC_S:
                s.resyncs += 1
                due, late = now, 0.0
            self._step(k, due, late, pose_every, baro_every)
            s.step_cpu_sum_s += (spent := clock.now() - now)
            s.step_cpu_max_s = max(s.step_cpu_max_s, spent)
            k += 1
            due += STEP_S

    def _step(self, k: int, t: float, late: float, pose_every: int, baro_every: int) -> None:
        s, body = self.stats, self.body
        self._drain_firmware(t)
        launch = self._launch
        for data in self.relay.poll(CLIENT_PER_STEP):
            self._to_fw(launch, data)
        body.step(STEP_S, self._pwm)
        if self._contact is None and self.params.surface is not None and not body.grounded:
            self._check_surface(t)
        self._truth = Truth(t, tuple(body.p), tuple(body.v), tuple(body.q), body.gyro())  # type: ignore[arg-type]
        if k % TRACK_EVERY == 0:
            self._track.append((round(t, 4), round(body.p[2], 4), any(self._pwm)))
        s.steps += 1
        s.late_max_s = max(s.late_max_s, late)
        s.late_over_1ms += late > 0.001
        if launch.addr is None:
            return
        if late > LATE_SKIP_S:
            s.late_skipped += 1
            return
        self._send_sensors(launch, k, t, pose_every, baro_every)

    def _send_sensors(
        self, launch: _Launch, k: int, t: float, pose_every: int, baro_every: int
    ) -> None:
        s, body, n = self.stats, self.body, self.params.noise
        acc, gyro = body.specific_force(), body.gyro()
        if n.acc_mps2 > 0:
            acc = tuple(c + self._rng.gauss(0.0, n.acc_mps2) for c in acc)
        if n.gyro_rad_s > 0:
            gyro = tuple(c + self._rng.gauss(0.0, n.gyro_rad_s) for c in gyro)
        self._to_fw(launch, wire.imu_packet(acc, gyro))  # type: ignore[arg-type]
        s.imu_sent += 1
        if s.imu_first_t is None:
            s.imu_first_t = t
        s.imu_last_t = t
        if launch.imu_from_t is None:
            launch.imu_from_t = t
        if k % pose_every == 0:  # the mocap the vehicle itself gets (exact: see docs)
            self._to_fw(launch, wire.extpose_packet(tuple(body.p), tuple(body.q)))  # type: ignore[arg-type]
            s.extposes += 1
        if k % baro_every == baro_every // 2:  # off the pose's steps: one less packet per ms
            mbar = wire.pressure_mbar(body.p[2])
            if n.baro_mbar > 0:
                mbar += self._rng.gauss(0.0, n.baro_mbar)
            self._to_fw(launch, wire.baro_packet(mbar, 25.0, body.p[2]))

    def _to_fw(self, launch: _Launch, data: bytes) -> None:
        if launch.addr is None:
            return  # no firmware yet: cflib's early packets are dropped, as a radio's would be
        try:
            self.fw.sendto(data, launch.addr)
            self.stats.to_firmware += 1
        except OSError:
            pass  # cf2 gone (killed for a relaunch); the next hello brings an address

    def _drain_firmware(self, t: float) -> None:
        launch = self._launch
        while True:
            try:
                data, addr = self.fw.recvfrom(256)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue  # ICMP from a cf2 that died
            kind = wire.classify(data)
            if kind is wire.Kind.MOTORS:
                if addr == launch.addr:
                    self._pwm = list(wire.decode_motors(data))
                    self.stats.motor_packets += 1
            elif kind is wire.Kind.HANDSHAKE:
                # a hello (again): this process is the firmware now; answer exactly F3
                self.fw.sendto(wire.HANDSHAKE, addr)
                launch.addr = addr
                self.stats.handshakes += 1
                launch.handshake.set()
            elif kind is wire.Kind.CALIBRATED:
                if addr == launch.addr and not launch.calibrated.is_set():
                    launch.calibrated_t = t
                    launch.calibrated.set()
            elif addr == launch.addr:
                self.relay.send(data)

    def _check_surface(self, t: float) -> None:
        surface, body = self.params.surface, self.body
        assert surface is not None
        if surface.gap(body.p) >= 0.0:
            speed = surface.speed(body.v)
            self._contact = Contact(t, speed, tuple(body.p))  # type: ignore[arg-type]
            body.perch()
