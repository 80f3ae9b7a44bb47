"""`perchd log export F --mcap OUT`: a simulated flight's log read back through mcap's own
reader, every value compared with the JSON lines (docs/contracts.md §5)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from simflight import NOISY, Sim, case1

from perchd.cli import main
from perchd.core.errors import MissingExtraError
from perchd.logs.flightlog import LogRow, read_log
from perchd.logs.mcapexport import EVENTS, FLIGHT, PHASE, ROW_STREAMS, TOPICS

make_reader = pytest.importorskip("mcap.reader").make_reader
ROW_FIELDS = LogRow.__dataclass_fields__


@pytest.fixture(scope="module")
def flown(tmp_path_factory) -> Path:
    """A real log: one simulated perch (20 ms latency, 1 mm noise), flown in-process."""
    log = tmp_path_factory.mktemp("flight") / "f.jsonl"
    assert Sim(NOISY).fly(case1("ipts"), log).outcome.name == "CONTACT"
    return log


def lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def read_mcap(path: Path) -> dict[str, list[tuple[int, int, dict]]]:
    """topic -> [(log_time, sequence, decoded JSON)] in the file's log-time order; checks
    every channel is JSON with a JSON Schema."""
    out: dict[str, list] = {t: [] for t in TOPICS}
    with open(path, "rb") as f:
        for schema, channel, msg in make_reader(f).iter_messages():
            assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
            assert json.loads(schema.data)["type"] == "object"
            assert msg.publish_time == msg.log_time
            out[channel.topic].append((msg.log_time, msg.sequence, json.loads(msg.data)))
    return out


def export(log: Path, out: Path, *more: str) -> int:
    return main(["log", "export", str(log), "--mcap", str(out), *more])


def ns(t: float) -> int:
    return round(t * 1e9)


def test_every_row_and_event_is_on_its_channel_at_its_clock_time(flown, tmp_path, capsys):
    assert export(flown, tmp_path / "f.mcap") == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "f.mcap")
    got = read_mcap(tmp_path / "f.mcap")
    objs = lines(flown)
    rows = [o["row"] for o in objs if "row" in o]
    events = [o["event"] for o in objs if "event" in o]
    assert len(rows) > 400 and any(v is None for r in rows for v in r.values())

    covered = {"phase"}  # on /perchd/phase, as changes
    for stream in ROW_STREAMS:
        msgs = got[stream.topic]
        assert [m[1] for m in msgs] == list(range(len(rows)))  # sequence: the row's place
        assert [m[0] for m in msgs] == [ns(r["t"]) for r in rows]  # monotonic: rows' t
        assert [m[2] for m in msgs] == [{k: r[k] for k in stream.fields} for r in rows]
        covered |= set(stream.fields)
    assert covered == set(ROW_FIELDS)  # every row value is exported somewhere

    changes = [
        (ns(r["t"]), r["phase"])
        for i, r in enumerate(rows)
        if i == 0 or rows[i - 1]["phase"] != r["phase"]
    ]
    assert [(m[0], m[2]["phase"]) for m in got[PHASE]] == changes
    assert [m[2]["previous"] for m in got[PHASE]] == [None] + [p for _, p in changes[:-1]]
    assert {"stage1", "stage2", "contact"} <= {p for _, p in changes}

    assert [m[2] for m in got[EVENTS]] == events
    assert [m[0] for m in got[EVENTS]] == [ns(e["t"]) for e in events]
    assert {"stage1", "contact"} <= {e["kind"] for e in events}

    ((t0, _, flight),) = got[FLIGHT]
    assert flight == {"header": objs[0], "end": objs[-1]["end"], "complete": True}
    assert t0 == ns(rows[0]["t"])
    every = sorted(m[0] for msgs in got.values() for m in msgs)
    with open(tmp_path / "f.mcap", "rb") as f:  # the file's own order is by log time
        assert [
            m.log_time for _, _, m in make_reader(f).iter_messages(log_time_order=False)
        ] == every


def test_a_log_cut_short_exports_what_it_has_and_says_so(flown, tmp_path, capsys):
    text = flown.read_text().splitlines(keepends=True)
    cut = tmp_path / "cut.jsonl"
    cut.write_text("".join(text[:200]) + text[200][:25])  # torn, no end line
    assert export(cut, tmp_path / "cut.mcap") == 0
    err = capsys.readouterr().err
    log = read_log(cut)
    assert err.count("\n") == 1 and "no end line" in err
    assert f"{len(log.rows)} rows and {len(log.events)} events" in err
    got = read_mcap(tmp_path / "cut.mcap")
    assert len(got["/perchd/estimate"]) == len(log.rows)
    assert got[FLIGHT][0][2]["end"] is None and got[FLIGHT][0][2]["complete"] is False


def test_an_existing_output_is_kept_unless_forced(flown, tmp_path, capsys):
    out = tmp_path / "o.mcap"
    out.write_bytes(b"keep")
    assert export(flown, out) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "exists (pass --force to overwrite)" in err
    assert out.read_bytes() == b"keep"
    assert export(flown, out, "--force") == 0
    assert out.read_bytes()[:8] == b"\x89MCAP0\r\n"


def test_no_directory_is_made_and_the_input_is_never_the_output(flown, tmp_path, capsys):
    assert export(flown, tmp_path / "nowhere" / "o.mcap") == 2
    assert "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "nowhere").exists()
    before = flown.read_bytes()
    assert export(flown, flown, "--force") == 2
    assert "is the input" in capsys.readouterr().err
    assert flown.read_bytes() == before


def test_a_file_that_is_not_a_flight_log_is_one_line_and_exit_2(tmp_path, capsys):
    (tmp_path / "x.jsonl").write_text('{"schema": "other"}\n')
    assert export(tmp_path / "x.jsonl", tmp_path / "x.mcap") == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not (tmp_path / "x.mcap").exists()
    assert export(tmp_path / "absent.jsonl", tmp_path / "x.mcap") == 2
    assert "cannot read" in capsys.readouterr().err


def test_without_the_mcap_package_one_line_names_the_extra(flown, tmp_path, capsys, monkeypatch):
    def missing(module: str, extra: str):
        raise MissingExtraError(module.split(".")[0], extra)

    monkeypatch.setattr("perchd.commands.log.require", missing)
    assert export(flown, tmp_path / "o.mcap") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'perchd[mcap]'" in err
    assert not (tmp_path / "o.mcap").exists()


def test_the_real_require_names_the_extra_when_mcap_cannot_be_imported(
    flown, tmp_path, capsys, monkeypatch
):
    for name in ("mcap", "mcap.writer"):
        monkeypatch.setitem(sys.modules, name, None)  # import of mcap halted: as if absent
    assert export(flown, tmp_path / "o.mcap") == 2
    err = capsys.readouterr().err
    assert err == "perchd log: mcap is not installed: pip install 'perchd[mcap]'\n"
    assert not (tmp_path / "o.mcap").exists()


PLAN = Path(__file__).resolve().parents[2] / "plans" / "case1-ipts-n3.json"


def fly(log: Path, *more: str) -> int:
    return main(
        [
            "fly",
            str(PLAN),
            "--driver",
            "sim://",
            "--mocap",
            "sim://",
            "--log",
            str(log),
            "--json",
            *more,
        ]
    )


def test_fly_log_mcap_writes_the_jsonl_beside_it_and_the_same_export(tmp_path, capsys):
    assert fly(tmp_path / "g.mcap") == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["log"], out["mcap"]) == (str(tmp_path / "g.jsonl"), str(tmp_path / "g.mcap"))
    assert export(tmp_path / "g.jsonl", tmp_path / "again.mcap") == 0
    assert read_mcap(tmp_path / "g.mcap") == read_mcap(tmp_path / "again.mcap")


def test_fly_log_mcap_refuses_before_flying(tmp_path, capsys, monkeypatch):
    (tmp_path / "h.jsonl").write_text("keep")  # the JSONL beside it is an output too
    assert fly(tmp_path / "h.mcap") == 2
    assert "h.jsonl: exists" in capsys.readouterr().err
    assert not (tmp_path / "h.mcap").exists() and (tmp_path / "h.jsonl").read_text() == "keep"
    monkeypatch.setitem(sys.modules, "mcap.writer", None)
    assert fly(tmp_path / "i.mcap") == 2
    assert "pip install 'perchd[mcap]'" in capsys.readouterr().err
    assert not list(tmp_path.glob("i.*"))
