"""A campaign's results: its table (perchd.campaign.tableformats) and the JSON summary beside
it (`OUT.summary.json`), which names the campaign that made the table.

A campaign is named by its output: opened again with the same campaign (plan, policy,
configuration, spread and draw), the table's rows are kept and only the flights missing
from it, keyed by (index, seed), fly; opened with another campaign it is refused."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from perchd.campaign.flights import COLUMNS, FlightRow, FlightSpec, summarize
from perchd.campaign.tableformats import TableFormat, table_format
from perchd.core.safefile import OutputError


def digest(obj: Any) -> str:
    """sha256 of obj's canonical JSON (or of bytes)."""
    data = obj if isinstance(obj, bytes) else json.dumps(obj, sort_keys=True).encode()
    return hashlib.sha256(data).hexdigest()


def summary_path(table: Path) -> Path:
    return table.with_name(table.stem + ".summary.json")


def key(item: FlightRow | FlightSpec) -> tuple[int, int]:
    """A flight's key in the table: its index and its noise seed (drawn from the campaign's)."""
    return item.index, item.seed


class CampaignTable:
    """The rows so far (`rows`: this table's earlier ones first); `begin`, then `append` as
    flights end; `finish` writes the table whole, sorted by index, and the summary."""

    def __init__(self, path: Path, identity: dict[str, Any], force: bool) -> None:
        self.path, self.identity = path, json.loads(json.dumps(identity))
        try:
            self.store: TableFormat = table_format(path, FlightRow)
        except ImportError as err:
            raise OutputError(f"--table {path}: {err}") from None
        self.force, self.begun = force, False
        self.rows: list[FlightRow] = [] if force else self._resume()
        self.resumed = len(self.rows)

    def begin(self) -> None:
        """Claim the table for this campaign (a forced one starts empty) before any flight,
        so a campaign killed at once is resumed, not refused."""
        if self.force:
            self.store.remove()
        self.begun = True
        self._write_summary(complete=False)

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
            return self.store.load() if self.store.exists() else []
        except (OSError, ValueError) as err:
            raise OutputError(f"--table {self.path}: cannot resume it ({err})") from None

    def missing(self, specs: Iterable[FlightSpec]) -> list[FlightSpec]:
        done = {key(r) for r in self.rows}
        return [s for s in specs if key(s) not in done]

    def append(self, rows: list[FlightRow]) -> None:
        self.store.append(rows)
        self.rows.extend(rows)

    def finish(self, planned: int, extra: dict[str, Any]) -> list[FlightRow]:
        """The table sorted by index, then the summary: complete when every planned flight
        is in it (nothing written before `begin`). The sorted rows."""
        self.rows.sort(key=lambda r: r.index)
        if not self.begun:
            return self.rows
        self.store.finish(self.rows)
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
        out = summary_path(self.path)
        tmp = out.with_name(f".{out.name}.tmp")
        tmp.write_text(json.dumps(doc, indent=1) + "\n")
        os.replace(tmp, out)
