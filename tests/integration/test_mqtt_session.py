"""MqttSession against the embedded broker: will, retain, reconnect, outbox, dispatch, QoS."""

from __future__ import annotations

import asyncio
import json
import socket
import subprocess
import sys
import textwrap
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import pytest

from tests.integration.mqtt_helpers import client_for, watching
from vda5050.broker import BrokerAddress, EmbeddedBroker
from vda5050.mqtt import InboundMessage, MqttSession, MqttSettings, Outgoing, Will
from vda5050.topics import Topic

pytestmark = pytest.mark.integration


def settings(address: BrokerAddress, url: str | None = None) -> MqttSettings:
    """Quick reconnects for tests; ``url`` overrides the broker URL (e.g. with credentials)."""
    return MqttSettings(
        url=url or address.url, keepalive_s=5, reconnect_min_s=0.05, reconnect_max_s=0.5
    )


@asynccontextmanager
async def running(session: MqttSession, *, connected: bool = True) -> AsyncIterator[MqttSession]:
    """Run ``session`` in a task group; stop it cleanly afterwards."""
    async with asyncio.TaskGroup() as group:
        group.create_task(session.run(), name="test.session")
        if connected:
            async with asyncio.timeout(5):
                await session.wait_connected()
        try:
            yield session
        finally:
            await session.stop()


async def test_publish_uses_each_topics_qos_and_retain(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """R04-R07: connection is QoS 1 retained, factsheet retained, state QoS 0 not retained."""
    prefix = f"{unique_interface_name}/v2/acme/r1"
    async with watching(embedded_broker, f"{prefix}/#", qos=1) as watcher:
        async with running(MqttSession(settings(embedded_broker))) as session:
            session.publish(f"{prefix}/connection", Topic.CONNECTION, b"c")
            session.publish(f"{prefix}/factsheet", Topic.FACTSHEET, b"f")
            session.publish(f"{prefix}/state", Topic.STATE, b"s")
            (connection,) = await watcher.wait_for(f"{prefix}/connection")
            (state,) = await watcher.wait_for(f"{prefix}/state")
        assert connection.qos == 1
        assert not state.retain
        # amqtt raises delivery QoS to the subscription's (mqtt-notes defect 4), so the state's
        # QoS 0 is checked against Mosquitto in test_mqtt_session_mosquitto.py.
    # A late subscriber gets what was retained, and only that.
    async with watching(embedded_broker, f"{prefix}/#") as late:
        await late.wait_for(f"{prefix}/factsheet")
        await late.wait_for(f"{prefix}/connection")
        await asyncio.sleep(0.2)
        assert not late.on(f"{prefix}/state")


async def test_retained_connection_reaches_a_late_subscriber(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """R06: the retained connection state is delivered to a subscriber that comes later."""
    topic = f"{unique_interface_name}/v2/acme/r1/connection"
    async with running(MqttSession(settings(embedded_broker))) as session:
        session.publish(topic, Topic.CONNECTION, b'{"connectionState":"ONLINE"}')
        await asyncio.sleep(0.2)
    async with watching(embedded_broker, topic) as watcher:
        (message,) = await watcher.wait_for(topic)
        assert message.retain
        assert json.loads(message.payload)["connectionState"] == "ONLINE"


WILL_CLIENT = textwrap.dedent(
    """
    import asyncio, sys
    from vda5050.logs import configure_logging
    from vda5050.mqtt import MqttSession, MqttSettings, Will
    configure_logging(json=True, level="WARNING")
    async def main():
        url, topic = sys.argv[1], sys.argv[2]
        session = MqttSession(MqttSettings(url=url, keepalive_s=60),
                              will=Will(topic, b"CONNECTIONBROKEN"))
        task = asyncio.create_task(session.run())
        await session.wait_connected()
        print("connected", flush=True)
        await task
    asyncio.run(main())
    """
)


def start_will_client(address: BrokerAddress, topic: str) -> subprocess.Popen[str]:
    process = subprocess.Popen(  # noqa: S603 - our own interpreter and script
        [sys.executable, "-c", WILL_CLIENT, address.url, topic],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env={"PYTHONPATH": "src"},
    )
    assert process.stdout is not None
    with process.stdout:
        line = process.stdout.readline().strip()
    assert line == "connected", line
    return process


async def test_will_is_delivered_when_the_connection_drops(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """R11: a client killed without DISCONNECT gets its retained last will delivered."""
    topic = f"{unique_interface_name}/v2/acme/r1/connection"
    async with watching(embedded_broker, topic) as watcher:
        process = await asyncio.to_thread(start_will_client, embedded_broker, topic)
        process.kill()
        await asyncio.to_thread(process.wait, 5)
        (will,) = await watcher.wait_for(topic)
        assert will.payload == b"CONNECTIONBROKEN"
        assert will.qos == 1


async def test_stop_publishes_final_messages_then_disconnects_cleanly(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """R10: the final message (OFFLINE) is published and the will is not delivered."""
    topic = f"{unique_interface_name}/v2/acme/r1/connection"
    session = MqttSession(settings(embedded_broker), will=Will(topic, b"CONNECTIONBROKEN"))
    async with watching(embedded_broker, topic) as watcher:
        async with asyncio.TaskGroup() as group:
            group.create_task(session.run(), name="test.session")
            async with asyncio.timeout(5):
                await session.wait_connected()
            await session.stop(Outgoing(topic, Topic.CONNECTION, b"OFFLINE"))
        await watcher.wait_for(topic)
        await asyncio.sleep(0.3)
        assert [m.payload for m in watcher.on(topic)] == [b"OFFLINE"]


async def test_session_reconnects_and_resubscribes_after_broker_restart(
    unused_tcp_port: int, unique_interface_name: str
) -> None:
    """After the broker restarts the session reconnects, subscribes again and reruns its hook."""
    topic = f"{unique_interface_name}/v2/acme/r1/order"
    received: list[bytes] = []
    hooks: list[int] = []
    got = asyncio.Event()

    async def on_order(message: InboundMessage) -> None:
        received.append(message.payload)
        got.set()

    async def on_connected() -> None:
        hooks.append(1)

    broker = EmbeddedBroker(port=unused_tcp_port)
    address = await broker.start()
    session = MqttSession(settings(address), on_connected=on_connected)
    session.subscribe(topic, on_order)
    async with running(session):
        await broker.stop()
        await asyncio.sleep(0.3)
        assert not session.connected
        session.publish(topic.replace("order", "state"), Topic.STATE, b"while-down")
        broker = EmbeddedBroker(port=unused_tcp_port)
        await broker.start()
        try:
            async with asyncio.timeout(10):
                while session.connect_count < 2 or not session.connected:
                    await asyncio.sleep(0.05)
            async with client_for(address) as publisher:
                await publisher.publish(topic, b"after-restart", qos=1)
                async with asyncio.timeout(5):
                    await got.wait()
        finally:
            await session.stop()
            await broker.stop()
    assert received == [b"after-restart"]
    assert len(hooks) == 2


async def test_first_connection_is_retried_and_queued_state_is_sent(
    unused_tcp_port: int, unique_interface_name: str
) -> None:
    """With no broker yet, publish never raises; the latest state goes out once connected."""
    topic = f"{unique_interface_name}/v2/acme/r1/state"
    address = BrokerAddress("127.0.0.1", unused_tcp_port)
    session = MqttSession(settings(address))
    async with asyncio.TaskGroup() as group:
        group.create_task(session.run(), name="test.session")
        session.publish(topic, Topic.STATE, b"old")
        session.publish(topic, Topic.STATE, b"new")
        session.publish(topic.replace("state", "visualization"), Topic.VISUALIZATION, b"v")
        await asyncio.sleep(0.5)  # several refused connection attempts
        async with EmbeddedBroker(port=unused_tcp_port) as started:
            async with watching(started, f"{unique_interface_name}/#") as watcher:
                async with asyncio.timeout(10):
                    await session.wait_connected()
                await watcher.wait_for(topic)
                await asyncio.sleep(0.2)
                assert [m.payload for m in watcher.messages] == [b"new"]
            await session.stop()


async def test_handler_errors_do_not_stop_the_session(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A handler that raises is logged and the next message is still handled."""
    topic = f"{unique_interface_name}/v2/acme/r1/instantActions"
    seen: list[bytes] = []
    done = asyncio.Event()

    async def handler(message: InboundMessage) -> None:
        seen.append(message.payload)
        if message.payload == b"boom":
            raise ValueError("boom")
        done.set()

    session = MqttSession(settings(embedded_broker))
    session.subscribe(topic, handler)
    async with running(session):
        async with client_for(embedded_broker) as publisher:
            await publisher.publish(topic, b"boom", qos=1)
            await publisher.publish(topic, b"fine", qos=1)
        async with asyncio.timeout(5):
            await done.wait()
    assert seen == [b"boom", b"fine"]


async def test_only_matching_subscriptions_receive(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Messages are dispatched by topic filter; each handler sees only its own topics."""
    base = f"{unique_interface_name}/v2"
    states: list[str] = []
    connections: list[str] = []
    done = asyncio.Event()

    async def on_state(message: InboundMessage) -> None:
        states.append(message.topic)

    async def on_connection(message: InboundMessage) -> None:
        connections.append(message.topic)
        done.set()

    session = MqttSession(settings(embedded_broker))
    session.subscribe(f"{base}/+/+/state", on_state)
    session.subscribe(f"{base}/+/+/connection", on_connection)
    async with running(session):
        async with client_for(embedded_broker) as publisher:
            await publisher.publish(f"{base}/a/1/state", b"{}", qos=1)
            await publisher.publish(f"{base}/a/1/factsheet", b"{}", qos=1)
            await publisher.publish(f"{base}/b/2/connection", b"{}", qos=1)
        async with asyncio.timeout(5):
            await done.wait()
    assert states == [f"{base}/a/1/state"]
    assert connections == [f"{base}/b/2/connection"]


async def test_session_socket_has_nagle_disabled(embedded_broker: BrokerAddress) -> None:
    """The session's TCP socket has TCP_NODELAY set (Nagle adds ~25 ms per message)."""
    session = MqttSession(settings(embedded_broker))
    async with running(session):
        sock = session._current_socket()
        assert sock is not None
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) != 0


async def test_wrong_credentials_keep_retrying_without_crashing(unused_tcp_port: int) -> None:
    """A refused login is retried with backoff; the session neither crashes nor connects."""
    async with EmbeddedBroker(port=unused_tcp_port, username="u", password="right") as address:
        bad = MqttSession(
            settings(
                BrokerAddress(address.host, address.port),
                url=f"mqtt://u:wrong@{address.host}:{address.port}",
            )
        )
        good = MqttSession(settings(address, url=f"mqtt://u:right@{address.host}:{address.port}"))
        async with running(good), running(bad, connected=False):
            await asyncio.sleep(0.8)
            assert not bad.connected
            assert good.connected
