"""Plug-in URIs (`scheme://host:port/path?key=value`) and the explicit registries built on them."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar
from urllib.parse import parse_qsl, urlsplit

from perchd.core.errors import UriError

T = TypeVar("T")


@dataclass(frozen=True)
class Uri:
    """A parsed plug-in URI; `raw` keeps the text the user gave for messages."""

    raw: str
    scheme: str
    host: str
    port: int | None
    path: str
    query: dict[str, str] = field(default_factory=dict)

    def param(self, key: str, default: str | None = None) -> str | None:
        return self.query.get(key, default)


def parse_uri(text: str) -> Uri:
    """Parse `text`; mavlink's `mavlink:udpout:HOST:PORT` form keeps its tail as `path`."""
    if ":" not in text:
        raise UriError(f"{text!r} is not a URI: expected scheme://... (e.g. sim://)")
    scheme, rest = text.split(":", 1)
    if not rest.startswith("//"):
        return Uri(text, scheme.lower(), "", None, rest, {})
    try:
        parts = urlsplit(text)
    except ValueError as err:  # e.g. an unclosed [IPv6 bracket
        raise UriError(f"{text!r} is not a URI ({err})") from None
    try:
        port = parts.port
    except ValueError as err:
        raise UriError(f"{text!r}: bad port ({err})") from None
    query = dict(parse_qsl(parts.query, keep_blank_values=True))
    return Uri(text, parts.scheme.lower(), parts.hostname or "", port, parts.path, query)


class Registry(Generic[T]):
    """Scheme -> factory, imported lazily from 'module:function' so optional libraries load
    only when their scheme is used. Every factory is called as factory(uri, runtime)."""

    def __init__(self, kind: str, entries: dict[str, str]) -> None:
        self.kind = kind
        self._entries = dict(entries)

    @property
    def schemes(self) -> list[str]:
        return sorted(self._entries)

    def factory(self, scheme: str) -> Callable[..., T]:
        target = self._entries.get(scheme)
        if target is None:
            known = ", ".join(f"{s}://" for s in self.schemes)
            raise UriError(f"unknown {self.kind} scheme {scheme!r}: use one of {known}")
        module, name = target.split(":")
        factory: Callable[..., T] = getattr(importlib.import_module(module), name)
        return factory

    def open(self, text: str, runtime: Any) -> T:
        uri = parse_uri(text)
        factory = self.factory(uri.scheme)
        from perchd.core.uriparams import check_params  # imports this module

        check_params(self.kind, uri)  # a misspelt key is refused, not ignored (contracts §7)
        return factory(uri, runtime)
