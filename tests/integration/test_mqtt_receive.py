"""MqttSession's receive path (its own queue fed by paho, handled in batches) against amqtt and
Mosquitto: a burst arrives complete and in order without holding the event loop, a receive-only
session notices a broken connection and receives again after reconnecting, and the backlog it
reports goes back to 0."""

from __future__ import annotations

import asyncio
import socket
from dataclasses import replace

import pytest
from paho.mqtt import publish as paho_publish

from tests.integration.mqtt_helpers import client_for
from tests.integration.test_mqtt_session import running, settings
from vda5050 import mqtt as mqtt_module
from vda5050.broker import BrokerAddress
from vda5050.misc_ticker import MiscTicker
from vda5050.mqtt import InboundMessage, MqttSession
from vda5050.socket_reader import READ_BURST
from vda5050.topics import Topic

pytestmark = pytest.mark.integration


async def publish_numbered(broker: BrokerAddress, topic: str, count: int) -> None:
    """``count`` QoS 0 messages "0", "1", ... on ``topic``, all at once (paho, in a thread)."""
    flood: paho_publish.MessagesList = [(topic, str(n).encode(), 0, False) for n in range(count)]
    await asyncio.to_thread(paho_publish.multiple, flood, hostname=broker.host, port=broker.port)


async def test_a_burst_arrives_in_order_and_other_tasks_keep_running(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """3000 messages published at once reach the handler all and in publication order. The
    handler of the first one takes a while, so the rest piles up in the session's queue; while
    that pile is handled, a task that only yields keeps getting turns (the receive loop yields
    between batches). Afterwards the session reports no backlog."""
    topic = f"{unique_interface_name}/v2/acme/r1/state"
    count = 3000
    seen: list[int] = []
    ticks = 0
    ticks_at: dict[int, int] = {}

    async def handler(message: InboundMessage) -> None:
        seen.append(int(message.payload))
        if len(seen) == 1:
            await asyncio.sleep(1)  # the burst is read into the queue meanwhile
            ticks_at[1] = ticks
        elif len(seen) == count:
            ticks_at[count] = ticks

    async def ticker() -> None:
        nonlocal ticks
        while True:
            await asyncio.sleep(0)
            ticks += 1

    session = MqttSession(settings(broker))
    session.subscribe(topic, handler)
    async with running(session):
        await publish_numbered(broker, topic, count)
        ticking = asyncio.create_task(ticker())
        async with asyncio.timeout(30):
            while count not in ticks_at:
                await asyncio.sleep(0.01)
        ticking.cancel()
        async with asyncio.timeout(5):
            while session.inbound_backlog_bytes() > 0:
                await asyncio.sleep(0.01)
    assert seen == list(range(count))
    # the pile was handled in batches with a turn for others between them
    assert ticks_at[count] - ticks_at[1] >= count // (2 * mqtt_module._RECEIVE_BURST)


async def test_a_lagging_session_stops_reading_and_loses_nothing(
    broker: BrokerAddress, unique_interface_name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """While the messages read but not handled are over the bound, the session stops reading
    (a flood must not grow a slow service's memory without limit) and the broker waits; it reads
    again once it caught up, and every message arrives, in order."""
    monkeypatch.setattr(mqtt_module, "_INBOUND_PAUSE", (200, 1 << 30))
    monkeypatch.setattr(mqtt_module, "_INBOUND_RESUME", (50, 1 << 30))
    topic = f"{unique_interface_name}/v2/acme/r1/state"
    count = 3000
    seen: list[int] = []
    most_unhandled = 0

    session = MqttSession(settings(broker))

    async def handler(message: InboundMessage) -> None:
        nonlocal most_unhandled
        seen.append(int(message.payload))
        most_unhandled = max(most_unhandled, len(session._inbound))
        if len(seen) == 1:
            await asyncio.sleep(1)  # lagging: the burst arrives meanwhile

    session.subscribe(topic, handler)
    async with running(session):
        await publish_numbered(broker, topic, count)
        async with asyncio.timeout(30):
            while len(seen) < count:
                await asyncio.sleep(0.01)
        assert session.reader is not None
        assert not session.reader.paused
    assert seen == list(range(count))
    assert session.read_pauses >= 1
    assert most_unhandled <= 200 + READ_BURST


async def test_a_receive_only_session_notices_a_broken_connection_and_receives_again(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A session that only receives (master control with nothing to send) learns that its
    connection broke from the receive path, reconnects, subscribes again and gets the next
    message."""
    topic = f"{unique_interface_name}/v2/acme/r1/state"
    got: list[bytes] = []

    async def handler(message: InboundMessage) -> None:
        got.append(message.payload)

    session = MqttSession(settings(broker))
    session.subscribe(topic, handler)
    async with running(session), client_for(broker) as sender:
        await sender.publish(topic, b"before")
        async with asyncio.timeout(5):
            while got != [b"before"]:
                await asyncio.sleep(0.01)
        sock = session._current_socket()
        assert sock is not None
        sock.shutdown(socket.SHUT_RDWR)
        async with asyncio.timeout(10):
            while session.connect_count < 2 or not session.connected:
                await asyncio.sleep(0.01)
        async with asyncio.timeout(10):
            while b"after" not in got:
                await sender.publish(topic, b"after")
                await asyncio.sleep(0.2)
    assert got[0] == b"before"
    assert b"after" in got


async def test_messages_read_before_a_broken_connection_are_handled_after_the_reconnect(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """The connection breaks while a handler is busy and more messages wait behind it; the
    failed publication ends the connection and its tasks. The waiting messages are not lost
    with it: they are handled, in order, once the session is connected again."""
    topic = f"{unique_interface_name}/v2/acme/r1/instantActions"
    handled: list[bytes] = []
    busy = asyncio.Event()

    async def handler(message: InboundMessage) -> None:
        if message.payload == b"first":
            busy.set()
            await asyncio.sleep(30)  # cancelled when the connection ends
        handled.append(message.payload)

    session = MqttSession(settings(broker))
    session.subscribe(topic, handler)
    async with running(session), client_for(broker) as sender:
        await sender.publish(topic, b"first")
        async with asyncio.timeout(5):
            await busy.wait()
        for payload in (b"second", b"third"):
            await sender.publish(topic, payload)
        async with asyncio.timeout(5):
            while len(session._inbound) < 2:
                await asyncio.sleep(0.01)
        sock = session._current_socket()
        assert sock is not None
        sock.shutdown(socket.SHUT_RDWR)
        await asyncio.sleep(0.2)  # paho sees the end of the connection
        session.publish(f"{unique_interface_name}/v2/acme/r1/state", Topic.STATE, b"{}")
        async with asyncio.timeout(10):
            while handled != [b"second", b"third"]:
                await asyncio.sleep(0.01)
        assert session.connect_count == 2


async def test_keep_alive_runs_on_the_shared_ticker(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Two idle sessions with a 3 s keep-alive stay connected for 7 s (the broker drops a
    client silent for 1.5 keep-alives; paho pings within a keep-alive and a round of the
    timer): their PINGREQs come from one shared timer, which holds both while they are
    connected and none once they stopped (the keep-alive of R12 and of a vehicle's last will,
    R11, depends on it)."""
    del unique_interface_name
    quick = replace(settings(broker), keepalive_s=3)
    sessions = [MqttSession(replace(quick, client_id=f"ticker-{n}")) for n in range(2)]
    async with running(sessions[0]), running(sessions[1]):
        ticker = MiscTicker.of(asyncio.get_running_loop())
        assert len(ticker) == 2
        rounds = ticker.rounds
        await asyncio.sleep(7)
        assert ticker.rounds >= rounds + 6
        assert all(s.connected for s in sessions)
        assert [s.connect_count for s in sessions] == [1, 1]
    async with asyncio.timeout(5):
        while len(ticker):
            await asyncio.sleep(0.05)


async def test_qos0_messages_skip_paho_and_keep_their_place_among_qos1_ones(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """QoS 0 publications are taken from the reader's buffer without paho
    (vda5050.socket_reader), QoS 1 ones by paho (it acknowledges them): mixed on one topic
    they reach the handler all and in publication order; on a topic subscribed at QoS 0 they
    arrive at QoS 0, read without paho; a retained message delivered at the subscription
    keeps its retain flag."""
    mixed = f"{unique_interface_name}/v2/acme/r1/state"
    plain = f"{unique_interface_name}/v2/acme/r2/state"
    kept = f"{unique_interface_name}/v2/acme/r1/connection"
    count = 400
    handled: dict[str, list[tuple[bytes, int, bool]]] = {mixed: [], plain: [], kept: []}

    async def handler(message: InboundMessage) -> None:
        handled[message.topic].append((message.payload, message.qos, message.retain))

    async with client_for(broker) as sender:
        await sender.publish(kept, b"ONLINE", qos=0, retain=True)
    session = MqttSession(settings(broker))
    session.subscribe(mixed, handler, 1)
    session.subscribe(plain, handler, 0)
    session.subscribe(kept, handler, 1)
    async with running(session), client_for(broker) as sender:
        for n in range(count):
            await sender.publish(mixed, str(n).encode(), qos=n % 2)
            await sender.publish(plain, str(n).encode(), qos=0)
        async with asyncio.timeout(10):
            while len(handled[mixed]) + len(handled[plain]) < 2 * count or not handled[kept]:
                await asyncio.sleep(0.01)
        assert session.reader is not None
        raw_reads = session.reader.raw_reads
    (online,) = handled[kept]
    assert (online[0], online[2]) == (b"ONLINE", True)
    assert [p for p, _, _ in handled[mixed]] == [str(n).encode() for n in range(count)]
    # amqtt delivers at the subscription's QoS, Mosquitto at the publication's (MQTT 3.1.1
    # §3.8.4 asks for the lower): either way paho acknowledges what came at QoS 1
    assert all(q in (n % 2, 1) for n, (_, q, _) in enumerate(handled[mixed]))
    assert handled[plain] == [(str(n).encode(), 0, False) for n in range(count)]
    assert raw_reads >= count // 2
