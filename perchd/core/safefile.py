"""Reading files named by untrusted input (control-socket requests, config paths) safely.

A path a client names is resolved (symlinks followed) and must land inside the directory the
service was configured with; what is read must be a regular file of bounded size. Opening is
non-blocking so a FIFO or device named as a plan cannot stall the service loop.
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path
from typing import IO, Callable

from perchd.core.errors import PerchdError

MAX_FILE_BYTES = 1 << 20
"""[bytes] largest plan or config file read (a plan is ~1 kB, the full config ~6 kB)."""


def confine(name: str | os.PathLike[str], root: str | os.PathLike[str], what: str,
            error: type[PerchdError]) -> Path:
    """`name` (relative to `root`, or absolute) resolved; `error` unless it lies inside root."""
    base = Path(os.path.realpath(root))
    given = Path(root) / name  # an absolute name stays as given
    real = Path(os.path.realpath(given))
    if not real.is_relative_to(base):
        via = f" (a symlink to {real})" if real != Path(os.path.abspath(given)) else ""
        raise error(f"{what} {given}{via}: outside the plan directory {base} "
                    "(plan_dir in [service])")
    return real


def read_regular(path: str | os.PathLike[str], what: str, error: type[PerchdError],
                 max_bytes: int = MAX_FILE_BYTES) -> str:
    """The UTF-8 text of a regular file of at most `max_bytes`; `error` naming why not,
    as "WHAT PATH: why" (or "PATH: why" when `what` is empty)."""
    what = f"{what} {path}" if what else str(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOCTTY)
    except OSError as err:
        raise error(f"{what}: cannot read ({err.strerror})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise error(f"{what}: not a regular file ({_kind(st.st_mode)})")
        if st.st_size > max_bytes:
            raise error(f"{what}: {st.st_size} bytes, over the {max_bytes} byte limit "
                        f"by {st.st_size - max_bytes}")
        with os.fdopen(os.dup(fd), "rb") as f:
            data = f.read(max_bytes + 1)
    finally:
        os.close(fd)
    if len(data) > max_bytes:  # grew after the check
        raise error(f"{what}: over the {max_bytes} byte limit")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise error(f"{what}: not UTF-8 text (byte {err.start})") from None


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    return "not a file"


class OutputError(PerchdError, OSError):
    """An output path that would destroy data or needs directories made (exit 2)."""


def check_output(path: str | os.PathLike[str], flag: str, force: bool = False,
                 inputs: tuple[str | os.PathLike[str], ...] = ()) -> Path:
    """`path` if writing it destroys nothing: its directory exists (none is created), it is
    not a directory, not one of `inputs`, and absent unless `force`; else OutputError
    naming `flag`."""
    out = Path(path)
    if out.is_dir():
        raise OutputError(f"{flag} {out}: is a directory (give a file path inside it)")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise OutputError(f"{flag} {out}: directory {parent} does not exist "
                          "(perchd creates none; make it first)")
    for given in inputs:
        if os.path.exists(given) and out.exists() and os.path.samefile(out, given):
            raise OutputError(f"{flag} {out}: is the input {given}; give another path")
    if out.exists() and not force:
        raise OutputError(f"{flag} {out}: exists (pass --force to overwrite)")
    return out


def write_text(path: Path, text: str, flag: str, force: bool) -> None:
    """`text` written to `path` (checked by check_output) by write_atomic."""
    write_atomic(path, lambda f: _write_all(f, text.encode("utf-8")), flag, force)


def write_atomic(path: Path, write: Callable[[IO[bytes]], None], flag: str, force: bool) -> None:
    """`write(f)` into a temporary file beside `path`, then renamed onto it: a failure at any
    point leaves whatever was at `path` as it was. Without `force` an existing `path` (one
    that appeared since check_output) is refused, and the rename cannot replace one made
    meanwhile (os.link refuses an existing name)."""
    parent = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=parent)
    except OSError as err:
        raise OutputError(f"{flag} {path}: cannot write ({err.strerror})") from None
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        _place(tmp, path, flag, force)
    except OSError as err:
        if isinstance(err, PerchdError):
            raise
        raise OutputError(f"{flag} {path}: cannot write ({err.strerror})") from None
    finally:
        if os.path.lexists(tmp):
            os.unlink(tmp)


def _place(tmp: str, path: Path, flag: str, force: bool) -> None:
    if force:
        if os.path.lexists(path) and not os.path.isfile(path):
            raise OutputError(f"{flag} {path}: not a regular file; refusing to replace it")
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise OutputError(f"{flag} {path}: exists (pass --force to overwrite)") from None


def _write_all(f: IO[bytes], data: bytes) -> None:
    f.write(data)
