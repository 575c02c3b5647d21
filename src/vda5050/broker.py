"""The embedded MQTT 3.1.1 broker: amqtt 0.12 without its known defects.

`EmbeddedBroker` runs an amqtt broker inside the running event loop, on a loopback port by
default, anonymous by default or restricted to one username/password pair. It is what the master's
``--embedded-broker`` flag and the integration tests start.

amqtt 0.12.1 has defects that a broker for VDA 5050 must not pass on (see
``design/mqtt-notes.md``, "Defects reproduced"). `_Broker` overrides the few amqtt methods
involved, each override naming the defect it fixes:

1. Keep-alive is never enforced, so the will of a frozen client is never sent.
2. Retained messages leak: on connect, a client gets the retained messages matching every filter
   that *any* client holds, before it subscribes to anything.
3. Connect churn crashes sessions: amqtt iterates the subscription dict across ``await``s and
   fails with "dictionary changed size during iteration".

Example:
    async with EmbeddedBroker() as address:
        ...  # connect MQTT clients to address.host and address.port
"""

from __future__ import annotations

import asyncio
import hmac
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import structlog
from amqtt.broker import Broker
from amqtt.errors import BrokerError
from amqtt.mqtt.protocol.broker_handler import BrokerProtocolHandler
from amqtt.plugins.base import BaseAuthPlugin

from vda5050.net import bind_problem

if TYPE_CHECKING:
    from _collections_abc import dict_items
    from collections.abc import Iterator
    from types import TracebackType

    from amqtt.adapters import ReaderAdapter, WriterAdapter
    from amqtt.session import Session

__all__ = ["BrokerAddress", "EmbeddedBroker"]

log = structlog.get_logger()

#: amqtt's stdlib loggers (and its state-machine library's), which are chatty below WARNING.
_LIBRARY_LOGGERS = ("amqtt", "transitions")


@dataclass(frozen=True, slots=True)
class BrokerAddress:
    """Where a running broker accepts MQTT connections.

    Attributes:
        host: The address the broker listens on, as given to `EmbeddedBroker`.
        port: The bound TCP port (never 0).
    """

    host: str
    port: int

    @property
    def url(self) -> str:
        """The broker URL, ``mqtt://host:port`` (IPv6 hosts in brackets)."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"mqtt://{host}:{self.port}"


class EmbeddedBroker:
    """An in-process MQTT 3.1.1 broker (amqtt 0.12) for the running event loop.

    Args:
        host: Address to listen on; loopback by default. Use a literal IP address with port 0,
            since a host name may resolve to several sockets, each with its own free port.
        port: TCP port; 0 picks a free one. Once bound, the port is kept for later restarts of
            this instance, so clients can reconnect to the same address.
        username: With `password`, the only credentials accepted; otherwise anonymous access.
        password: See `username`.
        keepalive_grace: A client whose keep-alive is K seconds is disconnected (and its will
            sent) after K * keepalive_grace seconds without a packet; 1.5 as in Mosquitto and
            MQTT 3.1.1 §3.1.2.10. A keep-alive of 0 is never enforced.

    Raises:
        ValueError: Only one of username and password is given, or keepalive_grace < 1.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        username: str | None = None,
        password: str | None = None,
        keepalive_grace: float = 1.5,
    ) -> None:
        if (username is None) != (password is None):
            raise ValueError("username and password must be given together")
        if keepalive_grace < 1:
            msg = f"keepalive_grace must be at least 1, got {keepalive_grace}"
            raise ValueError(msg)
        self._host = host
        self._port = port
        self._credentials = None if username is None or password is None else (username, password)
        self._keepalive_grace = keepalive_grace
        self._broker: _Broker | None = None
        self._address: BrokerAddress | None = None

    @property
    def address(self) -> BrokerAddress:
        """The address of the running broker.

        Raises:
            RuntimeError: The broker is not running.
        """
        if self._address is None:
            raise RuntimeError("embedded broker is not running")
        return self._address

    async def start(self) -> BrokerAddress:
        """Start listening and return the bound address.

        Raises:
            RuntimeError: The broker is already running.
            OSError: The address cannot be bound (for example, the port is in use).
        """
        if self._broker is not None:
            raise RuntimeError("embedded broker is already running")
        problem = bind_problem(self._host, self._port)
        if problem is not None:  # checked first: amqtt would log a traceback before failing
            msg = f"embedded broker cannot listen on {self._host}:{self._port}: {problem}"
            raise OSError(msg)
        _quiet_library_loggers()
        broker = _Broker(self._amqtt_config(), keepalive_grace=self._keepalive_grace)
        try:
            await broker.start()
        except BrokerError as exc:
            msg = f"embedded broker cannot listen on {self._host}:{self._port}"
            raise OSError(msg) from exc
        self._broker = broker
        self._port = broker.bound_port()
        self._address = BrokerAddress(self._host, self._port)
        log.info("broker.started", url=self._address.url, anonymous=self._credentials is None)
        return self._address

    async def stop(self) -> None:
        """Disconnect every client, close the listener and release the port; idempotent."""
        broker, self._broker, self._address = self._broker, None, None
        if broker is None:
            return
        await broker.shutdown()
        broker.close_open_streams()
        log.info("broker.stopped", port=self._port)

    async def __aenter__(self) -> BrokerAddress:
        return await self.start()

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.stop()

    def _amqtt_config(self) -> dict[str, Any]:
        # Always give `plugins`: without it amqtt loads its slow logging plugins, an empty dict
        # rejects everyone, and the older `auth` key emits a DeprecationWarning.
        plugins: dict[str, dict[str, Any]]
        if self._credentials is None:
            plugins = {
                "amqtt.plugins.authentication.AnonymousAuthPlugin": {"allow_anonymous": True}
            }
        else:
            username, password = self._credentials
            plugins = {
                _plugin_path(_SingleUserAuthPlugin): {"username": username, "password": password}
            }
        return {
            "listeners": {"default": {"type": "tcp", "bind": f"{self._host}:{self._port}"}},
            "plugins": plugins,
        }


class _SingleUserAuthPlugin(BaseAuthPlugin):  # type: ignore[misc]  # amqtt ships no type hints
    """Accepts exactly one username/password pair (amqtt's own plugins need a password file)."""

    @dataclass
    class Config:
        username: str
        password: str

    async def authenticate(self, *, session: Session) -> bool:
        config: _SingleUserAuthPlugin.Config = self.context.config
        username = (session.username or "").encode()
        password = (session.password or "").encode()
        username_ok = hmac.compare_digest(username, config.username.encode())
        password_ok = hmac.compare_digest(password, config.password.encode())
        return username_ok and password_ok


class _SnapshotDict(dict[str, Any]):
    """A dict whose iteration walks a snapshot, so it may change while a loop awaits (defect 3)."""

    def __iter__(self) -> Iterator[str]:
        return iter(list(super().__iter__()))

    def items(self) -> dict_items[str, Any]:
        return dict(super().items()).items()


class _KeepAliveHandler(BrokerProtocolHandler):  # type: ignore[misc]  # amqtt ships no type hints
    """amqtt's per-connection protocol handler, closing connections whose keep-alive expired."""

    def handle_read_timeout(self) -> None:
        # Defect 1 (keep-alive never enforced): amqtt's reader waits `session.keep_alive` seconds
        # for each packet, then calls this hook, which amqtt leaves empty. End the input stream
        # instead: the reader then stops as on a dropped socket, and the broker sends the will.
        log.info(
            "broker.keepalive_expired",
            client_id=self.session.client_id,
            timeout_s=self.session.keep_alive,
        )
        self.reader.feed_eof()


class _Broker(Broker):  # type: ignore[misc]  # amqtt ships no type hints
    """amqtt's broker with the defects listed in the module docstring fixed."""

    def __init__(self, config: dict[str, Any], *, keepalive_grace: float) -> None:
        super().__init__(config)
        self._keepalive_grace = keepalive_grace
        # Defect 3 (crash under connect churn): amqtt iterates this dict across awaits, for
        # example in `_handle_client_session` and `_run_broadcast`; iterate over snapshots.
        self._subscriptions = _SnapshotDict()
        self._open_streams: set[asyncio.StreamWriter] = set()

    async def stream_connected(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, listener_name: str
    ) -> None:
        # amqtt leaves the socket of some ended connections open (e.g. a client that disconnects
        # while the broker shuts down): close every connection when its handler ends.
        self._open_streams.add(writer)
        try:
            await super().stream_connected(reader, writer, listener_name)
        finally:
            self._open_streams.discard(writer)
            writer.close()

    def close_open_streams(self) -> None:
        """Close the connections whose handlers are still running (after shutdown)."""
        for writer in list(self._open_streams):
            writer.close()
        self._open_streams.clear()

    def bound_port(self) -> int:
        """The TCP port the default listener is bound to (amqtt only keeps it privately)."""
        port: int = self._servers["default"].instance.sockets[0].getsockname()[1]
        return port

    async def _initialize_client_session(
        self, reader: ReaderAdapter, writer: WriterAdapter, remote_address: str, remote_port: int
    ) -> tuple[BrokerProtocolHandler, Session]:
        # Defect 1 (keep-alive never enforced): the handler amqtt returns is fresh and not yet
        # attached; use ours, which acts on a read timeout. amqtt itself widens `keep_alive`
        # (by its timeout-disconnect-delay) into the read timeout; widen it by the grace factor.
        _, session = await super()._initialize_client_session(
            reader, writer, remote_address, remote_port
        )
        if session.keep_alive > 0:
            session.keep_alive *= self._keepalive_grace
        return _KeepAliveHandler(self.plugins_manager), session

    async def _publish_retained_messages_for_subscription(
        self, subscription: tuple[str, int], session: Session
    ) -> None:
        # Defect 2 (retained messages leak): on every CONNECT amqtt calls this for every filter
        # that any client holds; serve only filters that this session holds itself.
        topic_filter, _ = subscription
        holders = self._subscriptions.get(topic_filter, [])
        if any(holder.client_id == session.client_id for holder, _ in holders):
            await super()._publish_retained_messages_for_subscription(subscription, session)


def _plugin_path(plugin: type[Any]) -> str:
    return f"{plugin.__module__}.{plugin.__qualname__}"


def _quiet_library_loggers() -> None:
    for name in _LIBRARY_LOGGERS:
        logger = logging.getLogger(name)
        if logger.level == logging.NOTSET:  # leave levels that someone set on purpose
            logger.setLevel(logging.WARNING)
