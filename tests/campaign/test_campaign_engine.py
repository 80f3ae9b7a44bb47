"""Campaigns on a real Dask LocalCluster on loopback: a worker killed mid-flight loses no
flight, an interrupted campaign resumed flies only the rest, the table does not depend on
the workers, and no process outlives the campaign however it ends."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("distributed")
pq = pytest.importorskip("pyarrow.parquet")
psutil = pytest.importorskip("psutil")

from perchd.campaign.flights import TIMING_COLUMNS  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BOX = str(ROOT / "plans" / "robust-n3-table2-box.json")
FLIGHTS = "24"
WAIT_S = 240.0
"""[s] a generous bound for a loaded machine: a test waits for an event, never times one."""


def campaign(table: Path, *extra: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "perchd",
        "sim",
        "--campaign",
        BOX,
        "--flights",
        FLIGHTS,
        "--seed",
        "5",
        "--gust",
        "0.2",
        "--table",
        str(table),
        "--json",
        *extra,
    ]


def run(table: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        campaign(table, *extra), capture_output=True, text=True, timeout=WAIT_S, cwd=ROOT
    )


def flights(table: Path) -> list[dict]:
    """The table's rows without the columns that time the machine."""
    return pq.read_table(table).drop_columns(list(TIMING_COLUMNS)).to_pylist()


def journal_rows(table: Path) -> int:
    journal = table.with_name(table.name + ".journal")
    return journal.read_text().count("\n") if journal.exists() else 0


def start(table: Path, *extra: str) -> subprocess.Popen:
    """The campaign in the background; its stderr in a file beside the table (a pipe
    nobody reads while waiting could fill and stall it)."""
    with open(table.with_name("stderr.txt"), "w") as err:
        return subprocess.Popen(
            campaign(table, *extra), stdout=subprocess.PIPE, stderr=err, text=True, cwd=ROOT
        )


def finish(proc: subprocess.Popen, table: Path) -> tuple[str, str]:
    """stdout and stderr once it exits."""
    out, _ = proc.communicate(timeout=WAIT_S)
    return out, table.with_name("stderr.txt").read_text()


def wait_for_rows(proc: subprocess.Popen, table: Path, least: int) -> None:
    deadline = time.monotonic() + WAIT_S
    while journal_rows(table) < least:
        assert proc.poll() is None, finish(proc, table)
        assert time.monotonic() < deadline, "no rows came"
        time.sleep(0.05)


def descendants(proc: subprocess.Popen) -> list:
    return psutil.Process(proc.pid).children(recursive=True)


def assert_all_gone(procs: list) -> None:
    """Every process the campaign started has exited (none left running or unreaped)."""
    _, alive = psutil.wait_procs(procs, timeout=30)
    assert not alive, [p.cmdline() for p in alive]


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> list[dict]:
    """The campaign flown in one process: the table every engine must give."""
    table = tmp_path_factory.mktemp("ref") / "ref.parquet"
    done = run(table)
    assert done.returncode in (0, 1), done.stderr
    rows = flights(table)
    assert [r["index"] for r in rows] == list(range(int(FLIGHTS)))
    return rows


@pytest.mark.parametrize("workers", ["1", "2"])
def test_the_same_seed_gives_the_same_table_on_any_number_of_workers(tmp_path, reference, workers):
    table = tmp_path / "t.parquet"
    done = run(table, "--cluster", f"local:{workers}")
    assert done.returncode in (0, 1), done.stderr
    assert json.loads(done.stdout)["engine"] == f"a local Dask cluster of {workers}"
    assert flights(table) == reference


def test_a_worker_killed_mid_flight_loses_nothing(tmp_path, reference):
    table = tmp_path / "t.parquet"
    proc = start(table, "--cluster", "local:2")
    wait_for_rows(proc, table, 1)
    started = descendants(proc)
    workers = [p for p in started if "spawn_main" in " ".join(p.cmdline())]
    assert workers, [p.cmdline() for p in started]
    workers[0].send_signal(signal.SIGKILL)  # flying its unit: the scheduler reruns it elsewhere
    out, err = finish(proc, table)
    assert proc.returncode in (0, 1), err
    assert json.loads(out)["flights"] == int(FLIGHTS)
    assert flights(table) == reference
    assert_all_gone(started + descendants_left(proc))


def descendants_left(proc: subprocess.Popen) -> list:
    try:
        return descendants(proc)
    except psutil.NoSuchProcess:
        return []


def test_an_interrupted_campaign_resumed_flies_only_the_rest(tmp_path, reference):
    table = tmp_path / "t.parquet"
    proc = start(table, "--cluster", "local:2")
    wait_for_rows(proc, table, 2)
    started = descendants(proc)
    proc.send_signal(signal.SIGINT)
    out, err = finish(proc, table)
    assert proc.returncode == 130, err
    assert "interrupted by SIGINT" in err and "Traceback" not in err
    assert_all_gone(started)
    kept = json.loads(out)["flights"]
    assert 2 <= kept < int(FLIGHTS) and len(flights(table)) == kept

    again = run(table, "--cluster", "local:2")
    assert again.returncode in (0, 1), again.stderr
    summary = json.loads(again.stdout)
    assert (summary["resumed"], summary["flown"]) == (kept, int(FLIGHTS) - kept)
    assert flights(table) == reference
    assert json.loads(table.with_name("t.summary.json").read_text())["complete"] is True


def test_another_campaign_on_the_table_is_refused_in_one_line(tmp_path, reference):
    table = tmp_path / "t.parquet"
    assert run(table).returncode in (0, 1)
    before = table.read_bytes()
    args = campaign(table)
    args[args.index("--seed") + 1] = "6"
    other = subprocess.run(args, capture_output=True, text=True, timeout=WAIT_S, cwd=ROOT)
    assert other.returncode == 2 and other.stderr.count("\n") == 1, other.stderr
    assert "made by another campaign (its spread differ)" in other.stderr
    assert table.read_bytes() == before


def test_an_unreachable_scheduler_is_one_line_and_leaves_nothing(tmp_path):
    table = tmp_path / "t.parquet"
    proc = start(table, "--cluster", "tcp://127.0.0.1:9")
    out, err = finish(proc, table)
    assert proc.returncode == 2 and err.count("\n") == 1, err
    assert "--cluster tcp://127.0.0.1:9: no scheduler answers" in err
    assert not table.exists()


def test_without_dask_a_scheduler_address_names_the_extra(monkeypatch):
    from perchd.campaign import engine
    from perchd.core.errors import ConfigError

    monkeypatch.setattr(engine, "have_dask", lambda: False)
    with pytest.raises(ConfigError, match=r"pip install 'perchd\[cluster\]'"):
        engine.open_engine(engine.parse_cluster("tcp://10.0.0.1:8786"), 1)
    pool = engine.open_engine(engine.parse_cluster("local:2"), 1)
    try:
        assert isinstance(pool, engine.ProcessPool) and pool.workers == 2
    finally:
        pool.close()
    assert os.getpid()  # this process is left as it was


KILL_BOUND_S = 2.0
"""[s] what kill may take on a loaded machine (~0.1 s idle), against the 4 s close waits."""


def executing(engine) -> int:
    """Units running on the engine's workers now (a worker answers while its thread flies)."""
    counts = engine.client.run(lambda dask_worker: len(dask_worker.state.executing))
    return sum(counts.values())


def wait_until_executing(engine, units: int) -> None:
    deadline = time.monotonic() + WAIT_S
    while executing(engine) < units:
        assert time.monotonic() < deadline, "the units never started"
        time.sleep(0.05)


def spawned() -> list:
    """This process's Dask worker processes."""
    return [
        p
        for p in psutil.Process().children(recursive=True)
        if "spawn_main" in " ".join(p.cmdline())
    ]


@pytest.mark.solo  # times the kill (tests/conftest.py)
def test_a_stopped_engine_kills_its_busy_workers_rather_than_wait_for_their_units():
    """close lets a Nanny ask its busy worker to leave, and kill it 4 s later; kill does not
    wait (docs/contracts.md §6: a campaign ends within 1 s of a signal)."""
    from perchd.campaign.dask_engine import DaskEngine

    engine = DaskEngine.start(None, 2)
    workers = spawned()
    try:
        assert len(workers) == 2, [p.cmdline() for p in workers]
        for _ in range(2):
            engine.client.submit(time.sleep, WAIT_S, pure=False)
        wait_until_executing(engine, 2)
        t0 = time.monotonic()
        engine.kill()
        took = time.monotonic() - t0
    finally:
        engine.close()
    assert took < KILL_BOUND_S, f"{took:.1f} s: kill waited for the workers to leave"
    assert not [p for p in workers if p.is_running()], "a worker outlived kill"
    assert spawned() == [], "a Nanny started its killed worker again"


def test_a_stopped_engine_leaves_a_remote_schedulers_workers_running():
    from distributed import LocalCluster

    from perchd.campaign.dask_engine import DaskEngine

    with LocalCluster(
        n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
    ) as remote:
        workers = spawned()
        engine = DaskEngine.start(remote.scheduler_address, 1)
        assert engine.cluster is None
        engine.client.submit(time.sleep, 1.0, pure=False)
        wait_until_executing(engine, 1)
        engine.kill()
        assert engine.client.status == "closed"
        assert len(workers) == 1 and all(p.is_running() for p in workers)
        assert len(remote.scheduler_info["workers"]) == 1


@pytest.mark.solo  # times the kill (tests/conftest.py)
def test_a_stopped_process_pool_kills_its_busy_workers_rather_than_wait_for_their_units():
    """The pool without Dask (the [cluster] extra absent): kill ends the running units too."""
    import threading

    from perchd.campaign.engine import ProcessPool

    before = set(psutil.Process().children())
    pool = ProcessPool(2)
    ended: list[BaseException] = []

    def consume() -> None:  # a campaign's loop: blocks in the first unit's result
        try:
            list(pool.map_unordered(time.sleep, [WAIT_S, WAIT_S]))
        except BaseException as err:  # noqa: BLE001 - the killed pool's error, kept
            ended.append(err)

    reader = threading.Thread(target=consume, daemon=True)
    reader.start()
    deadline = time.monotonic() + WAIT_S
    while len(set(psutil.Process().children()) - before) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    workers = list(set(psutil.Process().children()) - before)
    time.sleep(0.3)  # both units running
    t0 = time.monotonic()
    try:
        pool.kill()
    finally:
        took = time.monotonic() - t0
        pool.close()
    reader.join(KILL_BOUND_S)
    assert took < KILL_BOUND_S, f"{took:.1f} s: kill waited for the units"
    assert len(workers) == 2 and not [p for p in workers if p.is_running()]
    assert not reader.is_alive() and ended, "the campaign's loop never heard of the kill"
