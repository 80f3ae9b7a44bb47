"""Property tests: nothing a network can deliver makes the client raise, and every frame
perchd can express survives encode/decode in every supported version."""

from __future__ import annotations

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mutate import mutated_bytes  # the one byte mutator, shared with tests/fuzz
from natnet_recordings import session_frames

from perchd.core.clock import ManualClock
from perchd.mocap.natnet.client import NatNetConfig, NatNetSource
from perchd.mocap.natnet.clock import ClockSync
from perchd.mocap.natnet.frame import (
    AnalogDevice,
    Frame,
    LabeledMarker,
    RigidBodySample,
    Skeleton,
    Timing,
    decode_frame,
    encode_frame,
)
from perchd.mocap.natnet.wire import MalformedPacket

REAL = [r.data for r in session_frames()[:20]]
VERSIONS = [(2, 5), (2, 6), (2, 7), (2, 9), (2, 10), (2, 11), (3, 0), (3, 1), (4, 0), (4, 1)]


def fresh_client(version=(3, 0)) -> NatNetSource:
    """A client in the state start() leaves it in, without sockets: the receive path only."""
    source = NatNetSource(NatNetConfig("127.0.0.1", "RaceQuad"), ManualClock(10.0))
    source.info = type("Info", (), {"version": version})()
    source._body_id = 2
    source._sync = ClockSync(3312787)
    return source


def check_accounting(source: NatNetSource) -> None:
    stats = source.stats()
    assert stats.poses + stats.dropped <= stats.received
    latest = source.latest()
    if latest is not None and latest.valid:
        assert all(math.isfinite(v) for v in (*latest.p, *latest.q, latest.t))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.binary(max_size=600), min_size=1, max_size=8))
def test_arbitrary_datagrams_never_raise_and_are_counted(datagrams):
    source = fresh_client()
    for datagram in datagrams:
        source.handle_datagram(datagram, 10.0)
    assert source.stats().received == len(datagrams)
    check_accounting(source)


@settings(max_examples=400, deadline=None)
@given(st.lists(mutated_bytes(REAL), min_size=1, max_size=5))
def test_mutated_real_packets_never_raise_and_are_counted(packets):
    source = fresh_client()
    for datagram in packets:
        source.handle_datagram(datagram, 10.0)
    check_accounting(source)
    assert source.stats().received == len(packets)


def test_the_unmutated_real_packets_all_become_poses():
    source = fresh_client()
    for datagram in REAL:
        source.handle_datagram(datagram, 10.0e6)
    assert source.stats().poses == len(REAL) and source.stats().dropped == 0


f32 = st.integers(-(2**20), 2**20).map(lambda i: i / 1024.0)  # exactly representable
vec3 = st.tuples(f32, f32, f32)
quat = st.tuples(f32, f32, f32, f32)


@st.composite
def frames(draw, version) -> Frame:
    old = version < (3, 0)
    markers = (
        st.lists(st.tuples(vec3, st.integers(0, 99), f32), max_size=3).map(tuple)
        if old
        else st.just(())
    )
    body = st.builds(
        RigidBodySample,
        st.integers(0, 1000),
        vec3,
        quat,
        f32 if version >= (2, 0) else st.just(0.0),
        st.booleans() if version >= (2, 6) else st.just(True),
        markers,
    )
    marker = st.builds(
        LabeledMarker,
        st.integers(-(2**31), 2**31 - 1),
        vec3,
        f32,
        st.integers(0, 63) if version >= (2, 6) else st.just(0),
        f32 if version >= (3, 0) else st.just(0.0),
    )
    device = st.builds(
        AnalogDevice,
        st.integers(0, 9),
        st.lists(st.lists(f32, max_size=3).map(tuple), max_size=2).map(tuple),
    )
    stamps = st.integers(1, 2**63) if version >= (3, 0) else st.none()
    timing = Timing(
        draw(f32 if version >= (2, 6) else st.just(0.0)),
        draw(stamps),
        draw(stamps),
        draw(stamps),
        draw(f32) if old else None,
        draw(st.integers(0, 2**32 - 1)),
        draw(st.integers(0, 2**32 - 1)),
        *(draw(st.integers(0, 2**32 - 1)) for _ in range(2) if version >= (4, 1)),
    )

    def lists(s, allowed=True):
        return st.lists(s, max_size=3).map(tuple) if allowed else st.just(())

    return Frame(
        draw(st.integers(-(2**31), 2**31 - 1)),
        draw(lists(body)),
        timing,
        draw(lists(st.tuples(st.text("abcxyz ", min_size=1, max_size=8), lists(vec3)))),
        draw(lists(vec3)),
        draw(lists(st.builds(Skeleton, st.integers(0, 9), lists(body)), version >= (2, 1))),
        (),
        draw(lists(marker, version >= (2, 3))),
        draw(lists(device, version >= (2, 9))),
        draw(lists(device, version >= (2, 11))),
        draw(st.integers(0, 3)) if version >= (2, 6) else 0,
    )


@settings(max_examples=40, deadline=None)
@given(st.data())
def test_any_frame_survives_encode_and_decode_in_every_version(data):
    version = data.draw(st.sampled_from(VERSIONS))
    frame = data.draw(frames(version))
    assert decode_frame(encode_frame(frame, version), version) == frame


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(VERSIONS), st.binary(max_size=300))
def test_decoding_arbitrary_bytes_either_works_or_says_malformed(version, payload):
    try:
        decode_frame(payload, version)
    except MalformedPacket:
        pass
