"""Shared by every test folder: the helpers in tests/helpers import by their module name."""

from __future__ import annotations

import sys
from pathlib import Path

import perchd  # noqa: F401  (first: it limits BLAS threads before numpy loads)

HELPERS = Path(__file__).resolve().parent / "helpers"
if str(HELPERS) not in sys.path:
    sys.path.insert(0, str(HELPERS))
