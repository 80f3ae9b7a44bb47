"""Plan files and libraries take the service's bounded regular-file rule on the
command line too, and unknown top-level keys are refused naming the key (docs/contracts.md §1)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from perchd.core.errors import PlanError
from perchd.tau import load_plan
from perchd.tau.library import load_library

ROOT = Path(__file__).resolve().parents[2]
PLANS = ROOT / "plans"


def perchd(*args, timeout=20):
    return subprocess.run(
        [sys.executable, "-m", "perchd", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


@pytest.mark.parametrize(
    "argv",
    [
        ["plan", "check", "/dev/zero"],
        ["fly", "/dev/zero", "--driver", "sim://", "--mocap", "sim://"],
        ["sim", "--campaign", "/dev/zero"],
    ],
)
def test_a_device_is_refused_at_once(argv):
    out = perchd(*argv)
    assert out.returncode == 2, out.stderr
    assert "not a regular file (a character device)" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_a_fifo_does_not_hang(tmp_path):
    fifo = tmp_path / "p.json"
    os.mkfifo(fifo)
    out = perchd("plan", "check", str(fifo), timeout=10)
    assert out.returncode == 2 and "not a regular file (a FIFO)" in out.stderr


def test_an_oversized_plan_is_refused(tmp_path):
    big = tmp_path / "big.json"
    big.write_text(" " * (1 << 20) + "{}")
    with pytest.raises(PlanError, match="byte limit"):
        load_plan(big)


def test_an_unknown_plan_key_is_named(tmp_path):
    doc = json.loads((PLANS / "case1-ipts-n3.json").read_text())
    doc["durration"] = 1.0
    (tmp_path / "p.json").write_text(json.dumps(doc))
    out = perchd("plan", "check", str(tmp_path / "p.json"))
    assert out.returncode == 2
    assert "unknown key 'durration'" in out.stderr and "allowed:" in out.stderr


def test_an_unknown_library_key_is_named(tmp_path):
    doc = json.loads((PLANS / "libraries" / "case1-ipts-n3.json").read_text())
    doc["extra"] = 1
    (tmp_path / "l.json").write_text(json.dumps(doc))
    with pytest.raises(PlanError, match="unknown key 'extra'"):
        load_library(tmp_path / "l.json")
    with pytest.raises(PlanError, match="not a regular file"):
        load_library("/dev/zero")


@pytest.mark.parametrize("path", sorted(PLANS.glob("*.json")), ids=lambda p: p.name)
def test_shipped_plans_still_load(path):
    plan = load_plan(path)
    if "certificate" in json.loads(path.read_text()):
        assert "certificate" in plan.extra


@pytest.mark.parametrize("path", sorted((PLANS / "libraries").glob("*.json")), ids=lambda p: p.name)
def test_shipped_libraries_still_load(path):
    load_library(path)


@pytest.mark.parametrize(
    "x0, says",
    [
        ("1e999", "must be finite"),
        ("NaN", "must be finite"),
        ("-" + "9" * 400, "400 digits"),
        ("true", "expected a number"),
        ("-" + "9" * 5000, "not JSON"),
    ],
)
def test_a_plan_number_of_any_size_is_one_line(tmp_path, x0, says):
    text = (PLANS / "case1-ipts-n3.json").read_text()
    doc = json.loads(text)
    (tmp_path / "p.json").write_text(
        text.replace(f'"x0": {json.dumps(doc["x0"])}', f'"x0": {x0}', 1)
    )
    out = perchd("plan", "check", str(tmp_path / "p.json"))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and says in out.stderr, out.stderr
