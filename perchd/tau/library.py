"""Plan libraries (schema perchd.planlib/1): minimum-time IPTS plans precomputed over a grid
of trigger states, from which the plan for a measured trigger state is one warm-started
local solve (a few ms) instead of a cold global search (tens of ms to a second).

Warm start: the scaled variables z = (m_1..m_n, t_s) (perchd.tau.ipts) of the grid cell's
four corners are blended bilinearly (the nearest feasible node where a corner has no plan),
then SLSQP runs once from there and the result is verified densely, exactly as a cold plan.
Near a node the global optimum moves smoothly with (x0, v0), so the blend starts inside its
basin; tests compare warm against cold solves across the grid. A state outside the grid is
refused, naming the axis and by how much: a library does not extrapolate.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from perchd.core.errors import PlanError
from perchd.core.safefile import write_text
from perchd.tau.ipts import MAX_ORDER, plan_ipts, plan_ipts_from
from perchd.tau.limits import Limits
from perchd.tau.plan import Plan, given
from perchd.tau.planfile import load_json

SCHEMA = "perchd.planlib/1"
SWITCH_TOL = 1e-6  # |q(t_s) - 1/tau_s| * |tau_s| a stored node may be off by (round-off)


@dataclass(frozen=True)
class Node:
    """The minimum-time plan at one grid state: k_0..k_n and its switch time t_switch [s]."""

    k: tuple[float, ...]
    t_switch: float

    def z(self) -> list[float]:
        """Scaled variables (m_1..m_n, t_s): m_i = k_i t_s^i, smooth across the grid."""
        return [ki * self.t_switch**i for i, ki in enumerate(self.k)][1:] + [self.t_switch]


@dataclass(frozen=True)
class PlanLibrary:
    """IPTS plans of one order and one set of limits over the grid x0s [m] x v0s [m/s];
    nodes[i][j] is the plan at (x0s[i], v0s[j]), None where no plan meets the limits."""

    order: int
    tau_s: float
    limits: Limits
    x0s: tuple[float, ...]
    v0s: tuple[float, ...]
    nodes: tuple[tuple[Node | None, ...], ...]

    def replan(self, x0: float, v0: float) -> Plan:
        """The minimum-time plan from the measured trigger state (x0 [m], v0 [m/s])."""

        i, fx = _cell(self.x0s, x0, "x0", "m")
        j, fv = _cell(self.v0s, v0, "v0", "m/s")
        lim = self.limits
        for z in self._starts(i, j, fx, fv):
            ts = z[-1]
            k = [v0 / x0] + [mi / ts**n for n, mi in enumerate(z[:-1], start=1)]
            plan = plan_ipts_from(x0, v0, self.tau_s, lim.v_contact, lim.v_max, lim.a_max, k, ts)
            if plan is not None:
                return plan
        raise PlanError(
            f"no warm replan from x0 = {x0:g} m, v0 = {v0:g} m/s converged to a "
            f"plan meeting the limits (library cell without plans?)"
        )

    def matches(self, plan: Plan) -> str:
        """Why this library cannot replan `plan` (its strategy, order or limits), or ''."""
        if plan.strategy != "ipts" or plan.order != self.order:
            return (
                f"the library holds IPTS order {self.order} plans, the plan is "
                f"{plan.strategy}{'' if plan.order is None else f' order {plan.order}'}"
            )
        if plan.tau_s != self.tau_s or plan.limits != self.limits:
            return "the library was made for other limits or tau_s than the plan's"
        return ""

    def _starts(self, i: int, j: int, fx: float, fv: float) -> list[list[float]]:
        """Warm starts, best first: the bilinear blend of the cell's corners (when all four
        have plans), then each corner's own optimum, nearest first."""
        corners = [
            (self.nodes[i + a][j + b], (fx if a else 1 - fx) * (fv if b else 1 - fv))
            for a in (0, 1)
            for b in (0, 1)
        ]
        known = sorted(((n, w) for n, w in corners if n is not None), key=lambda nw: -nw[1])
        starts = [n.z() for n, _ in known]
        if len(known) == 4:
            zs = [(n.z(), w) for n, w in known]
            starts.insert(0, [sum(z[q] * w for z, w in zs) for q in range(len(zs[0][0]))])
        return starts


def _cell(grid: tuple[float, ...], value: float, name: str, unit: str) -> tuple[int, float]:
    """Index of the grid cell holding value, and value's fraction across it."""
    lo, hi = grid[0], grid[-1]
    if not lo <= value <= hi:
        by = lo - value if value < lo else value - hi
        raise PlanError(
            f"{name} = {value:g} {unit} is outside the library's grid "
            f"{lo:g}..{hi:g} {unit} by {by:.4g} {unit}"
        )
    i = min(max(0, next(n for n, g in enumerate(grid) if g >= value) - 1), len(grid) - 2)
    return i, (value - grid[i]) / (grid[i + 1] - grid[i])


def build_library(
    x0: tuple[float, float],
    v0: tuple[float, float],
    counts: tuple[int, int],
    tau_s: float,
    v_contact: tuple[float, float],
    v_max: float | None,
    a_max: float | None,
    order: int,
    progress: Callable[[int, int], None] | None = None,
) -> PlanLibrary:
    """Cold-solve the global minimum-time plan at every node of the grid (x0 [m], v0 [m/s]
    ranges with counts[0] x counts[1] nodes). progress(done, total) is called per node."""

    if not 1 <= order <= MAX_ORDER:
        raise PlanError(f"order must be 1..{MAX_ORDER}, got {order}")
    lo, hi = v_contact
    limits = Limits((lo, hi), v_max, a_max)
    x0s, v0s = _axis(x0, counts[0], "x0"), _axis(v0, counts[1], "v0")
    rows: list[tuple[Node | None, ...]] = []
    first_refusal = ""
    for i, x in enumerate(x0s):
        row: list[Node | None] = []
        for j, v in enumerate(v0s):
            try:
                plan = plan_ipts(
                    x, v, tau_s, v_contact, v_max, a_max, order, probe_orders=False
                )  # a hole needs no order advice
                row.append(Node(tuple(given(plan.k, "stage1.k")), plan.t_switch))
            except PlanError as err:  # infeasible here; the file records the hole
                row.append(None)
                first_refusal = first_refusal or f"at x0 = {x:g} m, v0 = {v:g} m/s: {err}"
            if progress is not None:
                progress(i * len(v0s) + j + 1, len(x0s) * len(v0s))
        rows.append(tuple(row))
    if all(node is None for row in rows for node in row):
        raise PlanError(f"no node of the grid has a plan; {first_refusal}")
    return PlanLibrary(order, tau_s, limits, x0s, v0s, tuple(rows))


def _axis(span: tuple[float, float], count: int, name: str) -> tuple[float, ...]:
    lo, hi = span
    if not (count >= 2 and math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise PlanError(
            f"library {name} grid needs LO < HI and at least 2 nodes, "
            f"got {lo:g}..{hi:g} with {count}"
        )
    return tuple(lo + (hi - lo) * n / (count - 1) for n in range(count))


# -- files ------------------------------------------------------------------------------------
def library_to_json(lib: PlanLibrary) -> dict[str, object]:
    return {
        "schema": SCHEMA,
        "strategy": "ipts",
        "order": lib.order,
        "tau_s": lib.tau_s,
        "limits": lib.limits.to_json(),
        "x0": list(lib.x0s),
        "v0": list(lib.v0s),
        "nodes": [
            [None if n is None else {"k": list(n.k), "t_switch": n.t_switch} for n in row]
            for row in lib.nodes
        ],
    }


def library_text(lib: PlanLibrary) -> str:
    return json.dumps(library_to_json(lib)) + "\n"


def save_library(lib: PlanLibrary, path: str | Path, force: bool = True) -> None:
    """`lib` written to `path` by the one rule (core/safefile.py write_atomic)."""
    write_text(Path(path), library_text(lib), "library", force)


def load_library(path: str | Path) -> PlanLibrary:
    """The library in `path`, every node checked; errors name the field."""

    return load_json(path, library_from_json, "plan library")


KEYS = {"schema", "strategy", "order", "tau_s", "limits", "x0", "v0", "nodes"}


def library_from_json(doc: object) -> PlanLibrary:
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
        raise PlanError(f"schema must be {SCHEMA!r}")
    if doc.get("strategy") != "ipts":
        raise PlanError("strategy must be 'ipts'")
    unknown = sorted(doc.keys() - KEYS, key=str)
    if unknown:  # as plan files and the config: a misspelt key is refused
        raise PlanError(f"unknown key {unknown[0]!r} (allowed: {', '.join(sorted(KEYS))})")
    order, tau_s = doc.get("order"), _finite(doc.get("tau_s"), "tau_s")

    if not (isinstance(order, int) and 1 <= order <= MAX_ORDER):
        raise PlanError(f"order must be an integer 1..{MAX_ORDER}, got {order!r}")
    lim = doc.get("limits")
    if not isinstance(lim, dict):
        raise PlanError("limits must be an object")
    lo, hi = (
        _finite(v, "limits.v_contact") for v in _list(lim.get("v_contact"), 2, "limits.v_contact")
    )
    limits = Limits(
        (lo, hi),
        _optional(lim.get("v_max"), "limits.v_max"),
        _optional(lim.get("a_max"), "limits.a_max"),
    )
    x0s, v0s = _grid_axis(doc.get("x0"), "x0"), _grid_axis(doc.get("v0"), "v0")
    rows = _list(doc.get("nodes"), len(x0s), "nodes")
    nodes = tuple(
        tuple(
            _node(cell, order, tau_s, x0s[i], v0s[j], f"nodes[{i}][{j}]")
            for j, cell in enumerate(_list(row, len(v0s), f"nodes[{i}]"))
        )
        for i, row in enumerate(rows)
    )
    return PlanLibrary(order, tau_s, limits, x0s, v0s, nodes)


def _node(cell: object, order: int, tau_s: float, x0: float, v0: float, name: str) -> Node | None:
    if cell is None:
        return None
    if not isinstance(cell, dict):
        raise PlanError(f"{name} must be an object or null")
    k = tuple(_finite(v, f"{name}.k") for v in _list(cell.get("k"), order + 1, f"{name}.k"))
    ts = _finite(cell.get("t_switch"), f"{name}.t_switch")
    if not (ts > 0 and math.isclose(k[0], v0 / x0, rel_tol=1e-9)):
        raise PlanError(f"{name}: k_0 must be v0/x0 = {v0 / x0:g} and t_switch > 0")
    reached = sum(ki * ts**n for n, ki in enumerate(k))
    if abs(reached * tau_s - 1.0) > SWITCH_TOL:
        raise PlanError(f"{name}: tau(t_switch) = {1 / reached:g} s, not tau_s = {tau_s:g} s")
    return Node(k, ts)


def _grid_axis(value: object, name: str) -> tuple[float, ...]:
    grid = tuple(_finite(v, name) for v in _list(value, None, name))
    if len(grid) < 2 or any(b <= a for a, b in zip(grid, grid[1:])):
        raise PlanError(f"{name} must list at least 2 increasing grid values")
    return grid


def _list(value: object, length: int | None, name: str) -> list[object]:
    if not isinstance(value, list) or (length is not None and len(value) != length):
        want = "a list" if length is None else f"a list of {length}"
        raise PlanError(f"{name} must be {want}")
    return value


def _finite(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise PlanError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _optional(value: object, name: str) -> float | None:
    return None if value is None else _finite(value, name)
