"""`perchd vehicle show NAME` and `perchd vehicle forget NAME`: the profile a flight of
`--vehicle NAME` wrote, under $XDG_STATE_HOME (a temporary one: tests/conftest.py)."""

from __future__ import annotations

import json

from simflight import PLANS

from perchd.cli import main
from perchd.flight.vehiclestate import profile_path

PLAN = PLANS / "case1-ipts-n3.json"


def test_a_flown_vehicle_is_shown_then_forgotten(tmp_path, capsys):
    assert (
        main(
            [
                "fly",
                str(PLAN),
                "--driver",
                "sim://",
                "--mocap",
                "sim://",
                "--vehicle",
                "lab-1",
                "--log",
                str(tmp_path / "f.jsonl"),
            ]
        )
        == 0
    )
    path = profile_path("lab-1")
    assert f"vehicle profile: {path} (none yet; written)" in capsys.readouterr().out
    assert main(["vehicle", "show", "lab-1"]) == 0
    shown = capsys.readouterr().out.splitlines()
    assert shown[:2] == [f"vehicle profile: {path}", "vehicle: lab-1"]
    assert shown[2].startswith("hover: ") and "from 1 flight(s)" in shown[2]
    assert shown[3].startswith("response: lag ")
    assert main(["vehicle", "show", "lab-1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == json.loads(path.read_text())
    assert main(["vehicle", "forget", "lab-1"]) == 0
    assert not path.exists() and f"forgot {path}" in capsys.readouterr().out
    assert main(["vehicle", "show", "lab-1"]) == 1
    assert "no profile for 'lab-1'" in capsys.readouterr().err
    assert main(["vehicle", "forget", "lab-1"]) == 0


def test_forget_leaves_a_file_that_is_not_a_profile(tmp_path, capsys):
    other = tmp_path / "notes.json"
    other.write_text('{"schema": "someone.else/1"}')
    assert main(["vehicle", "forget", "x", "--state", str(other)]) == 2
    assert "not a perchd vehicle profile" in capsys.readouterr().err
    assert other.read_text() == '{"schema": "someone.else/1"}'
