"""Error types. Each subclasses a built-in and reaches the user as one line (see cli.main)."""

from __future__ import annotations


class PerchdError(Exception):
    """Base of perchd's own errors; `str(err)` is the one line the user sees."""

    exit_code = 2


class PlanError(PerchdError, ValueError):
    """A plan cannot be made, loaded or verified (infeasible constraint, bad file)."""


class ConfigError(PerchdError, ValueError):
    """A configuration file or option is invalid; the message names the key."""


class UriError(PerchdError, ValueError):
    """A driver or mocap URI is malformed or names an unknown scheme."""


class MissingExtraError(PerchdError, ImportError):
    """An optional dependency is missing; the message names the extra to install."""

    def __init__(self, module: str, extra: str) -> None:
        super().__init__(f"{module} is not installed: pip install 'perchd[{extra}]'")
        self.module = module
        self.extra = extra


class LinkError(PerchdError, ConnectionError):
    """A vehicle or mocap link could not be opened or was lost."""

    exit_code = 1
