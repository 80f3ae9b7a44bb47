"""A table of frozen-dataclass rows on disk, one row per line as rows arrive, and whole and
sorted at the end: CSV, or Parquet (pyarrow).

CSV is appended to in place. A Parquet file is written whole (its footer comes last), so
rows arriving go to a JSON-lines journal beside it (`OUT.parquet.journal`) and the Parquet
file is rewritten from the table and the journal at `finish`. Either way a process killed
mid-campaign leaves every row that had arrived readable; a torn last line is dropped."""

from __future__ import annotations

import csv
import dataclasses
import importlib.util
import json
import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, Protocol

PARQUET_EXTRA = "perchd[cluster]"


def have_pyarrow() -> bool:
    return importlib.util.find_spec("pyarrow") is not None


def _types(row_type: type) -> dict[str, str]:
    """Column name -> annotation text ('float | None', 'int', 'str', 'bool', 'float')."""
    return {f.name: str(f.type) for f in dataclasses.fields(row_type)}


class TableFormat(Protocol):
    """Rows of one dataclass type at `path`."""

    path: Path

    def exists(self) -> bool: ...

    def load(self) -> list[Any]: ...

    def append(self, rows: Iterable[Any]) -> None: ...

    def finish(self, rows: list[Any]) -> None: ...

    def remove(self) -> None: ...


def table_format(path: Path, row_type: type) -> TableFormat:
    """By suffix: .parquet (needs pyarrow) or anything else as CSV."""
    if path.suffix == ".parquet":
        if not have_pyarrow():
            raise ImportError(
                f"a .parquet table needs pyarrow; pip install '{PARQUET_EXTRA}' "
                "or name a .csv table"
            )
        return ParquetTable(path, row_type)
    return CsvTable(path, row_type)


def _replace(path: Path, write: Callable[[Path], None]) -> None:
    """Write beside `path`, then rename over it: a reader sees the old table or the new."""
    tmp = path.with_name(f".{path.name}.tmp")
    write(tmp)
    os.replace(tmp, path)


def open_appending(path: Path) -> Any:
    """`path` opened to append lines; a last line torn by a kill is ended first, so the
    next row starts a line of its own (readers drop the torn one)."""
    f = open(path, "a", newline="")
    if _torn(path):
        f.write("\n")
    return f


def _torn(path: Path) -> bool:
    if path.stat().st_size == 0:
        return False
    with open(path, "rb") as f:
        f.seek(-1, os.SEEK_END)
        return f.read(1) != b"\n"


# --- CSV -----------------------------------------------------------------------------------
def cell(value: Any) -> Any:
    """A CSV cell: floats to 7 significant digits, None empty."""
    if value is None:
        return ""
    return format(value, ".7g") if isinstance(value, float) else value


_PARSE = {"int": int, "float": float, "str": str, "bool": lambda s: s == "True"}


def _parse(text: str, kind: str) -> Any:
    if kind.endswith("| None"):
        return None if text == "" else _PARSE[kind.split()[0]](text)
    return _PARSE[kind](text)


class _Appending:
    """The file rows are appended to (opened at the first), and the files a table is."""

    path: Path
    _f: Any = None

    def files(self) -> tuple[Path, ...]:
        return (self.path,)

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def remove(self) -> None:
        self.close()
        for f in self.files():
            f.unlink(missing_ok=True)


class CsvTable(_Appending):
    """COLUMNS as the header; each row written and flushed as it arrives."""

    def __init__(self, path: Path, row_type: type) -> None:
        self.path, self.row_type, self.types = path, row_type, _types(row_type)

    def exists(self) -> bool:
        return self.path.exists()

    def load(self) -> list[Any]:
        with open(self.path, newline="") as f:
            lines = list(csv.reader(f))
        if not lines or tuple(lines[0]) != tuple(self.types):
            raise ValueError(f"{self.path}: not this table's columns")
        return [r for r in map(self._row, lines[1:]) if r is not None]

    def _row(self, cells: list[str]) -> Any:
        """The row, or None for a line torn by a kill mid-write."""
        if len(cells) != len(self.types):
            return None
        try:
            return self.row_type(*(_parse(c, k) for c, k in zip(cells, self.types.values())))
        except (ValueError, KeyError):
            return None

    def append(self, rows: Iterable[Any]) -> None:
        if self._f is None:
            fresh = not self.path.exists() or self.path.stat().st_size == 0
            self._f = open_appending(self.path)
            self._csv = csv.writer(self._f)
            if fresh:
                self._csv.writerow(self.types)
        for row in rows:
            self._csv.writerow([cell(v) for v in dataclasses.astuple(row)])
        self._f.flush()

    def finish(self, rows: list[Any]) -> None:
        self.close()
        _replace(self.path, lambda tmp: _write_csv(tmp, self.types, rows))


def _write_csv(path: Path, columns: Iterable[str], rows: list[Any]) -> None:
    with open(path, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(columns)
        out.writerows([cell(v) for v in dataclasses.astuple(r)] for r in rows)


# --- Parquet -------------------------------------------------------------------------------
_ARROW = {"int": "int64", "float": "float64", "str": "string", "bool": "bool_"}


class ParquetTable(_Appending):
    """The Parquet file plus its journal of rows not yet in it."""

    def __init__(self, path: Path, row_type: type) -> None:
        self.path, self.row_type, self.types = path, row_type, _types(row_type)
        self.journal = path.with_name(path.name + ".journal")

    def files(self) -> tuple[Path, ...]:
        return self.path, self.journal

    def exists(self) -> bool:
        return self.path.exists() or self.journal.exists()

    def schema(self) -> Any:
        import pyarrow as pa

        return pa.schema(
            [(name, getattr(pa, _ARROW[kind.split()[0]])()) for name, kind in self.types.items()]
        )

    def load(self) -> list[Any]:
        rows = self._load_parquet() if self.path.exists() else []
        return rows + self._load_journal()

    def _load_parquet(self) -> list[Any]:
        import pyarrow.parquet as pq

        table = pq.read_table(self.path)
        if tuple(table.column_names) != tuple(self.types):
            raise ValueError(f"{self.path}: not this table's columns")
        return [self.row_type(**d) for d in table.to_pylist()]

    def _load_journal(self) -> list[Any]:
        if not self.journal.exists():
            return []
        rows = []
        for line in self.journal.read_text().splitlines():
            try:
                rows.append(self.row_type(**json.loads(line)))
            except (ValueError, TypeError):
                continue  # torn by a kill mid-write
        return rows

    def append(self, rows: Iterable[Any]) -> None:
        if self._f is None:
            self._f = open_appending(self.journal)
        self._f.write("".join(json.dumps(dataclasses.asdict(r)) + "\n" for r in rows))
        self._f.flush()

    def finish(self, rows: list[Any]) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.close()
        table = pa.Table.from_pylist([dataclasses.asdict(r) for r in rows], schema=self.schema())
        _replace(self.path, lambda tmp: pq.write_table(table, tmp))
        self.journal.unlink(missing_ok=True)
