"""The one rule for every file perchd reads or writes.

Reading: a path a client names is resolved (symlinks followed) and must land inside the
directory the service was configured with; what is read must be a regular file of bounded
size, opened non-blocking and checked on the open descriptor, so a FIFO or device named as
a plan, config, log or state file is refused at once instead of stalling a read.

Writing: an output is checked before anything runs (check_output: its directory exists, it
is a regular file or missing, not one of the inputs, absent unless --force), then written
to a temporary file beside it and renamed into place (write_atomic), so a failure at any
point leaves the old file as it was. A file written as it goes (a flight log, a campaign
table) is a Stream: a new one is created exclusively at its own name (O_EXCL|O_NOFOLLOW, so
nothing existing is truncated or followed and a FIFO there never blocks), where a crash or
a live view finds it; one replacing an existing file (--force) is written beside it and
renamed onto it when finished. A name taken from config or a request (a vehicle name in a
log name) is refused unless it is a plain file-name component (safe_name).
"""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO

from perchd.core.errors import PerchdError

MAX_FILE_BYTES = 1 << 20
"""[bytes] largest plan or config file read (a plan is ~1 kB, the full config ~6 kB)."""


def confine(
    name: str | os.PathLike[str], root: str | os.PathLike[str], what: str, error: type[PerchdError]
) -> Path:
    """`name` (relative to `root`, or absolute) resolved; `error` unless it lies inside root."""
    base = Path(os.path.realpath(root))
    given = Path(root) / name  # an absolute name stays as given
    real = Path(os.path.realpath(given))
    if not real.is_relative_to(base):
        via = f" (a symlink to {real})" if real != Path(os.path.abspath(given)) else ""
        raise error(
            f"{what} {given}{via}: outside the plan directory {base} (plan_dir in [service])"
        )
    return real


def read_regular(
    path: str | os.PathLike[str],
    what: str,
    error: type[PerchdError],
    max_bytes: int = MAX_FILE_BYTES,
) -> str:
    """The UTF-8 text of a regular file of at most `max_bytes`; `error` naming why not,
    as "WHAT PATH: why" (or "PATH: why" when `what` is empty)."""
    what = f"{what} {path}" if what else str(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOCTTY)
    except (OSError, ValueError) as err:
        raise error(f"{what}: cannot read ({_why(err)})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise error(f"{what}: not a regular file ({kind(st.st_mode)})")
        if st.st_size > max_bytes:
            raise error(
                f"{what}: {st.st_size} bytes, over the {max_bytes} byte limit "
                f"by {st.st_size - max_bytes}"
            )
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


def regular_file(
    path: str | os.PathLike[str], what: str, error: type[PerchdError], executable: bool = False
) -> Path:
    """`path` if it names a regular file (symlinks followed), executable by us when
    `executable`: for a file another program opens (a firmware binary, its parameters),
    so that a FIFO, device or directory is refused at once, not met by it. Else `error`,
    "WHAT PATH: why"."""
    try:
        st = os.stat(path)
    except (OSError, ValueError) as err:
        raise error(f"{what} {path}: cannot read ({_why(err)})") from None
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{what} {path}: not a regular file ({kind(st.st_mode)})")
    if executable and not os.access(path, os.X_OK):
        raise error(f"{what} {path}: not executable (chmod +x)")
    return Path(path)


def _why(err: OSError | ValueError) -> str:
    """An OS error's own words; a NUL byte in a path (ValueError) named as such."""
    if isinstance(err, OSError):
        return err.strerror or str(err)
    return "a path with a NUL byte" if "null" in str(err) else str(err)


def kind(mode: int) -> str:
    """What a file of stat mode `mode` is, in words ("a FIFO", "a directory", ...)."""
    for test, name in (
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
    ):
        if test(mode):
            return name
    return "not a file"


class OutputError(PerchdError, OSError):
    """An output path that would destroy data or needs directories made (exit 2)."""


def _stat(path: Path, flag: str) -> os.stat_result | None:
    """os.stat of `path` (symlinks followed), None if nothing is there; OutputError for a
    path that cannot be looked at (too long, a NUL byte, no permission, a symlink loop)."""
    try:
        return os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (OSError, ValueError) as err:
        raise OutputError(f"{flag} {path}: cannot write ({_why(err)})") from None


def check_output(
    path: str | os.PathLike[str],
    flag: str,
    force: bool = False,
    inputs: tuple[str | os.PathLike[str], ...] = (),
) -> Path:
    """`path` if writing it destroys nothing: its directory exists (none is created), it is
    a regular file or missing, not one of `inputs`, and absent unless `force`; else
    OutputError naming `flag`."""
    out = Path(path)
    st = _stat(out, flag)
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{flag} {out}: is a directory (give a file path inside it)")
    parent = out.parent if str(out.parent) else Path(".")
    up = _stat(parent, flag)
    if up is None or not stat.S_ISDIR(up.st_mode):
        raise OutputError(
            f"{flag} {out}: directory {parent} does not exist (perchd creates none; make it first)"
        )
    if st is None:
        return out
    if not stat.S_ISREG(st.st_mode):
        raise OutputError(
            f"{flag} {out}: not a regular file ({kind(st.st_mode)}); "
            "perchd writes only regular files"
        )
    for given in inputs:
        if _same(st, given):
            raise OutputError(f"{flag} {out}: is the input {given}; give another path")
    if not force:
        raise OutputError(f"{flag} {out}: exists (pass --force to overwrite)")
    return out


def _same(st: os.stat_result, other: str | os.PathLike[str]) -> bool:
    try:
        ost = os.stat(other)
    except (OSError, ValueError):
        return False
    return (st.st_dev, st.st_ino) == (ost.st_dev, ost.st_ino)


def write_text(path: Path, text: str, flag: str, force: bool) -> None:
    """`text` written to `path` (checked by check_output) by write_atomic."""
    write_atomic(path, lambda f: _write_all(f, text.encode("utf-8")), flag, force)


def write_atomic(path: Path, write: Callable[[IO[bytes]], None], flag: str, force: bool) -> None:
    """`write(f)` into a temporary file beside `path`, then renamed onto it: a failure at any
    point leaves whatever was at `path` as it was. Without `force` an existing `path` (one
    that appeared since check_output) is refused, and the rename cannot replace one made
    meanwhile (os.link refuses an existing name)."""
    tmp = _temp_beside(path, flag)
    try:
        with open(tmp, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        _place(tmp, path, flag, force)
    except OSError as err:
        if isinstance(err, PerchdError):
            raise
        raise OutputError(f"{flag} {path}: cannot write ({_why(err)})") from None
    finally:
        if os.path.lexists(tmp):
            os.unlink(tmp)


def _temp_beside(path: Path, flag: str) -> str:
    """A new empty temporary file in `path`'s directory (so the rename stays on its
    filesystem), mode rw-r--r-- as an output's (not mkstemp's 0600; reading the umask
    would set it, which races the service's other threads)."""
    parent = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:64]}.", suffix=".part", dir=parent)
    except (OSError, ValueError) as err:
        raise OutputError(f"{flag} {path}: cannot write ({_why(err)})") from None
    os.fchmod(fd, 0o644)
    os.close(fd)
    return tmp


def _place(tmp: str, path: Path, flag: str, force: bool) -> None:
    if force:
        st = _stat(path, flag)
        if st is not None and not stat.S_ISREG(st.st_mode):
            raise OutputError(f"{flag} {path}: not a regular file; refusing to replace it")
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise OutputError(f"{flag} {path}: exists (pass --force to overwrite)") from None


NEW_FILE = (
    os.O_WRONLY
    | os.O_CREAT
    | os.O_EXCL
    | os.O_NOFOLLOW
    | os.O_NONBLOCK
    | os.O_CLOEXEC
    | os.O_NOCTTY
)
"""A new regular file only: whatever exists at the name (a file, a FIFO, a device, a
symlink) is EEXIST, before anything could block or be truncated."""


class Stream:
    """A file written as it goes (a flight log, a campaign table): `file` is open on
    `writing`, which is `target` itself when nothing was there (so a crash or a live view
    finds it) and a temporary file beside it when it replaces one (`force`); finish() puts
    it in place, abandon() drops a replacement and leaves the old file as it was."""

    def __init__(self, target: str | os.PathLike[str], flag: str, force: bool) -> None:
        self.target, self.flag = Path(target), flag
        replacing = _stat(check_output(self.target, flag, force), flag) is not None
        self.writing = Path(_temp_beside(self.target, flag)) if replacing else self.target
        self.file: IO[bytes] = self._open(replacing)

    def _open(self, replacing: bool) -> IO[bytes]:
        try:
            if replacing:  # _temp_beside made it, exclusively, a moment ago
                fd = os.open(self.writing, os.O_WRONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
            else:
                fd = os.open(self.writing, NEW_FILE, 0o666)
        except FileExistsError:
            raise OutputError(
                f"{self.flag} {self.target}: exists (pass --force to overwrite)"
            ) from None
        except (OSError, ValueError) as err:
            raise OutputError(f"{self.flag} {self.target}: cannot write ({_why(err)})") from None
        os.set_blocking(fd, True)
        return os.fdopen(fd, "wb")

    def finish(self) -> None:
        """Close; a replacement renamed onto the target (OSError if that fails: the old
        file stays)."""
        self.file.close()
        if self.writing != self.target:
            _place(str(self.writing), self.target, self.flag, force=True)

    def abandon(self) -> None:
        """Close; a replacement removed (the old file stays), a new file kept as written."""
        try:
            self.file.close()
        except OSError:
            pass  # the data that failed to write is what is being dropped
        if self.writing != self.target and os.path.lexists(self.writing):
            os.unlink(self.writing)


def safe_name(name: object, what: str, error: type[PerchdError]) -> str:
    """`name` if it is a plain file-name component (letters, digits, '.', '_', '-', at most
    64, not starting with '.'), so a file named after it stays in its directory; `error`
    otherwise. Refused, not sanitised: two names sanitised alike would share files."""
    if not isinstance(name, str):
        raise error(f"{what}: {name!r} is not a plain name: it names files")
    ok = (
        0 < len(name) <= 64
        and not name.startswith(".")
        and all(c.isascii() and (c.isalnum() or c in "._-") for c in name)
    )
    if not ok:
        raise error(
            f"{what}: {name!r} is not a plain name (letters, digits, '.', '_', '-'; "
            "at most 64, not starting with '.'): it names files"
        )
    return name


def _write_all(f: IO[bytes], data: bytes) -> None:
    f.write(data)
