"""Import optional dependencies on demand, naming the extra that provides them."""

from __future__ import annotations

import importlib
from types import ModuleType

from perchd.core.errors import MissingExtraError


def require(module: str, extra: str) -> ModuleType:
    """Import `module`, or raise MissingExtraError telling which perchd extra installs it."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        top = module.split(".")[0]
        if err.name is not None and err.name.split(".")[0] != top:
            raise  # the library is there but broken: show the real cause
        raise MissingExtraError(top, extra) from err
