"""MqttSession's direct socket writes (vda5050.socket_writer, paho's queue written at once and
QoS 0 packets written without paho) against amqtt and Mosquitto:
bursts arrive complete and in order at QoS 0 and 1, a burst larger than the socket buffer is
finished through the loop's writer, and a connection lost mid-burst ends the connection as it
did before (reconnect, the outbox's rest is sent, nothing is duplicated or reordered)."""

from __future__ import annotations

import asyncio
import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import aiomqtt
import pytest
from paho.mqtt import client as paho
from paho.mqtt.enums import CallbackAPIVersion
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.reasoncodes import ReasonCode

from tests.integration.mqtt_helpers import Watcher, watching
from tests.integration.test_mqtt_session import running, settings
from vda5050.broker import BrokerAddress
from vda5050.mqtt import MqttSession
from vda5050.topics import Topic

pytestmark = pytest.mark.integration

#: A send buffer far smaller than a burst, so the kernel refuses part of it (EAGAIN).
SMALL_SNDBUF = 4096


def numbered(watcher: Watcher, topic_prefix: str) -> list[int]:
    """The numbers carried by the watched messages under ``topic_prefix``, in arrival order."""
    return [
        int(bytes(m.payload[:8])) for m in watcher.messages if str(m.topic).startswith(topic_prefix)
    ]


def payload(number: int, size: int = 8) -> bytes:
    return f"{number:08d}".encode().ljust(size, b".")


async def wait_numbers(watcher: Watcher, prefix: str, last: int, timeout: float) -> list[int]:
    """Until the message numbered ``last`` arrived; every number seen, in order."""
    async with asyncio.timeout(timeout):
        while last not in numbered(watcher, prefix):
            watcher.arrived.clear()
            await watcher.arrived.wait()
    return numbered(watcher, prefix)


def shrink_send_buffer(session: MqttSession) -> None:
    sock = session._current_socket()
    assert sock is not None
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SMALL_SNDBUF)


@asynccontextmanager
async def bursting(
    broker: BrokerAddress, topic: str, count: int, size: int, kind: Topic = Topic.ORDER
) -> AsyncIterator[tuple[Watcher, MqttSession]]:
    """A connected session with a shrunken send buffer that has just queued ``count``
    numbered QoS 0 publications (``kind``) of ``size`` bytes on ``topic``, and a watcher of
    the topic."""
    async with (
        watching(broker, topic, qos=0) as watcher,
        running(MqttSession(settings(broker))) as session,
    ):
        shrink_send_buffer(session)
        for number in range(count):
            session.publish(topic, kind, payload(number, size))
        yield watcher, session


async def test_qos0_burst_arrives_complete_and_in_order(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """2000 QoS 0 publications queued at once arrive, all of them, in publication order; they
    are written as they are published, straight to the socket."""
    topic = f"{unique_interface_name}/v2/acme/r1/order"
    count = 2000
    async with (
        watching(broker, topic, qos=0) as watcher,
        running(MqttSession(settings(broker))) as session,
    ):
        for number in range(count):
            session.publish(topic, Topic.ORDER, payload(number, 200))
        seen = await wait_numbers(watcher, topic, count - 1, timeout=20)
        assert session.writer is not None
        assert session.writer.raw_writes >= 1  # written by write_qos0, not through paho
    assert seen == list(range(count))


async def test_qos1_burst_arrives_complete_and_in_order(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """300 QoS 1 publications (connection, retained, one topic each so the outbox keeps them
    all) arrive complete and in order, each acknowledged before the next (as before)."""
    prefix = f"{unique_interface_name}/v2/acme"
    count = 300
    async with (
        watching(broker, f"{prefix}/+/connection", qos=1) as watcher,
        running(MqttSession(settings(broker))) as session,
    ):
        for number in range(count):
            session.publish(f"{prefix}/r{number}/connection", Topic.CONNECTION, payload(number))
        seen = await wait_numbers(watcher, prefix, count - 1, timeout=20)
    assert seen == list(range(count))
    assert {m.qos for m in watcher.messages} == {1}


async def test_burst_larger_than_the_socket_buffer_arrives_completely(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """With a 4 KiB send buffer, 150 publications of 32 KiB cannot be written at once: the rest
    is written when the socket becomes writable again (the loop's writer), and every one
    arrives, in order."""
    topic = f"{unique_interface_name}/v2/acme/r1/order"
    count = 150
    async with bursting(broker, topic, count, 32 * 1024) as (watcher, session):
        seen = await wait_numbers(watcher, topic, count - 1, timeout=30)
        assert session.writer is not None
        assert session.writer.writer_registrations >= 1
        assert len(session.outbox) == 0
    assert seen == list(range(count))


async def test_connection_lost_mid_burst_reconnects_and_sends_the_rest(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """The connection breaks while a burst is being written: the session reconnects and
    publishes what the outbox still held; what arrives is in order, without duplicates, and
    ends with the burst's last message (a QoS 0 message on the wire when it broke may be lost,
    as before)."""
    topic = f"{unique_interface_name}/v2/acme/r1/order"
    count = 1500
    async with bursting(broker, topic, count, 4096) as (watcher, session):
        async with asyncio.timeout(10):
            while len(session.outbox) > count - 100:  # the first hundred are out
                await asyncio.sleep(0.001)
        assert len(session.outbox) > 0  # mid-burst
        sock = session._current_socket()
        assert sock is not None
        sock.shutdown(socket.SHUT_RDWR)
        seen = await wait_numbers(watcher, topic, count - 1, timeout=30)
        assert session.connect_count == 2
        assert session.connected
        assert len(session.outbox) == 0
    assert seen == sorted(set(seen))
    assert len(seen) >= count - 10  # at most what was on the wire is lost


def test_the_library_internals_the_writer_relies_on_exist() -> None:
    """socket_writer uses paho's _in_callback_mutex, _out_packet, _sock, _protocol, _transport,
    _msgtime_mutex and _last_msg_out and aiomqtt's _client and _disconnected,
    socket_reader paho's _sock_recv, _in_packet and _last_bytes_received and aiomqtt's
    on_socket_open, misc_ticker aiomqtt's
    _misc_loop, the echo check's SUBSCRIBE/UNSUBSCRIBE aiomqtt's _pending_subscribes and
    _pending_unsubscribes as resolved by its callbacks: this fails when an upgrade renames
    them."""
    raw = paho.Client(CallbackAPIVersion.VERSION2)
    assert raw._in_callback_mutex.acquire(blocking=False)
    raw._in_callback_mutex.release()

    # write_qos0: paho's queue, socket, protocol, transport and keep-alive clock
    assert len(raw._out_packet) == 0
    assert raw._sock is None
    assert raw._protocol == paho.MQTTv311
    assert raw._transport == "tcp"
    with raw._msgtime_mutex:
        assert isinstance(raw._last_msg_out, float)
    assert callable(paho.time_func)
    assert not paho.MQTTMessageInfo(0).is_published()

    # socket_reader: paho's per-instance _sock_recv(bufsize) and aiomqtt's on_socket_open hook;
    # for QoS 0 publications read without paho, its packet state between packets and the
    # keep-alive's clock of received bytes
    assert callable(raw._sock_recv)
    assert raw._in_packet["command"] == 0
    with raw._msgtime_mutex:
        assert isinstance(raw._last_bytes_received, float)

    async def wrapped() -> None:
        client = aiomqtt.Client("127.0.0.1")
        assert isinstance(client._client, paho.Client)
        assert isinstance(client._disconnected, asyncio.Future)
        assert client._client.on_socket_open is not None
        assert client._pending_publishes == {}
        assert callable(client._misc_loop)  # misc_ticker replaces it per instance
        # mqtt._subscribe_at_once / _unsubscribe_at_once: what aiomqtt's SUBACK and UNSUBACK
        # callbacks resolve, looked up by message id
        suback: asyncio.Future[tuple[int, ...] | list[ReasonCode]]
        suback = asyncio.get_running_loop().create_future()
        client._pending_subscribes[7] = suback
        granted = [ReasonCode(PacketTypes.SUBACK, "Granted QoS 0")]
        client._on_subscribe(client._client, None, 7, granted, None)
        assert suback.result() == granted
        assert client._pending_subscribes == {}
        unsuback = asyncio.Event()
        client._pending_unsubscribes[8] = unsuback
        client._on_unsubscribe(client._client, None, 8, [], None)
        assert unsuback.is_set()
        assert client._pending_unsubscribes == {}

    asyncio.run(wrapped())


async def test_a_packet_queued_inside_a_paho_callback_is_written_on_the_next_loop_turn(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Where paho says not to write (inside one of its callbacks, _in_callback_mutex held) the
    writer schedules the write for the next loop turn instead, and the message arrives."""
    topic = f"{unique_interface_name}/v2/acme/r1/order"
    async with (
        watching(broker, topic, qos=0) as watcher,
        running(MqttSession(settings(broker))) as session,
    ):
        live = session._live_client
        assert live is not None
        raw = live._client
        with raw._in_callback_mutex:
            info = raw.publish(topic, payload(7), 0)
            assert not info.is_published()  # not written while paho is "in a callback"
        seen = await wait_numbers(watcher, topic, 7, timeout=5)
        assert info.is_published()
    assert seen == [7]


async def test_qos0_writes_skip_paho_on_publish_while_nothing_awaits_it(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """QoS 0 packets written while no publication awaits a confirmation do not go through
    paho's on_publish (a ReasonCode and a Properties object each); a QoS 1 publication is
    still confirmed through it, and every message arrives."""
    prefix = f"{unique_interface_name}/v2/acme"
    async with (
        watching(broker, f"{prefix}/#", qos=1) as watcher,
        running(MqttSession(settings(broker))) as session,
    ):
        live = session._live_client
        assert live is not None
        raw = live._client
        hook = raw.on_publish
        assert hook is not None
        confirmed: list[int] = []

        def counting(*args: object) -> None:
            confirmed.append(int(args[2]))  # type: ignore[call-overload]
            hook(*args)  # type: ignore[arg-type]

        raw.on_publish = counting
        for number in range(100):
            session.publish(f"{prefix}/r1/visualization", Topic.VISUALIZATION, payload(number))
        await wait_numbers(watcher, f"{prefix}/r1/visualization", 99, timeout=10)
        assert confirmed == []
        session.publish(f"{prefix}/r2/connection", Topic.CONNECTION, payload(7))
        await wait_numbers(watcher, f"{prefix}/r2/connection", 7, timeout=10)
        async with asyncio.timeout(5):
            while not confirmed:
                await asyncio.sleep(0.01)
        assert len(confirmed) == 1  # the PUBACK of the QoS 1 connection message


async def test_a_visualization_goes_out_at_once_unless_something_waits_before_it(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A visualization skips the outbox, the drain loop and paho's publish while nothing waits
    there: it is on the wire when publish returns, not retained (R04, R109; its QoS 0 packet is
    checked byte for byte against paho's in tests/unit/test_qos0_packet.py).
    Behind messages still in the outbox it takes the outbox's way, so it never overtakes them;
    while offline it is dropped (digest §1.3)."""
    prefix = f"{unique_interface_name}/v2/acme/r1"
    session = MqttSession(settings(broker))
    session.publish(f"{prefix}/visualization", Topic.VISUALIZATION, payload(1))  # offline
    assert len(session.outbox) == 0
    assert session.outbox.dropped == 1
    async with watching(broker, f"{prefix}/#", qos=1) as watcher, running(session):
        assert session.writer is not None
        assert session._live_client is not None
        raw = session._live_client._client
        published: list[str] = []
        publish = raw.publish

        def noting(topic: str, *rest: Any) -> Any:
            published.append(topic)
            return publish(topic, *rest)

        raw.publish = noting  # type: ignore[method-assign, assignment]
        writes = session.writer.raw_writes
        session.publish(f"{prefix}/visualization", Topic.VISUALIZATION, payload(2))
        assert session.writer.raw_writes == writes + 1  # written inside publish(), not by paho
        assert published == []
        assert len(session.outbox) == 0
        for number in range(3, 6):  # an order burst queued first, then a visualization
            session.publish(f"{prefix}/order", Topic.ORDER, payload(number))
        session.publish(f"{prefix}/visualization", Topic.VISUALIZATION, payload(6))
        assert len(session.outbox) == 4
        seen = await wait_numbers(watcher, prefix, 6, timeout=10)
    assert seen == [2, 3, 4, 5, 6]
    async with watching(broker, f"{prefix}/visualization", qos=1) as late:
        await asyncio.sleep(0.3)
    assert late.messages == []  # nothing retained


async def test_visualizations_larger_than_the_socket_buffer_arrive_whole_and_in_order(
    broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Written without paho into a 4 KiB send buffer, a 32 KiB visualization is taken in part:
    its rest goes to paho's queue, the following ones wait behind it, and every one arrives
    intact and in order."""
    topic = f"{unique_interface_name}/v2/acme/r1/visualization"
    count, size = 200, 32 * 1024
    async with bursting(broker, topic, count, size, Topic.VISUALIZATION) as (watcher, session):
        seen = await wait_numbers(watcher, topic, count - 1, timeout=30)
        assert session.writer is not None
        assert session.writer.raw_partial_writes >= 1
        assert len(session.outbox) == 0
    assert seen == list(range(count))
    assert all(
        bytes(m.payload) == payload(n, size) for m, n in zip(watcher.messages, seen, strict=True)
    )
