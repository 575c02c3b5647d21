"""Connecting on the event loop (vda5050.mqtt_connect) against amqtt and Mosquitto: sessions
connect and publish without a thread (reconnects: test_mqtt_session.py), a literal address and
a host name both work, refused and unanswered connects fail as aiomqtt's own connect fails (TLS,
which keeps aiomqtt's way, is tested in test_tls.py)."""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any, TypeVar

import aiomqtt
import pytest

from tests.integration.mqtt_helpers import watching
from tests.integration.test_mqtt_session import running, settings
from vda5050.broker import BrokerAddress
from vda5050.mqtt import MqttSession
from vda5050.mqtt_connect import LoopConnectClient, open_tcp
from vda5050.topics import Topic

pytestmark = pytest.mark.integration

T = TypeVar("T")


class _RefusingExecutor(ThreadPoolExecutor):
    """A default executor that counts what is handed to it and runs nothing."""

    def __init__(self) -> None:
        super().__init__(max_workers=1)
        self.calls: list[str] = []

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:  # noqa: ARG002
        self.calls.append(getattr(fn, "__qualname__", repr(fn)))
        future: Future[T] = Future()
        future.set_exception(RuntimeError("no threads here"))
        return future


@contextmanager
def no_threads() -> Iterator[_RefusingExecutor]:
    """The running loop's default executor refuses work for the duration."""
    loop = asyncio.get_running_loop()
    refusing = _RefusingExecutor()
    loop.set_default_executor(refusing)
    try:
        yield refusing
    finally:
        loop._default_executor = None  # type: ignore[attr-defined]  # a fresh pool next time
        refusing.shutdown()


async def test_sessions_connect_and_publish_without_a_thread(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Twenty sessions on a literal address connect, subscribe and publish while the loop's
    executor refuses all work: nothing of a plain TCP connect runs in a thread."""
    topic = f"{unique_interface_name}/v2/acme/connect-test/state"
    async with watching(broker, topic, qos=0) as watcher:
        with no_threads() as refusing:
            sessions = [MqttSession(settings(broker)) for _ in range(20)]
            async with asyncio.TaskGroup() as group:
                for session in sessions:
                    group.create_task(session.run())
                async with asyncio.timeout(10):
                    await asyncio.gather(*(s.wait_connected() for s in sessions))
                for index, session in enumerate(sessions):
                    session.publish(topic, Topic.STATE, b"%d" % index)
                async with asyncio.timeout(10):
                    while len(watcher.messages) < len(sessions):
                        watcher.arrived.clear()
                        await watcher.arrived.wait()
                for session in sessions:
                    await session.stop()
        assert refusing.calls == []
    assert sorted(int(bytes(m.payload)) for m in watcher.messages) == list(range(20))


async def test_a_host_name_is_resolved(embedded_broker: BrokerAddress) -> None:
    """``localhost`` resolves (possibly to several addresses) and one of them takes the
    connection; the session works as with a literal address."""
    session = MqttSession(settings(embedded_broker, url=f"mqtt://localhost:{embedded_broker.port}"))
    async with running(session):
        assert session.connected


async def test_a_refused_connect_is_an_mqtt_error_naming_the_reason(unused_tcp_port: int) -> None:
    """Nobody listens: the connect fails at once with aiomqtt's MqttError, as it did when paho
    connected in a thread, and the client can be entered again afterwards."""
    client = LoopConnectClient("127.0.0.1", unused_tcp_port, timeout=5)
    for _ in range(2):
        async with asyncio.timeout(2):
            with pytest.raises(aiomqtt.MqttError, match=r"(?i)refused"):
                await client.__aenter__()


async def test_an_unanswered_connect_times_out() -> None:
    """A peer that never accepts (a full backlog stands in for a black-holed address) ends
    in the client's timeout, not a hang."""
    with socket.create_server(("127.0.0.1", 0), backlog=0) as server:
        port = server.getsockname()[1]
        fillers = []
        try:
            for _ in range(64):  # fill the accept queue; further SYNs go unanswered
                filler = socket.socket()
                filler.setblocking(False)
                filler.connect_ex(("127.0.0.1", port))
                fillers.append(filler)
            client = LoopConnectClient("127.0.0.1", port, timeout=0.5)
            async with asyncio.timeout(5):
                with pytest.raises(aiomqtt.MqttError, match="timed out"):
                    await client.__aenter__()
        finally:
            for filler in fillers:
                filler.close()


async def test_open_tcp_tries_every_address_and_reports_the_first_error(
    embedded_broker: BrokerAddress, unused_tcp_port: int
) -> None:
    """A connected non-blocking socket for a listening port; OSError for a closed one."""
    sock = await open_tcp(embedded_broker.host, embedded_broker.port)
    try:
        assert sock.getblocking() is False
        assert sock.getpeername()[1] == embedded_broker.port
    finally:
        sock.close()
    with pytest.raises(ConnectionRefusedError):
        await open_tcp("127.0.0.1", unused_tcp_port)
