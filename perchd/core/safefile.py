"""Reading files named by untrusted input (control-socket requests, config paths) safely.

A path a client names is resolved (symlinks followed) and must land inside the directory the
service was configured with; what is read must be a regular file of bounded size. Opening is
non-blocking so a FIFO or device named as a plan cannot stall the service loop.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from perchd.core.errors import PerchdError

MAX_FILE_BYTES = 1 << 20
"""[bytes] largest plan or config file read (a plan is ~1 kB, the full config ~6 kB)."""


def confine(name: str | os.PathLike, root: str | os.PathLike, what: str,
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


def read_regular(path: str | os.PathLike, what: str, error: type[PerchdError],
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
