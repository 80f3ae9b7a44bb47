"""Control-socket lines (docs/contracts.md §4) under fuzzing: first through the server's request
handling in this process (ControlServer.answer, PARSER_EXAMPLES lines; benchmarks/fuzz.py runs
10^6), then against a running `perchd serve` over its real Unix socket: every line gets exactly
one reply, a bad one {"ok": false, "error": ...}; the service never stops and answers the next
good request."""

from __future__ import annotations

import json

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from mutate import json_values
from served import Service

from perchd.service.control_socket import ControlServer
from perchd.service.request_line import BadRequest, parse_request

PARSER_EXAMPLES = 2000

HOSTILE_PLANS = [
    "../../../etc/passwd",
    "/etc/shadow",
    "/dev/zero",
    "/dev/stdin",
    "/proc/self/fd/0",
    "",
    ".",
    "..",
    "/",
    "a" * 5000,
    "plan\0.json",
    "~root/p.json",
    "*.json",
]
requests = st.fixed_dictionaries(
    {
        "cmd": st.sampled_from(["fly", "abort", "status", "FLY", "", "__class__", "eval"])
        | json_values
    },
    optional={"plan": st.sampled_from(HOSTILE_PLANS) | json_values, "x": json_values},
)
lines = st.one_of(
    st.binary(max_size=300).map(lambda b: b.replace(b"\n", b"")),
    requests.map(lambda r: json.dumps(r).encode()),
    json_values.map(lambda v: json.dumps(v).encode()),
    st.sampled_from(
        [
            b"[" * 60000,
            b'{"cmd":' * 5000,
            b"\xff\xfe",
            b'{"cmd": "status"}' * 2,
            b'{"cmd": "status", "cmd": 1}',
            b"\0" * 100,
        ]
    ),
)


@st.composite
def duplicated(draw) -> bytes:
    """A request object with one of its keys written twice, at any depth."""
    req = draw(requests)
    key = draw(st.sampled_from(sorted(req)))
    body = json.dumps(req)[1:-1]
    twice = json.dumps({key: draw(json_values)})[1:-1]
    return ("{" + body + ", " + twice + "}").encode()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    def dispatch(req):
        if req["cmd"] == "eval":
            raise RuntimeError("a dispatch that fails")
        return {"ok": True}

    s = ControlServer(tmp_path_factory.mktemp("parser") / "c.sock", dispatch)
    yield s
    s.close()


@settings(
    max_examples=PARSER_EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(lines | duplicated(), st.booleans())
def test_every_line_gets_one_reply_from_the_request_handling(server, line, reserved):
    reply = server.answer(line, reserved)
    assert isinstance(reply.get("ok"), bool)
    if not reply["ok"]:
        assert isinstance(reply["error"], str) and reply["error"] and "\n" not in reply["error"]
    event("accepted" if reply["ok"] else "rejected")


@settings(max_examples=PARSER_EXAMPLES // 3, deadline=None)
@given(duplicated())
def test_a_key_given_twice_is_always_refused(line):
    with pytest.raises(BadRequest, match="^malformed request: key .* given twice$"):
        parse_request(line)


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    s = Service(tmp_path_factory.mktemp("serve"))
    yield s
    s.stop()


@settings(
    deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
)
@given(st.lists(lines, min_size=1, max_size=4))
def test_each_bad_line_gets_one_error_reply_and_the_next_good_request_is_answered(service, batch):
    replies = service.talk(b"".join(line + b"\n" for line in batch), len(batch))
    assert len(replies) == len(batch)
    for reply in replies:
        assert set(reply) >= {"ok"} and isinstance(reply["ok"], bool)
        if not reply["ok"]:
            assert isinstance(reply["error"], str) and reply["error"]
        event("accepted" if reply["ok"] else "rejected")
    assert not any(r.get("flying") and "plan" in r for r in replies), (
        "no fuzzed line starts a flight"
    )
    status = service.talk(b'{"cmd": "status"}\n', 1)[0]
    assert status["ok"] is True and status["state"] == "idle"
    assert service.proc.poll() is None


def test_a_deeply_nested_line_is_answered_and_the_service_lives_on(service):
    reply = service.talk(b"[" * 60000 + b"\n", 1)[0]
    assert reply == {
        "ok": False,
        "error": "malformed request, not one JSON object: nested too deeply",
    }
    assert service.talk(b'{"cmd": "status"}\n', 1)[0]["ok"] is True


def test_an_overlong_line_drops_only_that_client(service):
    reply = service.talk(b"x" * 70000, 1)[0]
    assert "longer than 65536 bytes" in reply["error"]
    assert service.talk(b'{"cmd": "status"}\n', 1)[0]["state"] == "idle"
