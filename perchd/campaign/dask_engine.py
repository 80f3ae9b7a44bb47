"""The Dask engine: a LocalCluster of worker processes on 127.0.0.1, or a running
scheduler (`dask scheduler` + `dask worker tcp://HOST:8786` on each node).

Dask reruns a task whose worker was lost on another worker, and idle workers steal queued
tasks, so a campaign's units spread evenly and none is lost with a node. Imported only
when Dask is installed (pip install 'perchd[cluster]')."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import signal
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

import dask
from distributed import Client, LocalCluster, as_completed

from perchd.campaign.engine import MOST_PER_UNIT
from perchd.core.errors import ConfigError

T = TypeVar("T")
R = TypeVar("R")

CONNECT_TIMEOUT_S = 10.0
"""[s] to reach a scheduler named by --cluster tcp://."""
JOIN_TIMEOUT_S = 0.5
"""[s] for a Nanny to see its killed worker exit (it is SIGKILLed again after 80 % of it)."""
WORKER_CONFIG = {"distributed.worker.profile.enabled": False}
"""A local worker's Dask settings over the defaults (each Nanny hands its worker the
configuration it was made under): no statistical profiler, a thread sampling the stack every
10 ms (~5 % of a flight's CPU) for a dashboard perchd does not open."""


class DaskEngine:
    """A Dask client, and the LocalCluster it started (None on a remote scheduler)."""

    most_per_unit = MOST_PER_UNIT

    def __init__(self, client: Client, cluster: LocalCluster | None, name: str) -> None:
        self.client, self.cluster, self.name = client, cluster, name

    @classmethod
    def start(cls, address: str | None, workers: int) -> DaskEngine:
        if address is None:
            os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "error")  # workers: no chatter
            with dask.config.set(WORKER_CONFIG):
                cluster = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address="127.0.0.1:0",  # None still binds 8787, warning if taken
                    silence_logs=logging.ERROR,
                )
            try:
                return cls(Client(cluster), cluster, f"a local Dask cluster of {workers}")
            except BaseException:
                cluster.close()
                raise
        try:
            client = Client(address, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as err:
            raise ConfigError(f"--cluster {address}: no scheduler answers ({err})") from None
        return cls(client, None, f"the Dask scheduler at {address}")

    @property
    def workers(self) -> int:
        return max(1, sum(w.get("nthreads", 1) for w in self._info().values()))

    def _info(self) -> dict[str, Any]:
        return self.client.scheduler_info().get("workers", {})

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[R]:
        futures = [self.client.submit(fn, item, pure=False) for item in items]
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            self.client.cancel([f for f in futures if not f.done()])

    def close(self) -> None:
        """The client, then the cluster this engine started: no worker outlives it."""
        try:
            self.client.close()
        finally:
            if self.cluster is not None:
                self.cluster.close()

    def kill(self) -> None:
        """As close, but the local workers killed mid-unit: a stopped campaign drops their
        units, and a Nanny closed with the cluster waits for its worker's running unit. The
        workers of a remote scheduler are not this engine's: its units are only cancelled."""
        try:
            if self.cluster is not None:
                # The scheduler's comms to them end in tracebacks Dask logs at INFO, some
                # after the cluster closed and gave back the log level it held at ERROR.
                logging.getLogger("distributed").setLevel(logging.ERROR)
                self.cluster.sync(kill_workers, self.cluster)  # type: ignore[no-untyped-call]
        finally:
            self.close()


async def kill_workers(cluster: LocalCluster) -> None:
    """Every worker process of `cluster` killed, then its Nanny closed. Not asked to close: a
    worker finishes its running unit first, and one closing logs the heartbeat its own close
    cut short. The Nanny, closing, does not start its worker again."""
    nannies = list(cluster.workers.values())
    for nanny in nannies:
        nanny.close_gracefully(reason="campaign-stopped")
        if nanny.pid is not None:
            with contextlib.suppress(ProcessLookupError):  # it exited meanwhile
                os.kill(nanny.pid, signal.SIGKILL)
    await asyncio.gather(*(n.close(timeout=JOIN_TIMEOUT_S) for n in nannies))
