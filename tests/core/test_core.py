"""The shared plumbing: URIs, registries, clocks, extras and the CLI's error path."""

import subprocess
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from perchd.core.clock import ManualClock
from perchd.core.errors import MissingExtraError, UriError
from perchd.core.extras import require
from perchd.core.uri import Registry, parse_uri


def test_a_uri_splits_into_scheme_host_port_and_query():
    uri = parse_uri("natnet://10.0.0.5:1510?body=cf1&up=y")
    assert (uri.scheme, uri.host, uri.port) == ("natnet", "10.0.0.5", 1510)
    assert uri.param("body") == "cf1" and uri.param("up") == "y"


def test_a_mavlink_connection_string_keeps_its_tail():
    uri = parse_uri("mavlink:udpout:127.0.0.1:14550")
    assert uri.scheme == "mavlink" and uri.path == "udpout:127.0.0.1:14550"


@pytest.mark.parametrize("text", ["nonsense", "natnet://host:99999"])
def test_a_malformed_uri_is_refused_with_its_text(text):
    with pytest.raises(UriError, match="nonsense|port"):
        parse_uri(text)


def test_an_unknown_scheme_lists_the_known_ones():
    registry = Registry("driver", {"sim": "x:y", "zmq": "x:z"})
    with pytest.raises(UriError, match=r"unknown driver scheme 'ftp'.*sim://, zmq://"):
        registry.open("ftp://host", runtime=None)


def test_a_manual_clock_jumps_to_the_deadline_and_never_goes_back():
    clock = ManualClock(1.0)
    clock.sleep_until(2.5)
    clock.sleep_until(2.0)
    assert clock.now() == 2.5


def test_a_missing_optional_library_names_the_extra_to_install():
    with pytest.raises(MissingExtraError, match=r"pip install 'perchd\[crazyflie\]'"):
        require("cflib_that_does_not_exist", "crazyflie")


def test_the_cli_prints_its_version():
    out = subprocess.run(
        [sys.executable, "-m", "perchd", "--version"], capture_output=True, text=True, check=True
    )
    assert out.stdout.startswith("perchd ")


def test_an_unclosed_ipv6_bracket_is_a_uri_error_not_a_traceback():
    with pytest.raises(UriError, match=r"'natnet://\[::1' is not a URI"):
        parse_uri("natnet://[::1")


@settings(max_examples=300, deadline=None)
@given(
    st.text(max_size=40)
    | st.builds(
        lambda s, t: f"{s}://{t}",
        st.sampled_from(["sim", "zmq", "natnet", "radio"]),
        st.text(max_size=30),
    )
)
def test_any_text_parses_or_is_one_uri_error(text):
    try:
        parse_uri(text)
    except UriError as err:
        assert "\n" not in str(err)
