"""Every URI parameter on every side is applied or refused (docs/contracts.md §7): each
scheme's table (perchd.core.uriparams.PARAMS) walked on both sides; sim:// is one world
whose vehicle keys belong to --driver and mocap keys to --mocap, each refused on the other
side naming where it belongs, and the flight log's header records what was applied."""

from __future__ import annotations

import json

import pytest
from simflight import PLANS

from perchd.cli import main
from perchd.core.errors import UriError
from perchd.core.uri import parse_uri
from perchd.core.uriparams import PARAMS, check_params
from perchd.logs.flightlog import read_log
from perchd.session import open_links, open_session

# every sim:// key: a value other than its default, and where the world keeps it
SIM_VALUES = {
    "latency": ("0.02", lambda w: w.plant.latency_s, 0.02),
    "attitude_tau": ("0.05", lambda w: w.plant.attitude_tau_s, 0.05),
    "motor_tau": ("0.02", lambda w: w.plant.motor_tau_s, 0.02),
    "mass": ("0.04", lambda w: w.plant.mass_kg, 0.04),
    "drag": ("0.3", lambda w: w.plant.drag_per_s, 0.3),
    "qdrag": ("0.2", lambda w: w.plant.qdrag_per_m, 0.2),
    "start": ("-4,0,1.2", lambda w: w.start, (-4.0, 0.0, 1.2)),
    "draught": ("-2,0.1", lambda w: (w.plant.draught_x_m, w.plant.draught_mps2), (-2.0, 0.1)),
    "stall": ("1,0.2", lambda w: (w.stall.at_s, w.stall.for_s), (1.0, 0.2)),
    "mocap_rate": ("100", lambda w: w.mocap.rate_hz, 100.0),
    "mocap_latency": ("0.01", lambda w: w.mocap.latency_s, 0.01),
    "noise": ("0.05", lambda w: w.mocap.noise_m, 0.05),
    "seed": ("7", lambda w: w.seed, 7),
    "body": ("cf9", lambda w: w.body, "cf9"),
}
SIDES = ("driver", "mocap")


def sim_keys(kind: str) -> list[str]:
    return [p[0] for p in PARAMS[(kind, "sim")]]


def test_every_sim_key_has_one_side_and_a_case_here():
    driver, mocap = set(sim_keys("driver")), set(sim_keys("mocap"))
    assert not driver & mocap and driver | mocap == set(SIM_VALUES)


@pytest.mark.parametrize("kind", SIDES)
def test_each_sim_key_on_its_side_is_applied_to_the_world(kind):
    for key in sim_keys(kind):
        text, read, want = SIM_VALUES[key]
        uris = {"driver": "sim://", "mocap": "sim://", kind: f"sim://?{key}={text}"}
        session = open_links(uris["driver"], uris["mocap"])
        try:
            assert read(session.world.params) == pytest.approx(want), key
            assert session.applied[kind] == {key: text}
        finally:
            session.close()


@pytest.mark.parametrize("kind", SIDES)
def test_each_sim_key_on_the_other_side_is_refused_naming_its_side(kind):
    other = "mocap" if kind == "driver" else "driver"
    for key in sim_keys(kind):
        uris = {kind: "sim://", other: f"sim://?{key}={SIM_VALUES[key][0]}"}
        with pytest.raises(UriError, match=rf"'{key}' is a --{kind} parameter") as err:
            open_links(uris["driver"], uris["mocap"])
        assert len(str(err.value).splitlines()) == 1


@pytest.mark.parametrize("kind, scheme", sorted(PARAMS))
def test_every_table_is_taken_on_its_side_and_refused_on_the_other(kind, scheme):
    other = "mocap" if kind == "driver" else "driver"
    theirs = {p[0] for p in PARAMS.get((other, scheme), ())}
    base = "mavlink:udpout:127.0.0.1:14550" if scheme == "mavlink" else f"{scheme}://h:1"
    for key, *_ in PARAMS[(kind, scheme)]:
        check_params(kind, parse_uri(f"{base}?{key}=1"))  # known here: not refused
        if (other, scheme) in PARAMS and key not in theirs:
            with pytest.raises(UriError, match=rf"'{key}'"):
                check_params(other, parse_uri(f"{base}?{key}=1"))


@pytest.mark.parametrize("kind", SIDES)
def test_a_misspelt_sim_key_is_refused_listing_the_known_ones(kind):
    uris = {"driver": "sim://", "mocap": "sim://", kind: "sim://?nois=0.05"}
    with pytest.raises(UriError, match="unknown parameter 'nois'") as err:
        open_links(uris["driver"], uris["mocap"])
    assert all(key in str(err.value) for key in sim_keys(kind))


def test_a_whole_world_uri_still_opens_one_session_with_each_side_its_keys():
    session = open_session("sim://?latency=0.02&noise=0.001")
    try:
        assert session.world.params.plant.latency_s == 0.02
        assert session.world.params.mocap.noise_m == 0.001
        assert session.applied["driver"] == {"latency": "0.02"}
        assert session.applied["mocap"] == {"noise": "0.001"}
    finally:
        session.close()


def test_perchd_fly_applies_mocap_noise_and_the_log_header_says_so(tmp_path, capsys):
    log = tmp_path / "f.jsonl"
    code = main(
        [
            "fly",
            str(PLANS / "case1-ipts-n3.json"),
            "--driver",
            "sim://",
            "--mocap",
            "sim://?noise=0.002",
            "--log",
            str(log),
            "--json",
        ]
    )
    assert code == 0, capsys.readouterr().err
    header = read_log(log).header
    assert header["uri_params"]["mocap"] == {"noise": "0.002"}
    assert header["uri_params"]["sim_world"]["mocap"]["noise_m"] == 0.002
    assert json.loads(capsys.readouterr().out)["outcome"] == "CONTACT"


def test_perchd_fly_refuses_a_misplaced_sim_key_in_one_line(tmp_path, capsys):
    code = main(
        [
            "fly",
            str(PLANS / "case1-ipts-n3.json"),
            "--driver",
            "sim://?noise=0.05",
            "--mocap",
            "sim://",
            "--log",
            str(tmp_path / "f.jsonl"),
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--mocap" in err and "noise" in err
    assert not (tmp_path / "f.jsonl").exists()
