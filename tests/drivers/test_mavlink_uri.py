"""The `mavlink:` URI (drivers/mavlink/uri.py): bad ones refused by name before any link
opens."""

from __future__ import annotations

import sys

import pytest

pytest.importorskip("pymavlink")


from perchd.core.errors import MissingExtraError, UriError
from perchd.core.runtime import Runtime
from perchd.drivers.base import open_driver


@pytest.mark.parametrize(
    "uri, message",
    [
        ("mavlink:udpout:127.0.0.1:14550?mass=90", "mass=90 kg is outside"),
        ("mavlink:nonsense", "expected mavlink:udpin:HOST:PORT .PX4: udpin:127.0.0.1:14540"),
    ],
)
def test_bad_uris_are_refused_by_name(uri, message):
    with pytest.raises(UriError, match=message):
        open_driver(uri, Runtime.real())


@pytest.mark.parametrize(
    "uri, port",
    [
        ("mavlink:tcp:host:xx?mass=1", "'xx'"),
        ("mavlink:udpout:127.0.0.1?mass=1", "''"),
        ("mavlink:udpin:0.0.0.0:70000?mass=1", "'70000'"),
    ],
)
def test_a_network_device_without_a_port_is_refused_before_pymavlink_sees_it(uri, port):
    with pytest.raises(UriError, match=f"needs HOST:PORT with a port 1..65535, got {port}"):
        open_driver(uri, Runtime.real())


def test_without_pymavlink_the_factory_names_the_extra_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "pymavlink", None)  # as if not installed
    with pytest.raises(MissingExtraError, match=r"pip install 'perchd\[mavlink\]'"):
        open_driver("mavlink:udpout:127.0.0.1:14550?mass=1", Runtime.real())


@pytest.mark.parametrize(
    "uri",
    [
        "mavlink:udpin:127.0.0.1:14540?mass=1&sport=5000",
        "mavlink:udpout:127.0.0.1:14580?mass=1&sport=1.5",
    ],
)
def test_sport_is_for_udpout_only(uri):
    with pytest.raises(UriError, match="sport= is a whole port number, for udpout: links only"):
        open_driver(uri, Runtime.real())
