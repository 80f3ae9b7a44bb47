"""Plan files (docs/contracts.md §1, schema perchd.plan/1): save, and load with every figure re-derived.

A file's stored figures (t_switch, duration, v_contact, peaks) must agree with what its
parameters imply, so a tampered, stale or hand-edited plan is refused naming the field.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from perchd.core.errors import PlanError
from perchd.core.safefile import read_regular, write_text
from perchd.tau.figures import disagreement
from perchd.tau.ipts import MAX_ORDER
from perchd.tau.limits import Limits
from perchd.tau.plan import STRATEGIES, Plan, RobustBox, given, make_plan

SCHEMA = "perchd.plan/1"
T = TypeVar("T")


def plan_to_json(plan: Plan) -> dict[str, Any]:
    stage1: dict[str, Any] = (
        {"c": plan.c}
        if plan.strategy in ("ctds", "ctdts")
        else {"k": list(given(plan.k, "stage1.k"))}
    )
    doc: dict[str, Any] = {
        "schema": SCHEMA,
        "strategy": plan.strategy,
        "x0": plan.x0,
        "v0": plan.v0,
        "tau_s": plan.tau_s,
        "stage1": stage1,
        "t_switch": plan.t_switch,
        "duration": plan.duration,
        "v_contact": plan.v_contact,
        "limits": plan.limits.to_json(),
        "peaks": {"v": plan.peaks.v, "a": plan.peaks.a},
    }
    if plan.robust is not None:
        doc["robust"] = {"x0": list(plan.robust[0]), "v0": list(plan.robust[1])}
    doc.update(plan.extra)
    return doc


def plan_text(plan: Plan) -> str:
    return json.dumps(plan_to_json(plan), indent=2) + "\n"


def save_plan(plan: Plan, path: str | Path, force: bool = True) -> None:
    """`plan` written to `path` by the one rule (core/safefile.py write_atomic); replacing
    a file by default: the callers (the shipped cases, a benchmark) own their paths."""
    write_text(Path(path), plan_text(plan), "plan", force)


def load_plan(path: str | Path, text: str | None = None) -> Plan:
    """The plan in file `path`; `text`: its contents when the caller has read them already
    (the service reads plans through perchd.core.safefile)."""
    return load_json(path, plan_from_json, "plan file", text)


def load_json(
    path: str | Path, parse: Callable[[object], T], what: str, text: str | None = None
) -> T:
    """parse(JSON document of file `path`), every error one PlanError naming the file."""
    if text is None:  # one bounded regular-file rule for the CLI and the service
        text = read_regular(path, "", PlanError)  # "PATH: why", as below
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as err:
        raise PlanError(f"{path}: not JSON ({err.msg} at line {err.lineno})") from None
    except ValueError as err:  # an integer of more digits than Python converts
        raise PlanError(f"{path}: not JSON ({err})") from None
    except RecursionError:
        raise PlanError(f"{path}: not JSON (nested too deeply)") from None
    try:
        return parse(doc)
    except PlanError as err:
        raise PlanError(f"{path}: {err}") from None


def plan_from_json(doc: object) -> Plan:
    if not isinstance(doc, dict):
        raise PlanError("a plan file holds one JSON object")
    if doc.get("schema") != SCHEMA:
        raise PlanError(f"schema: expected {SCHEMA!r}, got {doc.get('schema')!r}")
    _known_keys(doc)
    strategy = doc.get("strategy")
    if strategy not in STRATEGIES:
        raise PlanError(f"strategy: expected one of {', '.join(STRATEGIES)}, got {strategy!r}")
    stage1 = _field(doc, "stage1", dict)
    c = _number(stage1, "c", "stage1.c") if strategy != "ipts" else None
    k = _numbers(stage1, "k", "stage1.k") if strategy == "ipts" else None
    tau_s = None if strategy == "ctds" else _number(doc, "tau_s")
    plan = make_plan(
        strategy,
        _number(doc, "x0"),
        _number(doc, "v0"),
        tau_s,
        _limits(doc),
        c=c,
        k=k,
        robust=_robust(doc),
    )
    _agree(doc, plan)
    extra = {key: doc[key] for key in doc.keys() & OPTIONAL_EXTRA}
    return Plan(**{**plan.__dict__, "extra": extra}) if extra else plan


KNOWN = {
    "schema",
    "strategy",
    "x0",
    "v0",
    "tau_s",
    "stage1",
    "t_switch",
    "duration",
    "v_contact",
    "limits",
    "peaks",
    "robust",
}
OPTIONAL_EXTRA = {"certificate"}
"""Documented keys carried through unchecked (docs/contracts.md §1)."""


def _known_keys(doc: dict[str, Any]) -> None:
    """Refuse unknown top-level keys, as the config loader does: a misspelt key is a mistake."""
    unknown = sorted(doc.keys() - KNOWN - OPTIONAL_EXTRA, key=str)
    if unknown:
        allowed = ", ".join(sorted(KNOWN | OPTIONAL_EXTRA))
        raise PlanError(f"unknown key {unknown[0]!r} (allowed: {allowed})")


def _agree(doc: dict[str, Any], plan: Plan) -> None:
    peaks = _field(doc, "peaks", dict)
    stored = {name: _number(doc, name) for name in ("t_switch", "duration", "v_contact")}
    stored |= {f"peaks.{k}": _number(peaks, k, f"peaks.{k}") for k in ("v", "a")}
    why = disagreement(stored, plan)
    if why is not None:
        raise PlanError(why)


def _field(
    doc: dict[str, Any], key: str, kind: type | tuple[type, ...], name: str | None = None
) -> Any:
    if key not in doc:
        raise PlanError(f"{name or key}: missing")
    value = doc[key]
    if not isinstance(value, kind) or isinstance(value, bool):
        expected = "a number" if isinstance(kind, tuple) else f"a JSON {kind.__name__}"
        raise PlanError(f"{name or key}: expected {expected}, got {value!r}")
    return value


def _number(doc: dict[str, Any], key: str, name: str | None = None) -> float:
    value = _field(doc, key, (int, float), name or key)
    if isinstance(value, int) and abs(value) >= 1e308:  # beyond a float
        raise PlanError(
            f"{name or key}: must be finite, got an integer of {len(str(abs(value)))} digits"
        )
    if not math.isfinite(value):
        raise PlanError(f"{name or key}: must be finite, got {value!r}")
    return float(value)


def _numbers(doc: dict[str, Any], key: str, name: str) -> list[float]:

    values = _field(doc, key, list, name)
    if not 2 <= len(values) <= MAX_ORDER + 1:
        raise PlanError(
            f"{name}: expected 2..{MAX_ORDER + 1} coefficients k_0..k_n, got {len(values)}"
        )
    return [_number({"v": v}, "v", f"{name}[{i}]") for i, v in enumerate(values)]


def _limits(doc: dict[str, Any]) -> Limits:
    lim = _field(doc, "limits", dict)
    pair = _numbers_pair(lim, "v_contact", "limits.v_contact")
    optional = {
        k: None if lim.get(k) is None else _number(lim, k, f"limits.{k}")
        for k in ("v_max", "a_max")
    }
    return Limits(pair, **optional)


def _numbers_pair(doc: dict[str, Any], key: str, name: str) -> tuple[float, float]:
    values = _field(doc, key, list, name)
    if len(values) != 2:
        raise PlanError(f"{name}: expected [low, high], got {values!r}")
    lo, hi = (_number({"v": v}, "v", f"{name}[{i}]") for i, v in enumerate(values))
    return lo, hi


def _robust(doc: dict[str, Any]) -> RobustBox | None:
    if doc.get("robust") is None:
        return None
    box = _field(doc, "robust", dict)
    pairs = (_numbers_pair(box, "x0", "robust.x0"), _numbers_pair(box, "v0", "robust.v0"))
    for key, (lo, hi) in zip(("x0", "v0"), pairs):
        if lo > hi:
            raise PlanError(f"robust.{key}: low {lo:g} above high {hi:g}")
    return pairs
