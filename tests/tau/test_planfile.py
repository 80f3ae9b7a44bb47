"""Plan files: a round trip, the committed plans regenerate, and bad files are named."""

import json
from pathlib import Path

import pytest

from perchd.core.errors import PlanError
from perchd.tau import load_plan, plan_ctdts, plan_to_json, save_plan
from perchd.tau.cases import CASES, FILES, make

PLANS = Path(__file__).resolve().parents[2] / "plans"


def test_a_saved_plan_loads_back_equal(tmp_path):
    plan = plan_ctdts(-3, 1.5, -0.5, 1.0, 1.4)
    save_plan(plan, tmp_path / "p.json")
    assert load_plan(tmp_path / "p.json") == plan


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
@pytest.mark.parametrize("kind", FILES)
def test_every_committed_plan_regenerates(case, kind):
    committed = load_plan(PLANS / f"{case.name}-{kind}.json")
    fresh = make(case, kind)
    assert fresh.duration == pytest.approx(committed.duration, abs=1e-6)
    assert fresh.v_contact == pytest.approx(committed.v_contact, abs=1e-6)


def _doc():
    return plan_to_json(plan_ctdts(-3, 1.5, -0.5, 1.0, 1.4))


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda d: d.update(duration=2.0), "duration"),
        (lambda d: d["peaks"].update(a=1.0), "peaks.a"),
        (lambda d: d.update(schema="perchd.plan/9"), "schema"),
        (lambda d: d.update(strategy="magic"), "strategy"),
        (lambda d: d.pop("x0"), "x0"),
        (lambda d: d.update(v0="fast"), "v0"),
        (lambda d: d["stage1"].update(c=float("nan")), "stage1.c"),
        (lambda d: d["limits"].update(v_contact=[1.0]), "limits.v_contact"),
        (lambda d: d.update(x0=3.0), "x0"),
    ],
)
def test_a_tampered_or_malformed_file_is_refused_naming_the_field(tmp_path, edit, field):
    doc = _doc()
    edit(doc)
    (tmp_path / "p.json").write_text(json.dumps(doc))
    with pytest.raises(PlanError, match=field.replace(".", r"\.")):
        load_plan(tmp_path / "p.json")


def test_a_file_that_is_not_json_says_where(tmp_path):
    (tmp_path / "p.json").write_text("{oops")
    with pytest.raises(PlanError, match="not JSON"):
        load_plan(tmp_path / "p.json")
