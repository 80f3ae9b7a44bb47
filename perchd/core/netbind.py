"""Where perchd may listen: loopback unless a URI opts in with `public=1`.

A bound ZMQ socket accepts poses or setpoints from whoever can reach it, so binding on any
other address (a LAN address, `*`, `0.0.0.0`, an interface name) must be asked for explicitly.
Connecting out to a remote host needs no opt-in: that is where a mocap bridge lives.
"""

from __future__ import annotations

import ipaddress

from perchd.core.errors import UriError

PUBLIC = "public"
"""URI query key that allows a non-loopback bind (`?bind=1&public=1`)."""


def is_loopback(host: str) -> bool:
    host = host.strip("[]")
    if host in ("localhost", "lo"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # '*', an interface or host name: not provably loopback
        return False


def check_bind(host: str, public: bool, what: str) -> None:
    """UriError unless `host` is a loopback address or the caller opted in (`public`)."""
    if not public and not is_loopback(host):
        raise UriError(f"{what}: refusing to bind {host}, which is not loopback; add "
                       f"{PUBLIC}=1 to the URI to listen on the network")
