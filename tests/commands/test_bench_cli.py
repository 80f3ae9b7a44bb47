import json

from perchd.cli import main
from perchd.commands.bench import percentiles_ms


def test_percentiles_are_min_median_and_nearest_rank_p99_in_ms():
    figures = percentiles_ms([0.003, 0.001, 0.002])
    assert figures == {"min_ms": 1.0, "median_ms": 2.0, "p99_ms": 3.0}


def test_bench_planner_json_reports_the_order_3_paper_optima_and_warm_replans(capsys):
    assert (
        main(["bench", "planner", "--orders", "3", "--repeat", "1", "--replans", "3", "--json"])
        == 0
    )
    rows = json.loads(capsys.readouterr().out)
    cold = [r for r in rows if r["solve"] == "cold"]
    assert sorted(round(r["duration_s"], 5) for r in cold) == [2.01475, 2.20937]
    assert all(r["min_ms"] <= r["median_ms"] <= r["p99_ms"] for r in rows)
    assert all(r["ratio"] > 1.0 for r in cold)
    warm = [r for r in rows if r["solve"] == "warm"]
    assert sorted(r["case"] for r in warm) == ["case1", "case2"]
    assert all(r["states"] == 3 and r["max_gap_to_cold_s"] < 1e-4 for r in warm)
