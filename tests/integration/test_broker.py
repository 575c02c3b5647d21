"""The embedded broker: addressing, authentication, last will, and amqtt's defects fixed."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import time
from typing import TYPE_CHECKING

import aiomqtt
import pytest

from vda5050.broker import BrokerAddress, EmbeddedBroker

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

pytestmark = pytest.mark.integration

NODELAY = [(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)]
CONNACK_ACCEPTED = b"\x20\x02\x00\x00"
PINGREQ, PINGRESP = b"\xc0\x00", b"\xd0\x00"
USER, PASS = "master", "s3cret"


def mqtt_client(address: BrokerAddress, **options: object) -> aiomqtt.Client:
    return aiomqtt.Client(
        address.host,
        address.port,
        socket_options=NODELAY,
        timeout=5,
        **options,  # type: ignore[arg-type]  # keyword arguments of aiomqtt.Client
    )


def connect_packet(client_id: str, *, keepalive: int, will_topic: str, will: bytes) -> bytes:
    """An MQTT 3.1.1 CONNECT with clean session and a QoS 0 will that is not retained."""

    def field(data: bytes) -> bytes:
        return len(data).to_bytes(2, "big") + data

    clean_session_and_will = 0x02 | 0x04
    body = (
        field(b"MQTT")
        + bytes([4, clean_session_and_will])
        + keepalive.to_bytes(2, "big")
        + field(client_id.encode())
        + field(will_topic.encode())
        + field(will)
    )
    assert len(body) < 128, "one-byte remaining length only"
    return bytes([0x10, len(body)]) + body


@contextlib.asynccontextmanager
async def raw_client(
    address: BrokerAddress, client_id: str, *, keepalive: int, will_topic: str
) -> AsyncIterator[tuple[asyncio.StreamReader, asyncio.StreamWriter]]:
    """A bare TCP client that has connected (with a will) and then sends only what the test does.

    Leaving the context closes the socket without sending DISCONNECT.
    """
    reader, writer = await asyncio.open_connection(address.host, address.port)
    try:
        writer.write(
            connect_packet(client_id, keepalive=keepalive, will_topic=will_topic, will=b"gone")
        )
        await writer.drain()
        assert await reader.readexactly(4) == CONNACK_ACCEPTED
        yield reader, writer
    finally:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()


async def connected_client(
    stack: contextlib.AsyncExitStack, address: BrokerAddress, *topic_filters: str
) -> aiomqtt.Client:
    client = await stack.enter_async_context(mqtt_client(address))
    for topic_filter in topic_filters:
        await client.subscribe(topic_filter, qos=1)
    return client


async def next_message(client: aiomqtt.Client) -> aiomqtt.Message:
    return await anext(aiter(client.messages))


async def messages_until(client: aiomqtt.Client, sentinel: bytes) -> list[aiomqtt.Message]:
    """Every message the client receives up to and including one whose payload is `sentinel`."""
    received = []
    async for message in client.messages:
        received.append(message)
        if message.payload == sentinel:
            return received
    raise AssertionError("unreachable: the message iterator never ends by itself")


async def test_port_zero_reports_the_bound_port() -> None:
    """Started on port 0, the broker reports the port it bound, and clients can reach it there."""
    broker = EmbeddedBroker(port=0)
    with pytest.raises(RuntimeError, match="not running"):
        _ = broker.address
    async with asyncio.timeout(5), broker as address:
        assert address == broker.address
        assert address.host == "127.0.0.1"
        assert address.port > 0
        assert address.url == f"mqtt://127.0.0.1:{address.port}"
        async with mqtt_client(address) as client:
            await client.subscribe("port/check", qos=1)
            await client.publish("port/check", b"hello", qos=1)
            assert (await next_message(client)).payload == b"hello"


async def test_start_on_a_busy_port_raises_oserror(embedded_broker: BrokerAddress) -> None:
    """Starting on a port that another listener holds raises OSError and leaves it stopped."""
    broker = EmbeddedBroker(port=embedded_broker.port)
    async with asyncio.timeout(5):
        with pytest.raises(OSError, match="cannot listen"):
            await broker.start()
    with pytest.raises(RuntimeError, match="not running"):
        _ = broker.address


async def test_anonymous_clients_are_accepted_by_default(embedded_broker: BrokerAddress) -> None:
    """Without configured credentials, a client without username or password may connect."""
    async with asyncio.timeout(5), mqtt_client(embedded_broker) as client:
        await client.subscribe("anonymous/check", qos=1)


async def test_configured_credentials_are_accepted(unique_interface_name: str) -> None:
    """With username and password configured, a client presenting exactly them may connect."""
    topic = f"{unique_interface_name}/auth"
    async with (
        asyncio.timeout(5),
        EmbeddedBroker(username=USER, password=PASS) as address,
        mqtt_client(address, username=USER, password=PASS) as client,
    ):
        await client.subscribe(topic, qos=1)
        await client.publish(topic, b"ok", qos=1)
        assert (await next_message(client)).payload == b"ok"


@pytest.mark.parametrize(
    ("username", "password"),
    [(None, None), (USER, "wrong"), ("intruder", PASS), (USER, None)],
)
async def test_other_credentials_are_refused(username: str | None, password: str | None) -> None:
    """With username and password configured, any other credentials get their CONNECT refused."""
    async with asyncio.timeout(5), EmbeddedBroker(username=USER, password=PASS) as address:
        client = mqtt_client(address, username=username, password=password)
        with pytest.raises(aiomqtt.MqttCodeError, match=r"Not authorized"):
            async with client:
                pass


async def test_will_is_sent_when_the_socket_closes_without_disconnect(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A client whose socket closes without DISCONNECT has its will published."""
    will_topic = f"{unique_interface_name}/will"
    async with asyncio.timeout(5), contextlib.AsyncExitStack() as stack:
        observer = await connected_client(stack, embedded_broker, will_topic)
        async with raw_client(embedded_broker, "dropping", keepalive=60, will_topic=will_topic):
            pass
        will = await next_message(observer)
        assert (will.topic.value, will.payload) == (will_topic, b"gone")


async def test_will_is_not_sent_after_a_clean_disconnect(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A client that disconnects cleanly has its will discarded."""
    will_topic = f"{unique_interface_name}/will"
    async with asyncio.timeout(5), contextlib.AsyncExitStack() as stack:
        observer = await connected_client(stack, embedded_broker, will_topic)
        publisher = await connected_client(stack, embedded_broker)
        async with mqtt_client(embedded_broker, will=aiomqtt.Will(will_topic, b"gone")):
            pass
        await asyncio.sleep(0.2)  # let the broker finish the disconnect before the sentinel
        await publisher.publish(will_topic, b"sentinel", qos=1)
        received = await messages_until(observer, b"sentinel")
        assert [message.payload for message in received] == [b"sentinel"]


async def test_expired_keepalive_disconnects_and_sends_the_will(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A client silent for 1.5x its keep-alive is dropped with its will; others are not."""
    frozen, pinging, unlimited = (
        f"{unique_interface_name}/{name}" for name in ("frozen", "ping", "ka0")
    )
    async with asyncio.timeout(6), contextlib.AsyncExitStack() as stack:
        observer = await connected_client(stack, embedded_broker, f"{unique_interface_name}/+")
        await stack.enter_async_context(
            raw_client(embedded_broker, "frozen", keepalive=1, will_topic=frozen)
        )
        await stack.enter_async_context(
            raw_client(embedded_broker, "unlimited", keepalive=0, will_topic=unlimited)
        )
        ping_reader, ping_writer = await stack.enter_async_context(
            raw_client(embedded_broker, "pinging", keepalive=1, will_topic=pinging)
        )
        started = time.monotonic()

        async def ping_loop() -> None:
            while True:
                await asyncio.sleep(0.5)
                ping_writer.write(PINGREQ)
                assert await ping_reader.readexactly(2) == PINGRESP

        async with asyncio.TaskGroup() as tg:
            pinger = tg.create_task(ping_loop(), name="test.ping_loop")
            will = await next_message(observer)
            elapsed = time.monotonic() - started
            assert will.topic.value == frozen
            assert 1.0 <= elapsed <= 2.5, f"will after {elapsed:.2f} s, expected about 1.5 s"
            with pytest.raises(TimeoutError):  # nobody else's will follows
                async with asyncio.timeout(0.5):
                    await next_message(observer)
            pinger.cancel()


async def test_retained_messages_are_replayed_only_for_own_subscriptions(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A client gets retained messages only for what it subscribes to, not for others' filters."""
    topics = [f"{unique_interface_name}/{name}" for name in ("a", "b", "c")]
    async with asyncio.timeout(5), contextlib.AsyncExitStack() as stack:
        publisher = await connected_client(stack, embedded_broker)
        for topic in topics:
            await publisher.publish(topic, f"retained {topic}".encode(), qos=1, retain=True)
        await connected_client(stack, embedded_broker, "#")
        newcomer = await connected_client(stack, embedded_broker, topics[1])
        await publisher.publish(topics[1], b"sentinel", qos=1)
        received = await messages_until(newcomer, b"sentinel")
        assert [(m.topic.value, m.payload, m.retain) for m in received] == [
            (topics[1], f"retained {topics[1]}".encode(), True),
            (topics[1], b"sentinel", False),
        ]


async def test_retained_messages_are_replayed_for_an_own_wildcard_subscription(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A client subscribing with a wildcard gets every matching retained message."""
    topics = [f"{unique_interface_name}/{name}" for name in ("a", "b", "c")]
    async with asyncio.timeout(5), contextlib.AsyncExitStack() as stack:
        publisher = await connected_client(stack, embedded_broker)
        for topic in topics:
            await publisher.publish(topic, b"retained", qos=1, retain=True)
        subscriber = await connected_client(stack, embedded_broker, f"{unique_interface_name}/+")
        received = [await next_message(subscriber) for _ in topics]
        assert sorted(message.topic.value for message in received) == topics
        assert all(message.retain for message in received)


async def test_connect_churn_leaves_every_session_working(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """200 clients connecting 5 ms apart, each with a retained topic, all subscribe and receive."""
    count = 200
    topics = [f"{unique_interface_name}/agv{i}" for i in range(count)]
    subscribed: set[str] = set()
    all_subscribed = asyncio.Event()

    async def churn_client(topic: str) -> list[tuple[str, bytes]]:
        # own timeout: on Python 3.11 a cancel can be lost in aiomqtt's wait_for while connecting
        async with asyncio.timeout(10), mqtt_client(embedded_broker) as client:
            await client.subscribe(topic, qos=1)
            received = [await next_message(client)]
            subscribed.add(topic)
            if len(subscribed) == count:
                all_subscribed.set()
            received.append(await next_message(client))
        return [(str(m.topic.value), bytes(m.payload)) for m in received]

    async with asyncio.timeout(15), contextlib.AsyncExitStack() as stack:
        publisher = await connected_client(stack, embedded_broker)
        for topic in topics:
            await publisher.publish(topic, b"retained", qos=1, retain=True)
        async with asyncio.TaskGroup() as tg:
            clients = []
            for i, topic in enumerate(topics):
                clients.append(tg.create_task(churn_client(topic), name=f"test.churn_client_{i}"))
                await asyncio.sleep(0.005)
            await all_subscribed.wait()
            for topic in topics:
                await publisher.publish(topic, b"live", qos=1)
    for topic, client in zip(topics, clients, strict=True):
        assert client.result() == [(topic, b"retained"), (topic, b"live")]


async def test_persistent_sessions_reconnecting_under_churn_keep_working(
    unique_interface_name: str,
) -> None:
    """100 persistent sessions reconnecting 5 ms apart, while others subscribe, all keep working."""
    count, subtopics = 100, ("order", "instantActions", "connection")
    agvs = [f"{unique_interface_name}/agv{i}" for i in range(count)]
    reconnected: set[str] = set()
    all_reconnected = asyncio.Event()

    async def reconnecting_client(address: BrokerAddress, agv: str) -> list[tuple[str, bytes]]:
        # amqtt keeps sessions only for clients that are not anonymous (mqtt-notes, defect 5),
        # and on reconnect replays retained messages for the session's filters, across awaits.
        options = {
            "identifier": agv.replace("/", "-"),
            "clean_session": False,
            "username": USER,
            "password": PASS,
        }
        async with asyncio.timeout(10):  # see churn_client
            async with mqtt_client(address, **options) as client:
                for subtopic in subtopics:
                    await client.subscribe(f"{agv}/{subtopic}", qos=1)
                    assert (await next_message(client)).payload == b"retained"
            async with mqtt_client(address, **options) as client:
                reconnected.add(agv)
                if len(reconnected) == count:
                    all_reconnected.set()
                received = await messages_until(client, b"live")
        return [(str(m.topic.value), bytes(m.payload)) for m in received]

    async with (
        asyncio.timeout(15),
        EmbeddedBroker(username=USER, password=PASS) as address,
        mqtt_client(address, username=USER, password=PASS) as publisher,
    ):
        for agv in agvs:
            for subtopic in subtopics:
                await publisher.publish(f"{agv}/{subtopic}", b"retained", qos=1, retain=True)
        async with asyncio.TaskGroup() as tg:
            clients = []
            for i, agv in enumerate(agvs):
                run = reconnecting_client(address, agv)
                clients.append(tg.create_task(run, name=f"test.reconnecting_client_{i}"))
                await asyncio.sleep(0.005)
            await all_reconnected.wait()
            for agv in agvs:
                await publisher.publish(f"{agv}/order", b"live", qos=1)
    for agv, client in zip(agvs, clients, strict=True):
        received = client.result()
        assert received[-1] == (f"{agv}/order", b"live")
        assert all(topic.startswith(f"{agv}/") for topic, _ in received)


async def test_stop_disconnects_clients_and_releases_the_port() -> None:
    """stop() closes client connections, leaves no task behind, is idempotent and frees the port."""
    tasks_before = asyncio.all_tasks()
    broker = EmbeddedBroker()
    async with asyncio.timeout(5):
        address = await broker.start()
        async with raw_client(address, "connected", keepalive=60, will_topic="stop/will") as (
            reader,
            _,
        ):
            await broker.stop()
            assert await reader.read() == b"", "the broker closed the connection"
        await broker.stop()
        assert asyncio.all_tasks() <= tasks_before
        async with EmbeddedBroker(port=address.port) as again, mqtt_client(again) as client:
            assert again.port == address.port
            await client.subscribe("stop/check", qos=1)
        assert await broker.start() == address, "a restart keeps the bound port"
        await broker.stop()
