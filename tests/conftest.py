"""Shared by every test folder: the helpers in tests/helpers import by their module name."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import perchd  # noqa: F401  (first: it limits BLAS threads before numpy loads)
import pytest

HELPERS = Path(__file__).resolve().parent / "helpers"
if str(HELPERS) not in sys.path:
    sys.path.insert(0, str(HELPERS))


@pytest.fixture(autouse=True, scope="session")
def _vehicle_state_in_a_temporary_folder(tmp_path_factory):
    """`perchd fly` keeps each vehicle's learned hover thrust under XDG_STATE_HOME: tests
    (and the processes they start) keep theirs out of the user's home."""
    os.environ["XDG_STATE_HOME"] = str(tmp_path_factory.mktemp("xdg-state"))
