"""The docs hold: every repository path a Markdown file names exists, every `perchd ...`
command it quotes parses with perchd's own argparse parser, and no tracked file speaks of
where a change came from (the work that made it, its tracker, its dates): files say what is
true and what they prove.

Each test collects every failure and reports them all at once.
"""

from __future__ import annotations

import contextlib
import glob
import io
import os
import re
import shlex
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

TOP_DIRS = ("perchd", "tests", "benchmarks", "plans", "docs", "systemd")
"""A path whose first segment is one of these is a path in the repository."""
PERCHD_DIRS = (
    "flight",
    "drivers",
    "core",
    "sim",
    "service",
    "mocap",
    "tau",
    "logs",
    "commands",
    "console",
    "bench",
    "session",
)
"""...and so is one whose first segment is a perchd subpackage (`flight/run.py`), resolved
under perchd/; those that exist now count as well."""
EXTENSIONS = (
    ".py",
    ".md",
    ".json",
    ".jsonl",
    ".toml",
    ".service",
    ".socket",
    ".rules",
    ".csv",
    ".bin",
    ".pcapng",
    ".txt",
    ".png",
)
SKIP_DIRS = {".git", "__pycache__", "node_modules", ".venv", "venv", "build", "dist"}

PATH_TOKEN = re.compile(r"^[\w.*{},/-]+$")
PLAIN_PATH = re.compile(
    r"(?<![\w/.-])((?:"
    + "|".join(TOP_DIRS)
    + r")/[\w./*-]*?(?:"
    + "|".join(re.escape(e) for e in EXTENSIONS)
    + r"))(?![\w/])"
)
BACKTICK = re.compile(r"(?<!`)`([^`\n]+)`(?!`)")
LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.M | re.S)

FORBIDDEN = re.compile(
    r"\b(issue \d+|the issue|this session|(first|second|third|\w+th) session|the review"
    r"|after review|the brief)\b|20\d\d-\d\d-\d\d",
    re.I,
)
FORBIDDEN_ALLOWED = {"tests/test_docs.py"}
"""Tracked files allowed to match FORBIDDEN: this file states the pattern."""

PLACEHOLDERS = {
    "N": "1",
    "PRIO": "50",
    "HZ": "100",
    "S": "1",
    "M": "0.001",
    "V": "0.5",
    "PORT": "5555",
    "X": "0",
    "Y": "0",
    "Z": "0",
    "NX": "1",
    "NY": "0",
    "NZ": "0",
    "GYRO": "0.001",
    "ACC": "0.01",
    "LEVEL_S": "0.5",
    "CUT_S": "2",
    "FILE": "f.json",
    "F": "f.json",
    "DIR": "out",
    "OUT": "out.mcap",
    "URI": "sim://",
    "NAME": "cf1",
    "HOST": "127.0.0.1",
    "DEG": "60",
    "TOML": "[lag_id]",
    "BUILD_DIR": "build/px4_sitl_default",
}
"""Placeholder words in the docs' commands, each replaced by a value of its kind."""


def markdown_files() -> list[Path]:
    out = []
    for dirpath, dirnames, filenames in os.walk(ROOT):
        dirnames[:] = sorted(
            d
            for d in dirnames
            if d not in SKIP_DIRS and not d.startswith(".") and not d.endswith(".egg-info")
        )
        out += [Path(dirpath) / f for f in sorted(filenames) if f.endswith(".md")]
    return out


def _perchd_dirs() -> set[str]:
    pkg = ROOT / "perchd"
    return (
        set(PERCHD_DIRS)
        | {p.name for p in pkg.iterdir() if p.is_dir()}
        | {p.stem for p in pkg.glob("*.py")}
    )


def _clean(token: str) -> str | None:
    """A repository path from a backtick or link token, or None if it is not one."""
    token = token.strip().strip("<>").split("#", 1)[0]
    token = re.sub(r"::.*$", "", token)  # pytest node ids
    token = re.sub(r"(\.py):[\w.]+$", r"\1", token)  # module:function
    token = token.rstrip(".,;:)")
    if not token or "://" in token or not PATH_TOKEN.match(token) or "/" not in token:
        return None
    first = token.split("/", 1)[0]
    if first not in TOP_DIRS and first not in _perchd_dirs():
        return None
    if not (token.endswith("/") or token.endswith(EXTENSIONS) or "*" in token):
        return None
    return token


def path_candidates(text: str) -> set[str]:
    found = set()
    for m in BACKTICK.finditer(text):
        found.add(_clean(m.group(1)))
    for m in LINK.finditer(text):
        found.add(_clean(m.group(1)))
    for m in PLAIN_PATH.finditer(text):
        found.add(_clean(m.group(1)))
    found.discard(None)
    return found


def _exists(path: str, doc: Path) -> bool:
    bases = [ROOT, doc.parent]
    if path.split("/", 1)[0] not in TOP_DIRS:
        bases.insert(0, ROOT / "perchd")
    for base in bases:
        pattern = str(base / path)
        for alt in _brace_expand(pattern):
            if glob.glob(alt) if any(c in alt for c in "*?[") else Path(alt).exists():
                return True
    return False


def _brace_expand(s: str) -> list[str]:
    m = re.search(r"\{([^{}]*)\}", s)
    if not m:
        return [s]
    return [
        x
        for opt in m.group(1).split(",")
        for x in _brace_expand(s[: m.start()] + opt + s[m.end() :])
    ]


def test_every_path_the_docs_name_exists():
    broken = []
    for doc in markdown_files():
        text = doc.read_text(encoding="utf-8")
        for path in sorted(path_candidates(text)):
            if not _exists(path, doc):
                broken.append(f"{doc.relative_to(ROOT)}: {path}")
    assert not broken, "paths named in the docs that do not exist:\n  " + "\n  ".join(broken)


# -- commands ------------------------------------------------------------------------------

ASSIGN = re.compile(r"^([A-Z_][A-Z0-9_]*)=(.*)$")
MENTION = (
    "arguments are required",
    "is required",
    "expected one argument",
    "expected at least one argument",
)
"""Why a mention (an inline `perchd fly`, `perchd sim --campaign`, or a block's elided
`perchd plan library ... --out L.json`) fails to parse: it names a valid command or option
without all its arguments. Anything else (an unknown command, option or choice, a bad
value) is a broken command."""


def _commands_in_blocks(text: str) -> list[str]:
    out = []
    for block in FENCE.findall(text):
        env = {}
        for line in block.replace("\\\n", " ").splitlines():
            line = line.strip()
            m = ASSIGN.match(line)
            if m:
                env[m.group(1)] = " ".join(shlex.split(m.group(2)))
            elif line.startswith("perchd "):
                out.append(
                    re.sub(
                        r"\$\{?([A-Z_][A-Z0-9_]*)\}?",
                        lambda v: env.get(v.group(1), v.group(0)),
                        line,
                    )
                )
    return out


def _commands_inline(text: str) -> list[str]:
    text = FENCE.sub("", text)
    return [
        m.group(1).strip()
        for m in BACKTICK.finditer(text)
        if m.group(1).strip().startswith("perchd ")
    ]


def _alternatives(command: str) -> list[str]:
    """`perchd log {summary|plot} F` -> both; `bench planner|loop` -> both."""
    m = re.search(r"\{([^{}]*\|[^{}]*)\}", command)
    if m:
        return [
            c
            for alt in m.group(1).split("|")
            for c in _alternatives(command[: m.start()] + alt.strip() + command[m.end() :])
        ]
    m = re.search(r"(?<=\s)([\w-]+(?:\|[\w-]+)+)(?=\s|$)", command)
    if m:
        return [
            c
            for alt in m.group(1).split("|")
            for c in _alternatives(command[: m.start()] + alt + command[m.end() :])
        ]
    return [command]


def _argv(command: str) -> list[str] | None:
    """The argv of a quoted command, placeholders replaced; None for log output (`perchd
    fly: ...`, `perchd sim: ready: ...`)."""
    command = re.split(r"\s#", " " + command, maxsplit=1)[0].strip()
    # ` | word://...` is an alternative value (keep the first); any other ` | ` a pipe
    command = re.sub(r"\s\|\s+\S*://\S*", "", command)
    command = re.split(r"\s(?:\||&&|>|;)\s", command, maxsplit=1)[0]
    command = command.rstrip("&").strip()
    try:
        words = shlex.split(command)
    except ValueError:
        words = command.split()
    if len(words) > 1 and words[1].endswith(":"):
        return None
    argv = []
    for w in words[1:]:
        w = w.replace("[", "").replace("]", "")
        if w in ("...", ""):
            continue
        if "=" in w and w.startswith("--"):
            opt, val = w.split("=", 1)
            w = f"{opt}={PLACEHOLDERS.get(val, val)}"
        argv.append(PLACEHOLDERS.get(w, w))
    return argv


def _parse(argv: list[str]) -> str | None:
    """None if argv parses, else argparse's message."""
    from perchd.cli import build_parser

    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            build_parser(argv).parse_args(argv)
    except SystemExit as e:
        if e.code not in (0, None):
            return err.getvalue().strip() or f"exit {e.code}"
    return None


def test_every_perchd_command_the_docs_quote_parses():
    broken = []
    for doc in markdown_files():
        text = doc.read_text(encoding="utf-8")
        quoted = [(c, "..." in c) for c in _commands_in_blocks(text)]
        quoted += [(c, True) for c in _commands_inline(text)]
        for command, mention in quoted:
            for alt in _alternatives(command):
                argv = _argv(alt)
                if argv is None:
                    continue
                why = _parse(argv)
                if why and not (mention and any(m in why for m in MENTION)):
                    broken.append(f"{doc.relative_to(ROOT)}: {alt!r}: {why}")
    assert not broken, "commands in the docs that perchd refuses:\n  " + "\n  ".join(broken)


# -- words ---------------------------------------------------------------------------------


def _tracked_files() -> list[str]:
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [p for p in out.decode().split("\0") if p]


def test_no_tracked_file_speaks_of_where_a_change_came_from():
    hits = []
    for rel in _tracked_files():
        if rel in FORBIDDEN_ALLOWED:
            continue
        path = ROOT / rel
        try:
            data = path.read_bytes()
        except OSError:
            continue  # listed but moved or deleted in the working tree
        if b"\0" in data[:8192]:
            continue  # binary
        for n, line in enumerate(data.decode("utf-8", "replace").splitlines(), 1):
            m = FORBIDDEN.search(line)
            if m:
                hits.append(f"{rel}:{n}: {m.group(0)!r}: {line.strip()[:120]}")
    assert not hits, (
        "tracked files that speak of where a change came from (FORBIDDEN):\n  " + "\n  ".join(hits)
    )
