"""benchmarks/ablation.py: each variant differs from the baseline config in exactly the
fields it names (compared field by field), its module constants are set while it flies and
restored after, and a 3-member run prints a well-formed table.
No assertion on any rate: the benchmark measures them."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import sys
from pathlib import Path

import pytest

from perchd.flight.config import FlightConfig

ROOT = Path(__file__).resolve().parents[2]


def _load():
    name = "perchd_bench_ablation"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / "ablation.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


ablation = _load()


def _leaves(cfg, prefix=()) -> dict[tuple[str, ...], object]:
    """Every leaf field of a config by its path (nested dataclasses walked)."""
    out = {}
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if dataclasses.is_dataclass(value):
            out.update(_leaves(value, prefix + (f.name,)))
        else:
            out[prefix + (f.name,)] = value
    return out


def _bases() -> list[FlightConfig]:
    plan = ablation.load_plan(ablation.PLAN)
    return [FlightConfig(), ablation._family_bench().base_config(ablation.PLAN, plan)]


@pytest.mark.parametrize("variant", ablation.VARIANTS, ids=lambda v: v.name)
def test_each_variant_changes_exactly_the_fields_it_names(variant):
    claimed = {(s, k): v for s, k, v in variant.changes}
    assert len(claimed) == len(variant.changes), "a field named twice"
    for base in _bases():
        before, after = _leaves(base), _leaves(variant.apply(base))
        assert before.keys() == after.keys()
        changed = {k: after[k] for k in before if before[k] != after[k]}
        assert changed == claimed, variant.name


def _switches(v) -> set[tuple[str, str]]:
    return {(s, k) for s, k, _ in v.changes + v.patches}


def test_every_single_layer_is_its_own_and_the_groups_are_unions_of_them():
    singles = set().union(*map(_switches, ablation.LAYERS))
    assert len(singles) == sum(len(v.changes) + len(v.patches) for v in ablation.LAYERS)
    paper = {v.name: v for v in ablation.GROUPS}["paper-only"]
    # the paper feeds the plan's acceleration forward (docs/errata.md §10): kept, lead 0
    assert _switches(paper) == singles - {("tau_gains", "feedforward")}
    for group in ablation.GROUPS:
        assert _switches(group) <= singles
    assert len({v.name for v in ablation.VARIANTS}) == len(ablation.VARIANTS)


@pytest.mark.parametrize(
    "variant", [v for v in ablation.VARIANTS if v.patches], ids=lambda v: v.name
)
def test_a_variants_constants_are_set_while_it_flies_and_restored_after(variant):
    slots = [(importlib.import_module(m), k, value) for m, k, value in variant.patches]
    before = [getattr(mod, k) for mod, k, _ in slots]
    assert all(value != was for (_, _, value), was in zip(slots, before)), "a patch changes"
    with variant.patched():
        assert [getattr(mod, k) for mod, k, _ in slots] == [value for _, _, value in slots]
    assert [getattr(mod, k) for mod, k, _ in slots] == before


def test_unknown_layers_are_refused():
    with pytest.raises(SystemExit, match="nope"):
        ablation.pick(["qdrag", "nope"])
    assert [v.name for v in ablation.pick(["qdrag"])] == ["baseline", "qdrag"]


def test_a_three_member_run_prints_a_well_formed_table(tmp_path, capsys):
    out = tmp_path / "a.json"
    assert (
        ablation.main(
            ["--n", "3", "--jobs", "1", "--layers", "qdrag", "paper-only", "--json", str(out)]
        )
        == 0
    )
    lines = capsys.readouterr().out.splitlines()
    table = [ln for ln in lines if ln.startswith("|")]
    assert table[0] == ablation.HEAD
    columns = ablation.HEAD.count(" | ") + 1
    assert [row.split(" | ")[0].lstrip("| ") for row in table[2:]] == [
        "baseline",
        "qdrag",
        "paper-only",
    ]
    for row in table:
        assert row.replace("\\|", "").count("|") == columns + 1, row
    doc = json.loads(out.read_text())
    assert doc["n"] == 3 and [v["name"] for v in doc["variants"]] == [
        "baseline",
        "qdrag",
        "paper-only",
    ]
    for v in doc["variants"]:
        s = v["summary"]
        assert s["n"] == 3 and len(v["rows"]) == 3
        assert 0.0 <= s["in_window_pct"] <= 100.0 and 0.0 <= s["on_time_pct"] <= 100.0
        assert sum(s["outcomes"].values()) == 3
        assert v["default_perch"]["outcome"]
    base = doc["variants"][0]["summary"]
    assert base["d_in_window_pp"] == 0.0 and base["se_in_window_pp"] == 0.0
