"""The socket reader's QoS 0 PUBLISH parser (MQTT 3.1.1 §3.3) against the writer's packets."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from vda5050.socket_reader import qos0_publish_at
from vda5050.socket_writer import qos0_publish_packet

_TOPICS = st.text(
    alphabet=st.characters(exclude_categories=["Cs"], exclude_characters="+#\x00"),
    min_size=1,
    max_size=40,
)


def _packet(topic: str, payload: bytes, *, retain: bool = False) -> bytes:
    packet = qos0_publish_packet(topic, payload, retain=retain, mqtt5=False)
    assert packet is not None
    return packet


@given(topic=_TOPICS, payload=st.binary(max_size=300), retain=st.booleans())
def test_a_whole_packet_is_read_back_and_no_part_of_it_is(
    topic: str, payload: bytes, retain: bool
) -> None:
    """What the writer sends reads back as topic, payload and retain flag, ending where the
    packet ends; a packet cut anywhere is left for later (None), never misread."""
    before = b"\x30\x03\x00\x01a"  # a whole packet in front: the offset is honoured
    packet = _packet(topic, payload, retain=retain)
    buffer = before + packet + b"\xd0\x00"  # a PINGRESP behind it stays unread
    assert qos0_publish_at(buffer, len(before)) == (
        topic,
        payload,
        retain,
        len(before) + len(packet),
    )
    for cut in range(len(packet)):
        assert qos0_publish_at(before + packet[:cut], len(before)) is None


def test_remaining_lengths_of_two_and_three_bytes() -> None:
    """MQTT 3.1.1 §2.2.3: the remaining length takes more bytes past 127 and 16,383."""
    for size in (200, 20_000):
        packet = _packet("a/b", bytes(size))
        assert qos0_publish_at(packet, 0) == ("a/b", bytes(size), False, len(packet))


def test_what_paho_must_read_is_left_to_it() -> None:
    """QoS 1 and 2, DUP set, other packet types, an empty topic, a topic that is not UTF-8
    and a remaining length longer than four bytes are not taken."""
    packet = _packet("a/b", b"x")
    for first in (0x32, 0x34, 0x38, 0x20, 0x90):
        assert qos0_publish_at(bytes((first,)) + packet[1:], 0) is None
    assert qos0_publish_at(b"\x30\x03\x00\x00x", 0) is None
    assert qos0_publish_at(b"\x30\x05\x00\x02\xff\xfex", 0) is None
    assert qos0_publish_at(b"\x30\xff\xff\xff\xff\x01", 0) is None
    assert qos0_publish_at(b"\x30\x01\x00", 0) is None  # too short for the topic's length
