"""Typed, bounded driver options read from a URI's query (`?mass=0.03&arm=1`)."""

from __future__ import annotations

from urllib.parse import parse_qsl

from perchd.core.errors import UriError
from perchd.core.uri import Uri


def split_query(text: str) -> tuple[str, dict[str, str]]:
    """'udpout:h:p?a=1' -> ('udpout:h:p', {'a': '1'}); for URIs parse_uri keeps whole."""
    head, _, query = text.partition("?")
    return head, dict(parse_qsl(query, keep_blank_values=True))


def without_query(uri: Uri) -> str:
    """The URI as the vehicle library should see it (perchd's options removed)."""
    return uri.raw.partition("?")[0]


def float_param(uri: Uri, key: str, default: float | None, lo: float, hi: float,
                unit: str = "") -> float | None:
    """Read `key` as a float in [lo, hi]; a bad value is one UriError naming the key."""
    text = uri.param(key)
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        raise UriError(f"{uri.raw}: {key}={text!r} is not a number") from None
    if not lo <= value <= hi:
        raise UriError(f"{uri.raw}: {key}={value:g}{unit} is outside {lo:g}..{hi:g}{unit}")
    return value


def bool_param(uri: Uri, key: str, default: bool = False) -> bool:
    text = uri.param(key)
    if text is None:
        return default
    if text.lower() in ("1", "true", "yes", "on"):
        return True
    if text.lower() in ("0", "false", "no", "off"):
        return False
    raise UriError(f"{uri.raw}: {key}={text!r} must be 1/0, true/false, yes/no or on/off")
