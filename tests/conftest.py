"""Shared by every test folder: the helpers in tests/helpers import by their module name."""

from __future__ import annotations

import fcntl
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

import perchd  # noqa: F401  (first: it limits BLAS threads before numpy loads)

HELPERS = Path(__file__).resolve().parent / "helpers"
if str(HELPERS) not in sys.path:
    sys.path.insert(0, str(HELPERS))

from stale import HARNESS_SAFETY, below_the_harness_limit  # noqa: E402 - a helper, path above


@pytest.fixture(autouse=True)
def _vehicle_state_in_a_temporary_folder(tmp_path_factory, monkeypatch):
    """`perchd fly` keeps what it learns of each vehicle (hover thrust, stage 1's push)
    under XDG_STATE_HOME: each test (and the processes it starts) keeps its own, out of the
    user's home and of the other tests' flights."""
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path_factory.mktemp("xdg-state")))


SOLO_LOCK = Path(tempfile.gettempdir()) / f"perchd-tests-solo-{os.getuid()}.lock"


@pytest.fixture(autouse=True)
def _solo_tests_run_alone(request) -> Iterator[None]:
    """Every test holds a shared lock and a `solo` one an exclusive lock, so across the xdist
    workers a test with a real-time bound runs with the CPU to itself: on two loaded cores
    a kill-to-LAND of 0.1 s measured the neighbours' load, not the sentinel."""
    mode = fcntl.LOCK_EX if request.node.get_closest_marker("solo") else fcntl.LOCK_SH
    with open(SOLO_LOCK, "a") as f:
        fcntl.flock(f, mode)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    """A passing test whose flights read a pose stream of this machine flew them with the
    harness's stale limit (stale.py), unless it is marked `own_stale_limit`: a flight that
    only passes while no process beside it is descheduled for 30 ms fails on a loaded CI."""
    result = yield
    tmp = getattr(item, "funcargs", {}).get("tmp_path")
    if tmp is not None and item.get_closest_marker("own_stale_limit") is None:
        short = below_the_harness_limit(tmp)
        assert not short, f"fly these with {HARNESS_SAFETY!r} (tests/helpers/stale.py): {short}"
    return result
