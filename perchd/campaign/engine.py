"""Where a campaign's work units run: the Engine protocol, this process, and a local
process pool (the standard library's, for machines without Dask).

`--cluster` names the engine: `local[:N]` (Dask's LocalCluster of N processes on 127.0.0.1
when Dask is installed, else the process pool below) or `tcp://HOST:8786` (a running Dask
scheduler, perchd.campaign.dask_engine). A unit's result does not depend on where it ran, so
the table does not depend on the engine."""

from __future__ import annotations

import importlib.util
import signal
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Protocol, TypeVar

from perchd.core.errors import ConfigError

T = TypeVar("T")
R = TypeVar("R")

MOST_PER_UNIT = 25
"""Flights in the largest unit sent to a worker process: ~2.5 CPU-s, against a few ms to
send it, and little to fly again when its worker is lost."""
CLUSTER_EXTRA = "perchd[cluster]"
"""The optional dependencies a Dask engine needs (pyproject.toml)."""


class Engine(Protocol):
    """Runs fn over items on `workers` processes, yielding results as they finish."""

    name: str
    workers: int
    most_per_unit: int
    """Flights a work unit may hold: 1 where a unit costs nothing to send."""

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[R]: ...

    def close(self) -> None:
        """After the last unit: everything closed, no process left."""

    def kill(self) -> None:
        """On a stop (a signal, an error): as close, without waiting for the running units."""


@dataclass(frozen=True)
class ClusterSpec:
    """What --cluster asked for: address (tcp://HOST:PORT) or None for this machine;
    workers: processes on this machine (None: --jobs); explicit: --cluster was given."""

    address: str | None
    workers: int | None
    explicit: bool


def parse_cluster(text: str | None) -> ClusterSpec:
    """`local`, `local:N` or `tcp://HOST:PORT` (None: local, the --jobs count)."""
    if text is None or text == "local":
        return ClusterSpec(None, None, text is not None)
    if text.startswith("local:"):
        n = text.partition(":")[2]
        if not n.isdigit() or int(n) < 1:
            raise ConfigError(f"--cluster {text}: local:N wants N >= 1 worker processes")
        return ClusterSpec(None, int(n), True)
    if text.startswith("tcp://") and text.rpartition(":")[2].isdigit():
        return ClusterSpec(text, None, True)
    raise ConfigError(f"--cluster {text}: local, local:N or tcp://SCHEDULER:PORT")


def have_dask() -> bool:
    return importlib.util.find_spec("distributed") is not None


def open_engine(spec: ClusterSpec, jobs: int) -> Engine:
    """The engine --cluster names. Without --cluster one job flies in this process."""
    workers = spec.workers or jobs
    if spec.address is None and not spec.explicit and workers == 1:
        return InProcess()
    if not have_dask():
        if spec.address is not None:
            raise ConfigError(
                f"--cluster {spec.address}: needs Dask; pip install '{CLUSTER_EXTRA}'"
            )
        return ProcessPool(workers)
    from perchd.campaign.dask_engine import DaskEngine

    return DaskEngine.start(spec.address, workers)


class InProcess:
    """Every unit in this process, one after the other."""

    name = "this process"
    workers = 1
    most_per_unit = 1  # rows as each flight ends

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[R]:
        return map(fn, items)

    def close(self) -> None:
        pass

    def kill(self) -> None:
        pass


class ProcessPool:
    """The standard library's pool of local processes; a worker that dies breaks the run
    (BrokenProcessPool), which Dask's engine survives."""

    def __init__(self, workers: int) -> None:
        self.workers, self.most_per_unit = workers, MOST_PER_UNIT
        self.name = f"a pool of {workers} processes"
        self._pool = ProcessPoolExecutor(max_workers=workers, initializer=leave_signals)

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[R]:
        futures = [self._pool.submit(fn, item) for item in items]
        for fut in as_completed(futures):
            yield fut.result()

    def close(self) -> None:
        """Queued units dropped, running ones let end: no process outlives the campaign."""
        self._pool.shutdown(wait=True, cancel_futures=True)

    def kill(self) -> None:
        """Queued units dropped, running ones killed: a stop waits for no unit."""
        kill_workers = getattr(self._pool, "kill_workers", None)  # Python >= 3.14
        if kill_workers is not None:
            kill_workers()
        else:  # before it, the pool's own table of its processes is the only way in
            for proc in list((getattr(self._pool, "_processes", None) or {}).values()):
                proc.kill()
        self.close()


def leave_signals() -> None:
    """Workers ignore Ctrl-C: the parent decides, and writes what has finished."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
