"""One control-socket request line (docs/contracts.md §4) parsed, or refused in one sentence.

json.loads only (never eval or unpickle). A key given twice in any object is refused rather
than letting the last one win silently: `{"cmd": "status", "cmd": "fly"}` must not mean
whichever the parser happens to keep.
"""

from __future__ import annotations

import json
from typing import Any


class BadRequest(ValueError):
    """A line that is not one request; str() is the one sentence the client is sent."""


def parse_request(line: bytes) -> dict[str, Any]:
    """The request object of one line (without its newline); BadRequest otherwise."""
    try:
        req = json.loads(line.decode("utf-8"), object_pairs_hook=_unique_keys)
    except BadRequest:
        raise
    except (UnicodeDecodeError, ValueError) as err:
        raise BadRequest(f"malformed request, not one JSON object: {err}") from None
    except RecursionError:  # json.loads of "[[[[..." recurses per level
        raise BadRequest("malformed request, not one JSON object: nested too deeply") from None
    if not isinstance(req, dict) or not isinstance(req.get("cmd"), str):
        raise BadRequest('a request is a JSON object with a "cmd" string')
    return req


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    obj = dict(pairs)
    if len(obj) != len(pairs):
        seen: set[str] = set()
        twice = next(k for k, _ in pairs if k in seen or seen.add(k))
        raise BadRequest(f"malformed request: key {twice[:40]!r} given twice")
    return obj
