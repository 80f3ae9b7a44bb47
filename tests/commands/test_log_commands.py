"""`perchd log summary` and `perchd log plot` on the log of a simulated flight."""

import json
import math
import statistics
import subprocess
import sys

import pytest
from svc import PLAN, perchd


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    """One simulated perch (20 ms latency, 1 mm noise): its log and `fly --json` object."""
    log = tmp_path_factory.mktemp("log") / "f.jsonl"
    driver, mocap = "sim://?latency=0.02", "sim://?noise=0.001"
    done = perchd(
        "fly", str(PLAN), "--driver", driver, "--mocap", mocap, "--log", str(log), "--json"
    )
    return log, json.loads(done.stdout)


def summary(log):
    done = perchd("log", "summary", str(log), "--json")
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_the_summary_agrees_with_the_flight_and_rederives_tau_rms_and_jitter(flown):
    log, fly = flown
    s = summary(log)
    assert s["outcome"] == fly["outcome"] == "CONTACT"
    assert s["contact_speed"] == pytest.approx(fly["contact_speed"])
    assert s["perch_time"] == pytest.approx(fly["perch_time"])
    assert s["plan_duration"] == pytest.approx(fly["plan_duration"])
    rows = [json.loads(line)["row"] for line in log.read_text().splitlines() if '"row"' in line]
    tracked = [
        r["tau"] - r["tau_ref"]
        for r in rows
        if r["phase"] in ("stage1", "stage2") and r["tau"] is not None and r["tau_ref"] is not None
    ]
    assert s["tau_rows"] == len(tracked) > 100
    assert s["tau_rms"] == pytest.approx(math.sqrt(statistics.fmean(e * e for e in tracked)))
    assert 0 < s["tau_rms"] < 0.1
    assert s["ticks"] == len(rows) == fly["loop"]["ticks"]
    # the default loop ticks on each frame of the simulator's 120 Hz mocap
    assert s["period"]["median"] == pytest.approx(1 / 120)
    assert s["jitter"]["max"] == max(r["jitter_s"] for r in rows[1:])


def test_the_text_summary_names_every_figure(flown):
    text = perchd("log", "summary", str(flown[0])).stdout
    for label in (
        "outcome: CONTACT",
        "contact speed:",
        "perch time:",
        "(plan 2.015 s, error",
        "tau tracking RMS:",
        "loop jitter: median",
    ):
        assert label in text


def test_a_log_cut_short_is_summarised_as_incomplete(flown, tmp_path):
    lines = flown[0].read_text().splitlines(keepends=True)
    contact = next(i for i, line in enumerate(lines) if '"kind":"contact"' in line)
    cut = tmp_path / "cut.jsonl"
    cut.write_text("".join(lines[: contact + 3]) + lines[contact + 3][:20])  # torn last line
    s = summary(cut)
    assert s["outcome"] == "INCOMPLETE" and s["contact_speed"] == pytest.approx(
        flown[1]["contact_speed"]
    )
    # from event tick times: trigger and contact are each interpolated within about a tick
    assert abs(s["perch_time"] - flown[1]["perch_time"]) < 0.03


def test_the_plot_is_a_png_of_three_rows(flown, tmp_path):
    out = tmp_path / "f.png"
    done = perchd("log", "plot", str(flown[0]), "--out", str(out))
    assert done.returncode == 0, done.stderr
    from matplotlib.image import imread

    img = imread(out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and img.shape[0] > img.shape[1]


def test_plotting_without_matplotlib_names_the_extra_and_summary_never_imports_it(flown, tmp_path):
    code = (
        "import sys; sys.modules['matplotlib'] = None; from perchd.cli import main; "
        f"sys.exit(main(['log', 'plot', {str(flown[0])!r}, '--out', {str(tmp_path / 'x.png')!r}]))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert (
        done.returncode == 2
        and "plot" in done.stderr
        and len(done.stderr.strip().splitlines()) == 1
    )
    code = (
        "import sys; from perchd.cli import main; main(['log', 'summary', "
        f"{str(flown[0])!r}]); assert 'matplotlib' not in sys.modules"
    )
    assert subprocess.run([sys.executable, "-c", code], capture_output=True).returncode == 0


def test_a_missing_log_is_one_line_and_exit_2(tmp_path):
    done = perchd("log", "summary", str(tmp_path / "none.jsonl"))
    assert done.returncode == 2 and done.stderr.strip().endswith(
        "cannot read (No such file or directory)"
    )
