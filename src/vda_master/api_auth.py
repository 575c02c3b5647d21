"""API keys with two roles for the HTTP API (issue 14).

- **viewer** keys may read (vehicles, orders, traffic, the map and its stream);
- **operator** keys may also act (create and cancel orders, send instant actions).

A key is sent as ``Authorization: Bearer <key>`` or ``X-API-Key: <key>``; the map page and its
event stream, which a browser opens without custom headers, may pass it as ``?key=<key>``.
``/health`` is always open. Without any key configured the API is open, which
:func:`check_exposure` allows only on a loopback address unless ``insecure_api`` says so.
Keys are compared in constant time.
"""

from __future__ import annotations

import hmac
from enum import IntEnum

from fastapi import Request

from vda5050.errors import ConfigError
from vda5050.net import is_loopback
from vda_master.config import MasterConfig
from vda_master.requests import RequestError

_BEARER = "bearer "


class Role(IntEnum):
    """What a key may do; a higher role includes the lower ones."""

    VIEWER = 1
    OPERATOR = 2


class ApiKeys:
    """The configured keys and their roles."""

    def __init__(self, operator: list[str], viewer: list[str]) -> None:
        self._keys = [(key.encode(), Role.OPERATOR) for key in operator]
        self._keys += [(key.encode(), Role.VIEWER) for key in viewer]

    @property
    def enabled(self) -> bool:
        return bool(self._keys)

    def role_of(self, presented: str) -> Role | None:
        """The role of ``presented``, or None; every key is compared (constant time)."""
        found: Role | None = None
        candidate = presented.encode()
        for key, role in self._keys:
            if hmac.compare_digest(key, candidate) and (found is None or role > found):
                found = role
        return found

    def require(self, request: Request, needed: Role) -> None:
        """Raise 401/403 unless the request carries a key with at least ``needed``."""
        if not self.enabled:
            return
        presented = presented_key(request)
        if presented is None:
            raise RequestError(
                401,
                "missing API key: send 'Authorization: Bearer <key>' or 'X-API-Key: <key>'",
            )
        role = self.role_of(presented)
        if role is None:
            raise RequestError(401, "unknown API key")
        if role < needed:
            raise RequestError(
                403,
                "this API key may only read (role viewer); orders, cancels and instant actions "
                "need an operator key",
            )

    def allows(self, request: Request, needed: Role) -> bool:
        """Whether :meth:`require` would let ``request`` through."""
        try:
            self.require(request, needed)
        except RequestError:
            return False
        return True


def presented_key(request: Request) -> str | None:
    """The key a request carries, from its headers or (for browsers) ``?key=``."""
    authorization = request.headers.get("authorization", "")
    if authorization.lower().startswith(_BEARER):
        return authorization[len(_BEARER) :].strip() or None
    return request.headers.get("x-api-key") or request.query_params.get("key") or None


def api_keys(config: MasterConfig) -> ApiKeys:
    """The keys of ``config``."""
    return ApiKeys(list(config.api_operator_keys), list(config.api_viewer_keys))


def check_exposure(config: MasterConfig) -> None:
    """Secure by default: no key-less API on a non-loopback address unless asked for."""
    if is_loopback(config.api_host) or config.insecure_api or api_keys(config).enabled:
        return
    msg = (
        f"the HTTP API would listen on {config.api_host} without authentication: set "
        "api_operator_keys (and api_viewer_keys) or VDA_API_OPERATOR_KEYS, or start with "
        "--insecure-api if the network is trusted"
    )
    raise ConfigError(msg)
