import json

from perchd.cli import main
from perchd.commands.bench import percentiles_ms


def test_percentiles_are_min_median_and_nearest_rank_p99_in_ms():
    figures = percentiles_ms([0.003, 0.001, 0.002])
    assert figures == {"min_ms": 1.0, "median_ms": 2.0, "p99_ms": 3.0}


def test_bench_planner_json_reports_the_order_3_paper_optima(capsys):
    assert main(["bench", "planner", "--orders", "3", "--repeat", "1", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    durations = {r["case"]: r["duration_s"] for r in rows}
    assert sorted(round(d, 5) for d in durations.values()) == [2.01475, 2.20937]
    assert all(r["min_ms"] <= r["median_ms"] <= r["p99_ms"] for r in rows)
    assert all(r["ratio"] > 1.0 for r in rows)
