"""Shared by every test folder: the helpers in tests/helpers import by their module name."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

import perchd  # noqa: F401  (first: it limits BLAS threads before numpy loads)

HELPERS = Path(__file__).resolve().parent / "helpers"
if str(HELPERS) not in sys.path:
    sys.path.insert(0, str(HELPERS))


@pytest.fixture(autouse=True)
def _vehicle_state_in_a_temporary_folder(tmp_path_factory, monkeypatch):
    """`perchd fly` keeps what it learns of each vehicle (hover thrust, stage 1's push)
    under XDG_STATE_HOME: each test (and the processes it starts) keeps its own, out of the
    user's home and of the other tests' flights."""
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path_factory.mktemp("xdg-state")))
