"""Plan files (docs/contracts.md §1) under fuzzing: whatever bytes or JSON a file holds, loading it
either gives a plan whose figures are finite and consistent, or one PlanError; never any
other exception."""

from __future__ import annotations

import json
import math
from pathlib import Path

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from mutate import json_values, mutated_bytes, mutated_document

from perchd.core.errors import PlanError
from perchd.tau.planfile import load_plan, plan_from_json, plan_to_json

PLANS = sorted((Path(__file__).resolve().parents[2] / "plans").glob("*.json"))
TEXTS = [p.read_bytes() for p in PLANS]
DOCS = [json.loads(t) for t in TEXTS]
FAST = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])


def load_or_refuse(doc):
    """plan_from_json's verdict: the Plan, or None for a PlanError; anything else propagates."""
    try:
        plan = plan_from_json(doc)
    except PlanError as err:
        assert str(err), "a refusal says why"
        return None
    figures = (
        plan.x0,
        plan.v0,
        plan.t_switch,
        plan.duration,
        plan.v_contact,
        plan.peaks.v,
        plan.peaks.a,
    )
    assert all(math.isfinite(v) for v in figures), figures
    assert plan.x0 < 0 < plan.v0 and plan.duration > 0
    assert plan_from_json(plan_to_json(plan)) == plan  # what loads, saves and loads the same
    return plan


def test_every_shipped_plan_loads():
    assert len(DOCS) >= 10 and all(load_or_refuse(doc) is not None for doc in DOCS)


@FAST
@given(st.sampled_from(DOCS).flatmap(mutated_document))
def test_a_mutated_plan_document_loads_or_is_refused_with_a_plan_error(doc):
    event("loaded" if load_or_refuse(doc) else "refused")


@FAST
@given(json_values)
def test_any_json_value_loads_or_is_refused_with_a_plan_error(doc):
    event("loaded" if load_or_refuse(doc) else "refused")


@FAST
@given(st.one_of(mutated_bytes(TEXTS), st.binary(max_size=400)))
def test_any_bytes_in_a_plan_file_load_or_are_refused_with_one_plan_error(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("plan") / "p.json"
    path.write_bytes(data)
    try:
        load_plan(path)
    except PlanError as err:
        assert str(err).startswith(str(path))


def test_deeply_nested_json_is_a_plan_error_not_a_recursion_error(tmp_path):
    path = tmp_path / "deep.json"
    path.write_text("[" * 100_000)
    try:
        load_plan(path)
    except PlanError as err:
        assert "nested too deeply" in str(err)
    else:
        raise AssertionError("a deeply nested file loaded")


def test_a_tau_dot_of_zero_or_below_is_a_plan_error_not_a_division_by_zero():
    # found by the mutation test above: stage1.c = 0 raised ZeroDivisionError
    for strategy, c in (("ctds", 0.0), ("ctdts", 0.0), ("ctdts", -0.5)):
        doc = {**next(d for d in DOCS if d["strategy"] == strategy), "stage1": {"c": c}}
        try:
            plan_from_json(doc)
        except PlanError as err:
            assert (
                str(err)
                == f"stage1.c must be a positive tau-dot (with c <= 0 the vehicle never arrives), got {c!r}"
            )
        else:
            raise AssertionError(f"{strategy} with c = {c} loaded")
