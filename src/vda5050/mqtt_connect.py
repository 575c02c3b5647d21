"""Connecting to the broker on the event loop instead of in aiomqtt's executor threads.

aiomqtt runs paho's ``connect`` in the loop's default executor, because paho opens the TCP
connection with a blocking ``socket.create_connection``. A process that connects a thousand
vehicles at once then has six threads taking turns at the interpreter lock with the event loop,
which is busy with the CONNACKs, SUBSCRIBEs and first publications of the vehicles already
connected: each connect waits for the lock again after every system call. Measured with 1000
simulated vehicles on a 2-core machine: through one thread the 1000 connects took 2.2-3.3 s.

:class:`LoopConnectClient` opens the TCP connection without blocking on the loop
(``loop.sock_connect``) and hands paho the connected socket; paho's ``connect`` then only sends
CONNECT, and runs on the loop too. What follows (CONNACK, subscriptions, publications) is
aiomqtt's as before. Plain TCP only: a TLS handshake would block the loop, so a client with
TLS (and one over websockets or a proxy) connects the way aiomqtt does.

Checked against aiomqtt 2.5 and paho-mqtt 2.2, like :mod:`vda5050.socket_writer`: the steps of
aiomqtt's ``__aenter__`` are repeated with its private ``_lock``, ``_client``, ``_hostname``,
``_port``, ``_socket_options``, ``_tls_params``, ``_client_connect``, ``_wait_for``,
``_connected`` and ``_disconnected``; paho's ``_ssl``, ``_transport``, ``_get_proxy`` and
``_create_socket_connection`` decide and take the socket. The tests in
``test_mqtt_connect.py`` fail if they change.
"""

from __future__ import annotations

import asyncio
import ipaddress
import math
import os
import socket
from collections.abc import Sequence
from typing import Any, Self

import aiomqtt
from aiomqtt.exceptions import MqttReentrantError

__all__ = ["LoopConnectClient", "open_tcp"]

#: What ``getaddrinfo`` gives per address: family, type, protocol, canonical name, address.
_AddressInfo = tuple[socket.AddressFamily, socket.SocketKind, int, str, Any]


class LoopConnectClient(aiomqtt.Client):
    """An aiomqtt client whose plain TCP connect does not use a thread (module docstring)."""

    async def __aenter__(self) -> Self:
        paho = self._client
        tls = paho._ssl or self._tls_params is not None  # noqa: SLF001 - as paho's connect reads it
        if tls or paho._transport != "tcp" or paho._get_proxy() is not None:  # noqa: SLF001
            return await super().__aenter__()
        # The steps of aiomqtt's __aenter__, with the socket opened on the loop.
        if self._lock.locked():
            msg = "The client context manager is reusable, but not reentrant"
            raise MqttReentrantError(msg)
        await self._lock.acquire()
        try:
            within = None if math.isinf(self.timeout) else self.timeout
            async with asyncio.timeout(within):
                sock = await open_tcp(self._hostname, self._port)
            for option in self._socket_options:
                sock.setsockopt(*option)
            paho._create_socket_connection = lambda: sock  # type: ignore[method-assign]  # noqa: SLF001 - paho takes the connected socket
            try:
                self._client_connect()  # sends CONNECT on the connected socket: does not block
            finally:
                del paho._create_socket_connection  # noqa: SLF001 - a later connect opens its own
        except OSError as exc:  # TimeoutError included: paho's blocking connect said "timed out"
            self._lock.release()
            raise aiomqtt.MqttError(str(exc) or "timed out") from None
        try:
            await self._wait_for(self._connected, timeout=None)
        except aiomqtt.MqttError:
            self._lock.release()
            self._connected = asyncio.Future()
            raise
        if self._disconnected.done():
            self._disconnected = asyncio.Future()
        return self


async def open_tcp(host: str, port: int) -> socket.socket:
    """A non-blocking TCP socket connected to ``host``:``port``, trying each address ``host``
    resolves to in turn (a literal address is not resolved). Bound it with ``asyncio.timeout``.

    Raises:
        OSError: no address could be connected to; the first address's error.
    """
    loop = asyncio.get_running_loop()
    errors: list[OSError] = []
    for family, kind, proto, _, address in await _addresses(loop, host, port):
        sock = socket.socket(family, kind, proto)
        try:
            sock.settimeout(0.0)  # non-blocking
            await loop.sock_connect(sock, address)
        except OSError as exc:
            sock.close()
            # asyncio says "Connect call failed (address)"; paho's connect said what failed
            errors.append(OSError(exc.errno, os.strerror(exc.errno)) if exc.errno else exc)
            continue
        except BaseException:
            sock.close()
            raise
        return sock
    if not errors:
        errors.append(OSError(f"{host} resolves to no address"))
    raise errors[0]


async def _addresses(
    loop: asyncio.AbstractEventLoop, host: str, port: int
) -> Sequence[_AddressInfo]:
    try:
        literal = ipaddress.ip_address(host)
    except ValueError:
        return await loop.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    if isinstance(literal, ipaddress.IPv4Address):
        return [(socket.AF_INET, socket.SOCK_STREAM, socket.IPPROTO_TCP, "", (host, port))]
    return [(socket.AF_INET6, socket.SOCK_STREAM, socket.IPPROTO_TCP, "", (host, port, 0, 0))]
