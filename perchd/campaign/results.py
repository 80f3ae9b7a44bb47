"""A campaign's results: its table (perchd.campaign.tableformats) and the JSON summary beside
it (`OUT.summary.json`), which names the campaign that made the table.

A campaign is named by its output: opened again with the same campaign (plan, policy,
configuration, spread and draw), the table's rows are kept and only the flights missing
from it, keyed by (index, seed), fly; opened with another campaign it is refused."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from perchd.campaign.flights import COLUMNS, Brief, FlightRow, FlightSpec, summarize
from perchd.campaign.tableformats import TableFormat, table_format
from perchd.core.safefile import OutputError, write_text


def digest(obj: Any) -> str:
    """sha256 of obj's canonical JSON (or of bytes)."""
    data = obj if isinstance(obj, bytes) else json.dumps(obj, sort_keys=True).encode()
    return hashlib.sha256(data).hexdigest()


def summary_path(table: Path) -> Path:
    return table.with_name(table.stem + ".summary.json")


def key(item: FlightRow | FlightSpec | Brief) -> tuple[int, int]:
    """A flight's key in the table: its index and its noise seed (drawn from the campaign's)."""
    return item.index, item.seed


class CampaignTable:
    """`begin`, then `append` rows as flights end, then `finish`. Rows go to the table's log
    as they arrive and into the new table in flight order as soon as every earlier flight
    is in (tableformats.py), so the rows held are those that came early, not the whole
    campaign; `rows` keeps each row's Brief (its key and summary figures), earlier ones
    first."""

    def __init__(self, path: Path, identity: dict[str, Any], force: bool) -> None:
        self.path, self.identity = path, json.loads(json.dumps(identity))
        try:
            self.store: TableFormat = table_format(path, FlightRow)
        except ImportError as err:
            raise OutputError(f"--table {path}: {err}") from None
        self.force, self.begun = force, False
        earlier = [] if force else self._resume()
        self.rows: list[Brief] = [Brief.of(r) for r in earlier]
        self.resumed = len(self.rows)
        self._early: dict[int, FlightRow] = {r.index: r for r in earlier}  # not written yet
        self._order: list[int] = []  # the campaign's flight indices, ascending
        self._next = 0  # _order[:_next] are in the new table

    def begin(self) -> None:
        """Claim the table for this campaign (a forced one starts empty) before any flight,
        so a campaign killed at once is resumed, not refused."""
        if self.force:
            self.store.remove()
        self.begun = True
        self._write_summary(complete=False)
        self.store.start()

    def _resume(self) -> list[FlightRow]:
        """The rows of the same campaign's table; nothing for a new table."""
        made = summary_path(self.path)
        if not made.exists():
            if self.path.exists():
                raise OutputError(f"--table {self.path}: exists (pass --force to overwrite)")
            return []
        theirs = json.loads(made.read_text()).get("campaign", {})
        differ = sorted(
            k for k in self.identity.keys() | theirs.keys() if self.identity.get(k) != theirs.get(k)
        )
        if differ:
            raise OutputError(
                f"--table {self.path}: made by another campaign (its "
                f"{', '.join(differ)} differ); name another table or pass --force"
            )
        try:
            rows = self.store.load() if self.store.exists() else []
        except (OSError, ValueError) as err:
            raise OutputError(f"--table {self.path}: cannot resume it ({err})") from None
        return list({key(r): r for r in rows}.values())  # a kept journal repeats the table

    def missing(self, specs: Iterable[FlightSpec]) -> list[FlightSpec]:
        """The specs not in the table yet; all of them are the campaign (its table's order)."""
        specs = list(specs)
        self._order = sorted({s.index for s in specs})
        done = {key(r) for r in self.rows}
        return [s for s in specs if key(s) not in done]

    def append(self, rows: list[FlightRow]) -> None:
        self.store.append(rows)
        self.rows.extend(Brief.of(r) for r in rows)
        self._early.update((r.index, r) for r in rows)
        ready = []
        while self._next < len(self._order) and self._order[self._next] in self._early:
            ready.append(self._early.pop(self._order[self._next]))
            self._next += 1
        if ready:
            self.store.write(ready)

    def finish(self, planned: int, extra: dict[str, Any]) -> list[Brief]:
        """The table in place, sorted by index (the rows of flights that did not end after
        a gap, at an interruption), then the summary: complete when every planned flight is
        in it (nothing written before `begin`). The Briefs, sorted."""
        self.rows.sort(key=lambda r: r.index)
        if not self.begun:
            return self.rows
        if self._early:
            self.store.write([self._early.pop(i) for i in sorted(self._early)])
        whole = self.store.written == self.resumed + self.store.logged
        try:
            self.store.finish(keep_log=not whole)
        except BaseException:
            self.store.abandon()
            raise
        self._write_summary(complete=len(self.rows) == planned, planned=planned, **extra)
        return self.rows

    def _write_summary(self, complete: bool, **extra: Any) -> None:
        doc = {
            "campaign": self.identity,
            "table": str(self.path),
            "columns": list(COLUMNS),
            "complete": complete,
            "rows": len(self.rows),
            **extra,
            "summary": dataclasses.asdict(summarize(self.rows)),
        }
        write_text(summary_path(self.path), json.dumps(doc, indent=1) + "\n", "--table", True)
