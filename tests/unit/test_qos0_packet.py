"""The QoS 0 PUBLISH packet socket_writer writes without paho: byte for byte what paho-mqtt
itself would send, in MQTT 3.1.1 and 5, across the remaining length's one- to four-byte forms."""

from __future__ import annotations

import pytest
from paho.mqtt import client as paho
from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion

from vda5050.socket_writer import qos0_publish_packet


def _paho_packet(
    topic: str, payload: bytes, *, retain: bool, protocol: MQTTProtocolVersion
) -> bytes:
    """What paho queues for ``publish(topic, payload, qos=0, retain)``."""
    client = paho.Client(CallbackAPIVersion.VERSION2, protocol=protocol)
    queued: list[bytes] = []

    def capture(command: int, packet: bytes, mid: int, qos: int, info: object = None) -> int:
        del command, mid, qos, info
        queued.append(bytes(packet))
        return 0

    client._packet_queue = capture  # type: ignore[method-assign, assignment]
    client._sock = object()  # type: ignore[assignment] # _send_publish only checks it is set
    try:
        client._send_publish(1, topic.encode(), payload, 0, retain)
    finally:
        client._sock = None
    (packet,) = queued
    return packet


@pytest.mark.parametrize("size", [0, 1, 100, 114, 115, 127, 128, 16_370, 16_384, 2_100_000])
@pytest.mark.parametrize("retain", [False, True])
@pytest.mark.parametrize("protocol", [paho.MQTTv311, paho.MQTTv5], ids=["3.1.1", "5"])
def test_the_packet_is_the_one_paho_would_send(
    size: int, retain: bool, protocol: MQTTProtocolVersion
) -> None:
    topic = "uagv/v2/acme/robot_0/visualization"
    payload = bytes(range(256)) * (size // 256) + bytes(size % 256)
    ours = qos0_publish_packet(topic, payload, retain=retain, mqtt5=protocol == paho.MQTTv5)
    assert ours == _paho_packet(topic, payload, retain=retain, protocol=protocol)


def test_a_multibyte_topic_is_counted_in_bytes() -> None:
    topic = "uagv/v2/Fahrzeugbau-Müller/ä€/visualization"
    ours = qos0_publish_packet(topic, b"{}", retain=False, mqtt5=False)
    assert ours == _paho_packet(topic, b"{}", retain=False, protocol=paho.MQTTv311)


@pytest.mark.parametrize("topic", ["", "a/+/b", "a/#", "x" * 65_536])
def test_topics_paho_refuses_are_left_to_paho(topic: str) -> None:
    assert qos0_publish_packet(topic, b"{}", retain=False, mqtt5=False) is None
