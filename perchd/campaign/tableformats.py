"""A table of frozen-dataclass rows on disk, CSV or Parquet (pyarrow), written as rows arrive.

Two files take the rows. The *log* takes each row the moment it arrives, in arrival order,
appended and flushed, so a process killed mid-campaign leaves every row that had arrived
readable (a torn last line is dropped): a CSV table is its own log, a Parquet one has a
JSON-lines journal beside it (`OUT.parquet.journal`). The *table* takes the rows in the
caller's order (`write`) as that order becomes known: into a temporary file beside it, a
row group at a time (core/safefile.py write_atomic, run by a thread of its own so the rows
can keep coming), which `finish` flushes, fsyncs and renames onto it. So no row waits in
memory for the end, and a failure at any point, a kill included, leaves the old table as
it was; the journal goes once the new table is in place."""

from __future__ import annotations

import csv
import dataclasses
import importlib.util
import io
import json
import os
import queue
import threading
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import IO, Any, Protocol

from perchd.core.safefile import NEW_FILE, OutputError, write_atomic

PARQUET_EXTRA = "perchd[cluster]"
ROW_GROUP_ROWS = 4096
"""Rows of a Parquet row group: a few MB of rows held at most, and a footer of a few
hundred row groups for 10^6 flights."""
FLAG = "--table"


def have_pyarrow() -> bool:
    return importlib.util.find_spec("pyarrow") is not None


def _types(row_type: type) -> dict[str, str]:
    """Column name -> annotation text ('float | None', 'int', 'str', 'bool', 'float')."""
    return {f.name: str(f.type) for f in dataclasses.fields(row_type)}


class TableFormat(Protocol):
    """Rows of one dataclass type at `path`: `append` to the log as rows arrive (`logged`
    counts them), `write` them in the table's order (`written`), then `finish` (or
    `abandon`: the old table stays)."""

    path: Path
    logged: int
    written: int

    def exists(self) -> bool: ...

    def load(self) -> list[Any]: ...

    def append(self, rows: Iterable[Any]) -> None: ...

    def start(self) -> None: ...

    def write(self, rows: Iterable[Any]) -> None: ...

    def finish(self, keep_log: bool = False) -> None: ...

    def abandon(self) -> None: ...

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


def open_appending(path: Path) -> Any:
    """`path` opened to append lines; a new file is created exclusively (core/safefile.py
    NEW_FILE: nothing at the name is followed or truncated); a last line torn by a kill is
    ended first, so the next row starts a line of its own (readers drop the torn one)."""
    try:
        fd = os.open(path, NEW_FILE, 0o666)
    except FileExistsError:
        f = open(path, "a", newline="")
        if _torn(path):
            f.write("\n")
        return f
    except (OSError, ValueError) as err:
        raise OutputError(f"{FLAG} {path}: cannot write ({err})") from None
    os.set_blocking(fd, True)
    return open(fd, "w", newline="")


def _torn(path: Path) -> bool:
    if path.stat().st_size == 0:
        return False
    with open(path, "rb") as f:
        f.seek(-1, os.SEEK_END)
        return f.read(1) != b"\n"


class _Sink(Protocol):
    """Rows into the replacement's file object: `close` completes it, `discard` lets go
    of it (write_atomic removes the file)."""

    def write(self, rows: list[Any]) -> None: ...

    def close(self) -> None: ...

    def discard(self) -> None: ...


_DONE, _DROP = object(), object()


class _Dropped(Exception):
    """The replacement abandoned: write_atomic removes its temporary file."""


class Replacement:
    """A file's new content streamed through write_atomic in a thread: `write(rows)` hands
    rows to the sink `make(f)` opened on the temporary file; `finish` puts the file in place
    (or raises, the old one left); `abandon` drops it."""

    def __init__(self, path: Path, make: Callable[[IO[bytes]], _Sink]) -> None:
        self.path, self._make = path, make
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="perchd-table", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            write_atomic(self.path, self._consume, FLAG, force=True)
        except _Dropped:
            pass
        except BaseException as err:  # raised in the caller's thread, at its next call
            self._error = err

    def _consume(self, f: IO[bytes]) -> None:
        sink = self._make(f)
        try:
            while (item := self._queue.get()) is not _DONE:
                if item is _DROP:
                    raise _Dropped
                sink.write(item)
            sink.close()
        except BaseException:
            sink.discard()
            raise

    def write(self, rows: list[Any]) -> None:
        self._check()
        self._queue.put(rows)

    def finish(self) -> None:
        self._queue.put(_DONE)
        self._thread.join()
        self._check()

    def abandon(self) -> None:
        self._queue.put(_DROP)
        self._thread.join()

    def _check(self) -> None:
        if self._error is not None:
            raise self._error


class _Table:
    """What both formats share: the log rows are appended to (opened at the first), the
    table's replacement (`start`ed before any row comes), and the files a table is."""

    path: Path
    logged = written = 0
    _f: Any = None
    _new: Replacement | None = None

    def files(self) -> tuple[Path, ...]:
        return (self.path,)

    def _sink(self, f: IO[bytes]) -> _Sink:
        raise NotImplementedError

    def start(self) -> None:
        """The replacement's thread and file, made before the rows come (a signal while a
        thread starts must not fall between a row and the table)."""
        if self._new is None:
            self._new = Replacement(self.path, self._sink)

    def write(self, rows: Iterable[Any]) -> None:
        """Rows in the table's order, after those written before."""
        self.start()
        assert self._new is not None
        batch = list(rows)
        self._new.write(batch)
        self.written += len(batch)

    def finish(self, keep_log: bool = False) -> None:
        """The rows written are the table now: renamed into place (the old one left as it
        was if that fails). keep_log: some row logged may be missing from them (a signal
        fell between), so the log stays for a resume to read."""
        self.close()
        self.start()
        assert self._new is not None
        new, self._new = self._new, None
        new.finish()

    def abandon(self) -> None:
        """The replacement dropped; the old table and the log stay as they are."""
        self.close()
        if self._new is not None:
            new, self._new = self._new, None
            new.abandon()

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def remove(self) -> None:
        self.abandon()
        for f in self.files():
            f.unlink(missing_ok=True)


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


class CsvTable(_Table):
    """COLUMNS as the header; each row appended and flushed as it arrives (the table is
    its own log) until the table in order is renamed onto it at `finish`."""

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
            self._f = open_appending(self.path)
            self._csv = csv.writer(self._f)
            if self._f.tell() == 0:
                self._csv.writerow(self.types)
        batch = list(rows)
        for row in batch:
            self._csv.writerow([cell(v) for v in dataclasses.astuple(row)])
        self._f.flush()
        self.logged += len(batch)

    def _sink(self, f: IO[bytes]) -> _Sink:
        return _CsvSink(f, self.types)

    def finish(self, keep_log: bool = False) -> None:
        """keep_log: the table stays the log (every row, in arrival order)."""
        if keep_log:
            self.abandon()
        else:
            super().finish()


class _CsvSink:
    def __init__(self, f: IO[bytes], columns: Iterable[str]) -> None:
        self._text = io.TextIOWrapper(f, newline="", encoding="utf-8")
        self._csv = csv.writer(self._text)
        self._csv.writerow(columns)

    def write(self, rows: list[Any]) -> None:
        self._csv.writerows([cell(v) for v in dataclasses.astuple(r)] for r in rows)

    def close(self) -> None:
        self._text.flush()
        self._text.detach()  # the file stays open for write_atomic to fsync

    def discard(self) -> None:
        self._text.detach()


# --- Parquet -------------------------------------------------------------------------------
_ARROW = {"int": "int64", "float": "float64", "str": "string", "bool": "bool_"}


class ParquetTable(_Table):
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
        batch = list(rows)
        self._f.write("".join(json.dumps(dataclasses.asdict(r)) + "\n" for r in batch))
        self._f.flush()
        self.logged += len(batch)

    def _sink(self, f: IO[bytes]) -> _Sink:
        return _ParquetSink(f, self.schema())

    def finish(self, keep_log: bool = False) -> None:
        super().finish()
        if not keep_log:
            self.journal.unlink(missing_ok=True)


class _ParquetSink:
    """Row groups of ROW_GROUP_ROWS rows (the last one shorter)."""

    def __init__(self, f: IO[bytes], schema: Any) -> None:
        import pyarrow.parquet as pq

        self._schema, self._rows = schema, list[dict[str, Any]]()
        self._out = pq.ParquetWriter(f, schema)

    def write(self, rows: list[Any]) -> None:
        self._rows.extend(dataclasses.asdict(r) for r in rows)
        while len(self._rows) >= ROW_GROUP_ROWS:
            self._group(self._rows[:ROW_GROUP_ROWS])
            del self._rows[:ROW_GROUP_ROWS]

    def _group(self, rows: list[dict[str, Any]]) -> None:
        import pyarrow as pa

        self._out.write_table(pa.Table.from_pylist(rows, schema=self._schema))

    def close(self) -> None:
        if self._rows:
            self._group(self._rows)
        self._out.close()  # the footer; the file stays open for write_atomic to fsync

    def discard(self) -> None:
        try:
            self._out.close()
        except (OSError, ValueError):
            pass  # what failed to be written is what is dropped
