"""Where perchd may listen: loopback unless a URI opts in with `public=1`; a port already
taken is bad input (exit 2), whichever part of perchd meets it.

A bound ZMQ socket accepts poses or setpoints from whoever can reach it, so binding on any
other address (a LAN address, `*`, `0.0.0.0`, an interface name) must be asked for explicitly.
Connecting out to a remote host needs no opt-in: that is where a mocap bridge lives.
"""

from __future__ import annotations

import errno
import ipaddress

from perchd.core.errors import LinkError, UriError

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
        raise UriError(
            f"{what}: refusing to bind {host}, which is not loopback; add "
            f"{PUBLIC}=1 to the URI to listen on the network"
        )


def port_error(what: str, err: Exception) -> Exception:
    """A taken port is bad input (exit 2, docs/contracts.md §6), whatever the transport; other
    failures to listen stay what they were (an OSError or LinkError becomes a LinkError)."""
    text = getattr(err, "strerror", None) or str(err)
    if getattr(err, "errno", None) == errno.EADDRINUSE or "Address already in use" in text:
        return UriError(
            f"{what}: the port is taken (another perchd sim, Motive or server is "
            "listening there); choose another PORT, or 0 for any free one"
        )
    return err if isinstance(err, LinkError) else LinkError(f"{what}: cannot listen: {text}")
