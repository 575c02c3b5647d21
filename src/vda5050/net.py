"""Small network helpers shared by the services and the demo."""

from __future__ import annotations

import ipaddress
import socket


def bind_problem(host: str, port: int) -> str | None:
    """Why a server could not listen on ``host:port`` (e.g. "Address already in use"), or None.

    Port 0 (pick a free one) never has a problem. Binding is probed with SO_REUSEADDR, as the
    servers themselves bind, so a port in TIME_WAIT does not count as taken.
    """
    if port == 0:
        return None
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as exc:
            return exc.strerror or str(exc)
    return None


def is_loopback(host: str) -> bool:
    """Whether ``host`` is reachable only from this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
