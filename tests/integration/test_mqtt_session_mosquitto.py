"""MqttSession against a real Mosquitto: will, retained state, reconnect after restart, auth."""

from __future__ import annotations

import asyncio
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import aiomqtt
import pytest
from paho.mqtt import client as paho_client
from paho.mqtt import publish as paho_publish

from tests.integration.mqtt_helpers import client_for, watching
from tests.integration.test_mqtt_session import running, settings, start_will_client
from tests.mosquitto import run_mosquitto
from vda5050.broker import BrokerAddress
from vda5050.mqtt import InboundMessage, MqttSession
from vda5050.socket_writer import SocketWriter
from vda5050.topics import Topic

pytestmark = pytest.mark.mosquitto


async def test_will_and_retained_connection_on_mosquitto(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """R06/R11 on Mosquitto: a killed client's retained will reaches a late subscriber."""
    topic = f"{unique_interface_name}/v2/acme/r1/connection"
    with run_mosquitto(tmp_path) as broker:
        process = await asyncio.to_thread(start_will_client, broker.address, topic)
        process.kill()
        await asyncio.to_thread(process.wait, 5)
        async with watching(broker.address, topic) as watcher:
            (will,) = await watcher.wait_for(topic)
            assert will.payload == b"CONNECTIONBROKEN"
            assert will.retain


async def test_qos_and_retain_per_topic_on_mosquitto(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """R04-R07 on Mosquitto (which delivers at min(publish, subscribe) QoS): state QoS 0, not
    retained; connection QoS 1 retained; factsheet QoS 0 retained."""
    prefix = f"{unique_interface_name}/v2/acme/r1"
    with run_mosquitto(tmp_path) as broker:
        async with running(MqttSession(settings(broker.address))) as session:
            for kind in (Topic.STATE, Topic.CONNECTION, Topic.FACTSHEET):
                session.publish(f"{prefix}/{kind.value}", kind, kind.value.encode())
            await asyncio.sleep(0.3)
            async with watching(broker.address, f"{prefix}/#", qos=1) as live:
                session.publish(f"{prefix}/state", Topic.STATE, b"live")
                (state,) = await live.wait_for(f"{prefix}/state")
                (connection,) = await live.wait_for(f"{prefix}/connection")
                (factsheet,) = await live.wait_for(f"{prefix}/factsheet")
        assert (state.qos, state.retain) == (0, False)
        assert (connection.qos, connection.retain) == (1, True)
        assert (factsheet.qos, factsheet.retain) == (0, True)


async def test_reconnects_after_mosquitto_restarts(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """After Mosquitto restarts the session reconnects and its subscription works again."""
    topic = f"{unique_interface_name}/v2/acme/r1/order"
    got = asyncio.Event()

    async def on_order(message: InboundMessage) -> None:
        if message.payload == b"after":
            got.set()

    with run_mosquitto(tmp_path) as broker:
        session = MqttSession(settings(broker.address))
        session.subscribe(topic, on_order)
        async with running(session):
            await asyncio.to_thread(broker.stop)
            await asyncio.sleep(0.2)
            await asyncio.to_thread(broker.start)
            async with asyncio.timeout(10):
                while session.connect_count < 2 or not session.connected:
                    await asyncio.sleep(0.05)
            async with client_for(broker.address) as publisher:
                await publisher.publish(topic, b"after", qos=1)
            async with asyncio.timeout(5):
                await got.wait()


async def test_password_authentication_on_mosquitto(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """Right credentials connect and publish; wrong ones are retried without crashing."""
    topic = f"{unique_interface_name}/v2/acme/r1/state"
    with run_mosquitto(tmp_path, credentials=("robot", "s3cret")) as broker:
        host, port = broker.address.host, broker.address.port
        good = MqttSession(settings(broker.address, url=f"mqtt://robot:s3cret@{host}:{port}"))
        bad = MqttSession(settings(broker.address, url=f"mqtt://robot:nope@{host}:{port}"))
        async with running(good), running(bad, connected=False):
            async with client_for(broker.address, username="robot", password="s3cret") as sub:
                await sub.subscribe(topic)
                good.publish(topic, Topic.STATE, b"hello")
                async with asyncio.timeout(5):
                    message = await anext(aiter(sub.messages))
                assert message.payload == b"hello"
            await asyncio.sleep(0.5)
            assert not bad.connected


async def test_inbound_backlog_is_what_the_session_has_not_read(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """inbound_backlog_bytes: 0 while not connected; while the session is busy, what the broker
    delivered meanwhile waits unread (master control holds resends then); 0 once caught up."""
    topic = f"{unique_interface_name}/v2/acme/r1/state"
    backlog: list[int] = []
    with run_mosquitto(tmp_path) as broker:
        session = MqttSession(settings(broker.address))

        async def busy(message: InboundMessage) -> None:
            if message.payload != b"first":
                return
            flood = [(topic, b"x" * 1000, 0, False)] * 200
            sender = threading.Thread(
                target=paho_publish.multiple,
                args=(flood,),
                kwargs={"hostname": broker.address.host, "port": broker.address.port},
            )
            sender.start()
            sender.join(5)
            time.sleep(0.5)  # noqa: ASYNC251 - the point: a session too busy to read
            backlog.append(session.inbound_backlog_bytes())

        session.subscribe(topic, busy)
        assert session.inbound_backlog_bytes() == 0
        assert await _backlog_then_caught_up(session, broker.address, topic, backlog) > 100_000


async def test_inbound_backlog_counts_messages_read_but_not_handled(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """inbound_backlog_bytes also counts what was read from the socket but waits for the
    handlers (a handler that awaits lets the socket be drained into the client's queue: the
    kernel's count alone would say 0 while 200 messages wait); 0 once they are handled."""
    topic = f"{unique_interface_name}/v2/acme/r1/state"
    backlog: list[int] = []
    with run_mosquitto(tmp_path) as broker:
        session = MqttSession(settings(broker.address))

        async def slow(message: InboundMessage) -> None:
            if message.payload != b"first":
                return
            flood: paho_publish.MessagesList = [(topic, b"x" * 1000, 0, False)] * 200
            await asyncio.to_thread(
                paho_publish.multiple,
                flood,
                hostname=broker.address.host,
                port=broker.address.port,
            )
            await asyncio.sleep(0.5)  # the loop reads the socket meanwhile
            backlog.append(session.inbound_backlog_bytes())

        session.subscribe(topic, slow)
        assert await _backlog_then_caught_up(session, broker.address, topic, backlog) >= 150_000


async def _backlog_then_caught_up(
    session: MqttSession, address: BrokerAddress, topic: str, backlog: list[int]
) -> int:
    """Runs the session, publishes "first" (its handler floods the topic and notes the backlog
    in ``backlog``), waits for that note and then until the session has read everything (0);
    returns the noted backlog."""
    async with running(session):
        async with client_for(address) as client:
            await client.publish(topic, b"first")
        async with asyncio.timeout(10):
            while not backlog:
                await asyncio.sleep(0.05)
        async with asyncio.timeout(10):
            while session.inbound_backlog_bytes() > 0:
                await asyncio.sleep(0.05)
    return backlog[0]


async def test_echo_checks_of_plain_topics_subscribe_with_the_connect(
    tmp_path: Path, unique_interface_name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A vehicle's echo-checked topics (its own connection and state) are subscribed in the
    connect's one SUBSCRIBE, not one more each before the first publication; the check still
    confirms the publications (no publish_denied) and unsubscribes them afterwards."""
    prefix = f"{unique_interface_name}/v2/acme/r1"
    calls: list[object] = []
    unsubscribed: list[str] = []
    # Counted where every SUBSCRIBE and UNSUBSCRIBE passes: paho's client (aiomqtt's calls and
    # the echo check's direct ones alike).
    subscribe, unsubscribe = paho_client.Client.subscribe, paho_client.Client.unsubscribe

    def counting(client: paho_client.Client, topic: Any, *args: Any, **kwargs: Any) -> Any:
        calls.append(topic)
        return subscribe(client, topic, *args, **kwargs)

    def noting(client: paho_client.Client, topic: Any, *args: Any, **kwargs: Any) -> Any:
        unsubscribed.extend(topic if isinstance(topic, list) else [topic])  # one packet, or more
        return unsubscribe(client, topic, *args, **kwargs)

    monkeypatch.setattr(paho_client.Client, "subscribe", counting)
    monkeypatch.setattr(paho_client.Client, "unsubscribe", noting)

    async def ignore(_message: InboundMessage) -> None:
        return None

    with run_mosquitto(tmp_path) as broker:
        session = MqttSession(replace(settings(broker.address), publish_check_s=1.0))
        session.subscribe(f"{prefix}/order", ignore)
        session.verify_echo(f"{prefix}/connection")
        session.verify_echo(f"{prefix}/state")
        async with running(session):
            session.publish(f"{prefix}/connection", Topic.CONNECTION, b"ONLINE")
            session.publish(f"{prefix}/state", Topic.STATE, b"state")
            async with asyncio.timeout(5):
                while len(unsubscribed) < 2:
                    await asyncio.sleep(0.05)
            await asyncio.sleep(1.2)  # past publish_check_s: nothing is reported denied
            assert session.access_problems == ()
    assert calls == [[(f"{prefix}/order", 0), (f"{prefix}/connection", 0), (f"{prefix}/state", 0)]]
    assert sorted(unsubscribed) == [f"{prefix}/connection", f"{prefix}/state"]


async def test_messages_behind_a_qos1_one_do_not_wait_for_its_puback(
    tmp_path: Path, unique_interface_name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The state queued behind an ONLINE (QoS 1) is written before the ONLINE's PUBACK is back
    (the broker keeps one connection's order: a subscriber still gets ONLINE first)."""
    prefix = f"{unique_interface_name}/v2/acme/r1"
    events: list[str] = []
    publish = aiomqtt.Client.publish

    async def noting(client: aiomqtt.Client, topic: str, *args: Any, **kwargs: Any) -> None:
        kind = topic.rsplit("/", 1)[-1]
        events.append(f"{kind} written")
        await publish(client, topic, *args, **kwargs)
        events.append(f"{kind} acknowledged")

    write_qos0 = SocketWriter.write_qos0

    def noting_raw(writer: SocketWriter, topic: str, *args: Any, **kwargs: Any) -> bool:
        written = write_qos0(writer, topic, *args, **kwargs)
        if written:  # a QoS 0 packet written without paho (and without aiomqtt's publish)
            events.append(f"{topic.rsplit('/', 1)[-1]} written")
        return written

    monkeypatch.setattr(aiomqtt.Client, "publish", noting)
    monkeypatch.setattr(SocketWriter, "write_qos0", noting_raw)
    with run_mosquitto(tmp_path) as broker:
        async with watching(broker.address, f"{prefix}/#", qos=1) as watcher:
            async with running(MqttSession(settings(broker.address))) as session:
                session.publish(f"{prefix}/connection", Topic.CONNECTION, b"ONLINE")
                session.publish(f"{prefix}/state", Topic.STATE, b"state")
                await watcher.wait_for(f"{prefix}/state")
                async with asyncio.timeout(5):
                    while "connection acknowledged" not in events:
                        await asyncio.sleep(0.01)
            arrived = [str(m.topic).rsplit("/", 1)[-1] for m in watcher.messages]
    assert events.index("state written") < events.index("connection acknowledged")
    assert arrived[:2] == ["connection", "state"]
