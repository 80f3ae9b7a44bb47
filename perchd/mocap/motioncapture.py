"""`motioncapture://` pose sources: any mocap system libmotioncapture speaks.

    motioncapture://TYPE?body=NAME[&hostname=HOST][&up=y|z][&max_age=0.5][&timeout=5]
        [&OPTION=VALUE ...]

TYPE is a libmotioncapture backend the installed library was built with (optitrack, vicon,
qualisys, vrpn, mock, ...; perchd.mocap.mcbackends); its own options (hostname, interface_ip,
port_command, port, ...) pass through. `up=` is the axis the system streams as up (OptiTrack:
y, the others: z, by default). The library runs in a process of its own (perchd.mocap.mcworker
says why): `timeout=` bounds its connect, and close() ends it at once, even mid-receive.

Each pose is stamped when the library hands its frame over: the binding gives no camera or
network latency, so a pose's latency is only its way from that process to this one, and
max_age drops poses that waited longer in between. A frame without the body (untracked, or
no such rigid body) is counted as a drop.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from dataclasses import dataclass, field

from perchd.core import childproc
from perchd.core.clock import Clock
from perchd.core.errors import LinkError, UriError
from perchd.core.extras import require
from perchd.core.runtime import Runtime
from perchd.core.types import Pose
from perchd.core.uri import Uri
from perchd.core.uriparams import float_param
from perchd.mocap import mcbackends, mcworker
from perchd.mocap.frames import UpAxis, to_world
from perchd.mocap.stream import Drop, PoseLimits, PoseStream, RateLimitedWarning, ThreadedSource

log = logging.getLogger("perchd.mocap.motioncapture")

OWN_PARAMS = ("body", "up", "max_age", "timeout")
CLOSE_WAIT_S = 0.3  # [s] a killed worker is reaped within this, else left to the OS


@dataclass(frozen=True)
class MotionCaptureConfig:
    """Which backend to start and which body to follow.

    kind: libmotioncapture's TYPE (optitrack, vicon, ...).
    options: the backend's own configuration, passed to motioncapture.connect as is.
    up: the axis the system streams as up (perchd's world is Z up).
    connect_timeout_s: [s] the library's connect must answer within this.
    """

    kind: str
    body: str
    options: tuple[tuple[str, str], ...] = ()
    up: UpAxis = UpAxis.Z
    connect_timeout_s: float = 5.0
    limits: PoseLimits = field(default_factory=PoseLimits)

    @property
    def name(self) -> str:
        host = dict(self.options).get("hostname")
        return f"motioncapture {self.kind}" + (f" {host}" if host else "")


def open_motioncapture(uri: Uri, runtime: Runtime) -> MotionCaptureSource:
    """Registry factory for `motioncapture://` (not started yet)."""
    return MotionCaptureSource(config_from_uri(uri), runtime.clock)


def config_from_uri(uri: Uri) -> MotionCaptureConfig:
    require("motioncapture", "motioncapture")
    backend = _backend(uri)
    options = {k: v for k, v in uri.query.items() if k not in OWN_PARAMS}
    _check_options(uri, backend, options)
    body = uri.param("body") or ""
    if not body:
        raise UriError(f"{uri.raw}: body=NAME (the rigid body's name) is required")
    return MotionCaptureConfig(
        backend.kind,
        body,
        tuple(sorted(options.items())),
        UpAxis.parse(uri.param("up", backend.up) or backend.up, uri.raw),
        float_param(uri, "timeout", 5.0, 0.05, 60.0, " s"),
        PoseLimits(max_age_s=float_param(uri, "max_age", 0.5, 0.001, 10.0, " s")),
    )


def _backend(uri: Uri) -> mcbackends.Backend:
    built = mcbackends.built_in()
    backend = mcbackends.backend(uri.host)
    if backend is None or backend.kind not in built:
        raise UriError(
            f"{uri.raw}: the installed libmotioncapture has no backend "
            f"{uri.host!r}; it has: {', '.join(built)}"
        )
    return backend


def _check_options(uri: Uri, backend: mcbackends.Backend, options: dict[str, str]) -> None:
    unknown = sorted(set(options) - set(backend.options))
    if unknown:
        known = ", ".join((*OWN_PARAMS, *backend.options))
        raise UriError(
            f"{uri.raw}: unknown parameter {unknown[0]!r}; "
            f"motioncapture://{backend.kind} takes {known}"
        )
    for key in sorted(set(options) & mcbackends.INTEGER_OPTIONS):
        if not options[key].isdigit():
            raise UriError(f"{uri.raw}: {key}={options[key]!r} is not a whole number")


class MotionCaptureSource(ThreadedSource):
    """PoseSource over libmotioncapture in a worker process; see the module docstring."""

    def __init__(self, config: MotionCaptureConfig, clock: Clock) -> None:
        super().__init__()
        self.config = config
        self.body = config.body
        self._clock = clock
        self._stream = PoseStream(config.body, config.limits, RateLimitedWarning(log, config.name))
        self._answered = threading.Event()
        self._failure = ""
        self._proc = None
        self._pipe = None

    def start(self) -> None:
        read, write = os.pipe()
        options = json.dumps(dict(self.config.options))
        try:
            self._proc = childproc.start(
                "perchd.mocap.mcworker",
                [str(write), self.config.kind, self.body, options],
                (write,),
            )
        finally:
            os.close(write)
        self._pipe = os.fdopen(read, "r")
        self._start_thread("motioncapture-rx")
        if not self._answered.wait(self.config.connect_timeout_s):
            self.close()
            raise LinkError(
                f"{self.config.name}: no answer within "
                f"{self.config.connect_timeout_s:g} s (is the server up, "
                "streaming, and set as docs/mocap.md says?)"
            )
        if self._failure:
            self.close()
            raise LinkError(f"{self.config.name}: {self._failure}")

    def close(self) -> None:
        self._stop.set()
        if self._proc is not None:
            self._proc.kill()  # blocked in the library's receive: nothing else ends it
            try:
                self._proc.wait(CLOSE_WAIT_S)
            except Exception:  # noqa: BLE001 - still exiting: the OS reaps it
                pass
        self._stop_thread()
        if self._pipe is not None:
            self._pipe.close()
        self._proc = self._pipe = None

    def _run(self) -> None:
        for line in self._pipe:
            self.handle_line(line, self._clock.now())
        if not self._answered.is_set():
            self._failure = f"the libmotioncapture process ended (exit {self._proc.wait()})"
            self._answered.set()
        elif not self._stop.is_set():
            log.warning("%s: the libmotioncapture process ended; no more poses", self.config.name)

    def handle_line(self, line: str, arrival: float) -> None:
        """Take one worker line that arrived at agent time `arrival`; never raises."""
        try:
            msg = mcworker.parse_line(line)
            if "seq" in msg:
                self._on_frame(msg, arrival)
            else:
                self._failure = str(msg.get("error", ""))
                self._answered.set()
        except (ValueError, KeyError, TypeError) as err:
            self._stream.drop(Drop.GARBAGE, f"{type(err).__name__}: {err}")

    def _on_frame(self, msg: dict, arrival: float) -> None:
        self._stream.packet()
        got = mcworker.sample(msg)
        if got is None:
            self._stream.drop(
                Drop.NO_BODY,
                f"frame {msg['seq']} has no rigid body "
                f"{self.body!r} (it has: "
                f"{', '.join(msg.get('seen', [])) or 'none'})",
            )
            return
        latency = max(0.0, time.monotonic() - float(msg["t"]))
        p, q = to_world(*got, self.config.up)
        self._stream.offer(Pose(self.body, int(msg["seq"]), arrival - latency, p, q, True, latency))
