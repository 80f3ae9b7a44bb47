"""A campaign's table written as rows arrive: into a file beside it in flight order, a
row group at a time, renamed onto it at the end; the rows held meanwhile are only those
that came before an earlier flight; a failure leaves the old table (and the journal) as
they were, and resuming reads them and flies only what is missing."""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import pytest

pq = pytest.importorskip("pyarrow.parquet")

from perchd.campaign import tableformats  # noqa: E402
from perchd.campaign.flights import FlightRow, FlightSpec  # noqa: E402
from perchd.campaign.results import CampaignTable, summary_path  # noqa: E402
from perchd.core.safefile import OutputError  # noqa: E402

IDENTITY = {"plan": "p", "draw": {"flights": 8}}
ROW = FlightRow(
    0, -3.0, 1.5, 0.0, 0.0, 0.5, 0.1, 0.0, 0.0, 0, "CONTACT", -3.0, 1.5, 0.9, 0.9, 2.0, 2.0,
    0.9, 0.7, 1.0, True, 0.0, "robust", "", "ipts", 0.0, 600, 0.03, 0.6,
)  # fmt: skip


def row(i: int) -> FlightRow:
    return dataclasses.replace(ROW, index=i, seed=100 + i, contact_speed=0.8 + i / 100)


def specs(n: int = 8) -> list[FlightSpec]:
    return [FlightSpec(i, -3.0, 1.5, 0.5, (0.1, 0.0, 0.0), 100 + i) for i in range(n)]


def opened(path: Path, force: bool = False) -> tuple[CampaignTable, list[FlightSpec]]:
    table = CampaignTable(path, IDENTITY, force)
    todo = table.missing(specs())
    table.begin()
    return table, todo


def indices(path: Path) -> list[int]:
    return pq.read_table(path).column("index").to_pylist()


def wait_for(seen, within_s: float = 60.0):
    """seen() once true (the table's thread makes its file), or False after within_s."""
    deadline = time.monotonic() + within_s
    while not (got := seen()) and time.monotonic() < deadline:
        time.sleep(0.01)
    return got


def temporaries(path: Path) -> list[Path]:
    return [p for p in path.parent.iterdir() if p.name.endswith(".part")]


@pytest.mark.parametrize("name", ["t.parquet", "t.csv"])
def test_rows_go_into_the_new_table_in_flight_order_as_soon_as_every_earlier_one_is_in(
    tmp_path, monkeypatch, name
):
    monkeypatch.setattr(tableformats, "ROW_GROUP_ROWS", 2)
    path = tmp_path / name
    table, _ = opened(path)
    table.append([row(2), row(1)])  # flight 0 is not in yet: both wait
    assert sorted(table._early) == [1, 2]
    table.append([row(0), row(3)])
    assert not table._early  # 0..3 went to the new table
    table.append([row(7), row(5), row(4), row(6)])
    assert not table._early and len(table.rows) == 8
    assert wait_for(lambda: temporaries(path))  # the new table, beside the old
    table.finish(8, {})
    assert not temporaries(path)
    got = indices(path) if name.endswith(".parquet") else table.store.load()
    if name.endswith(".parquet"):
        assert got == list(range(8)) and pq.ParquetFile(path).metadata.num_row_groups == 4
        assert not path.with_name(name + ".journal").exists()
    else:
        assert [r.index for r in got] == list(range(8))
    assert json.loads(summary_path(path).read_text())["complete"] is True


def test_an_interrupted_campaign_writes_what_ended_sorted_and_resumed_flies_the_rest(tmp_path):
    path = tmp_path / "t.parquet"
    table, _ = opened(path)
    table.append([row(0), row(3), row(5)])
    table.finish(8, {})  # interrupted: 1, 2, 4, 6, 7 never ended
    assert indices(path) == [0, 3, 5]
    again, todo = opened(path)
    assert again.resumed == 3 and [s.index for s in todo] == [1, 2, 4, 6, 7]
    again.append([row(i) for i in (7, 1, 2, 6, 4)])
    again.finish(8, {})
    assert indices(path) == list(range(8))
    assert pq.read_table(path).to_pylist()[5]["contact_speed"] == row(5).contact_speed


def resumed_mid_flight(path: Path) -> tuple[bytes, CampaignTable]:
    """The table of flights 0 and 1 (its bytes), then the campaign resumed with 2 and 4
    arrived: in the journal, and 2 in the new table beside it."""
    table, _ = opened(path)
    table.append([row(0), row(1)])
    table.finish(8, {})
    again, _ = opened(path)
    again.append([row(2), row(4)])
    return path.read_bytes(), again


def test_a_failure_leaves_the_old_table_and_the_journal_as_they_were(tmp_path, monkeypatch):
    path = tmp_path / "t.parquet"
    before, again = resumed_mid_flight(path)

    def broken(self):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(tableformats._ParquetSink, "close", broken)
    with pytest.raises(OutputError, match="--table .*No space left"):
        again.finish(8, {})
    assert path.read_bytes() == before and not temporaries(path)
    monkeypatch.undo()
    third, todo = opened(path)  # the table and the journal: 0, 1, 2, 4
    assert third.resumed == 4 and [s.index for s in todo] == [3, 5, 6, 7]


def test_a_kill_leaves_the_old_table_and_the_journal_readable(tmp_path):
    path = tmp_path / "t.parquet"
    before, again = resumed_mid_flight(path)
    # killed here: the new table is never renamed onto the old
    assert path.read_bytes() == before
    third, todo = opened(path)
    assert third.resumed == 4 and [s.index for s in todo] == [3, 5, 6, 7]
    again.store.abandon(), third.store.abandon()


@pytest.mark.parametrize("name", ["t.parquet", "t.csv"])
def test_a_row_logged_but_not_in_the_new_table_keeps_the_log(tmp_path, name):
    """A signal between a row's log line and the table: the log stays for the resume."""
    path = tmp_path / name
    table, _ = opened(path)
    table.append([row(0), row(1)])
    table.store.append([row(2)])  # interrupted before the row went further
    table.finish(8, {})
    again, todo = opened(path)  # the table and its log: 0, 1 and 2, each once
    assert again.resumed == 3 and [s.index for s in todo] == [3, 4, 5, 6, 7]
    again.append([row(i) for i in (3, 4, 5, 6, 7)])
    again.finish(8, {})
    assert [r.index for r in again.store.load()] == list(range(8))
