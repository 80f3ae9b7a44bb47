"""`perchd plan library` and `perchd plan robust` show their progress on stderr when it is a
terminal (the campaign's bar) and print nothing there when it is not."""

from __future__ import annotations

import subprocess
import sys

import pytest
from terminal import run_on_terminal

LIMITS = (
    "--tau-s",
    "-0.5",
    "--v-contact",
    "0.7",
    "1.0",
    "--v-max",
    "2.5",
    "--a-max",
    "1.4",
    "--order",
    "2",
    "--force",
)
COMMANDS = {
    "library": (
        (
            "plan",
            "library",
            "--x0",
            "-3.5",
            "-2.5",
            "--v0",
            "1.2",
            "1.8",
            "--nodes",
            "2",
            "3",
            *LIMITS,
        ),
        "nodes",
        6,
    ),
    "robust": (
        ("plan", "robust", "--x0", "-3.9", "-3.7", "--v0", "1.8", "2.0", "--maxiter", "4", *LIMITS),
        "generations",
        4,
    ),
}


@pytest.mark.parametrize("name", COMMANDS)
def test_on_a_terminal_stderr_shows_the_bar(name, tmp_path):
    args, unit, total = COMMANDS[name]
    code, out, seen = run_on_terminal(*args, "--out", str(tmp_path / "o.json"))
    assert code == 0, seen
    bars = [b for b in seen.split("\r") if b.startswith("[")]
    assert bars and all(f"/{total} {unit}" in b for b in bars)
    assert f" 1/{total} {unit}" in bars[0] and seen.endswith("\n")
    assert (tmp_path / "o.json").exists() and out.strip()


@pytest.mark.parametrize("name", COMMANDS)
def test_elsewhere_stderr_stays_empty(name, tmp_path):
    args, _, _ = COMMANDS[name]
    done = subprocess.run(
        [sys.executable, "-m", "perchd", *args, "--out", str(tmp_path / "o.json")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0 and done.stderr == ""
    assert (tmp_path / "o.json").exists()
