"""MQTT topics of VDA 5050: structure, QoS and retain flags (§6.2, §6.3, §6.5; digest §1.2, §1.3;
3.0 §4.1–§4.3).

Topic layout: ``<interfaceName>/v<major>/<manufacturer>/<serialNumber>/<topic>``. One
:class:`Topic` enum serves both generations: ``zoneSet`` and ``responses`` exist from 3.0 on
only, so building or parsing them under ``v2`` raises :class:`TopicError` (see
:func:`topics_of`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import StrEnum

from vda5050.errors import TopicError


class Topic(StrEnum):
    """The fixed final topic level of every VDA 5050 message (2.x: the first six; 3.0: all)."""

    ORDER = "order"
    INSTANT_ACTIONS = "instantActions"
    STATE = "state"
    VISUALIZATION = "visualization"
    CONNECTION = "connection"
    FACTSHEET = "factsheet"
    #: 3.0 only: fleet control → robot, the zones of one map (3.0 §4.3, §7.6).
    ZONE_SET = "zoneSet"
    #: 3.0 only: fleet control → robot, answers to the robot's requests (3.0 §4.3, §6.9).
    RESPONSES = "responses"

    @property
    def since_major(self) -> int:
        """The first major version that has this topic."""
        return 3 if self in _V3_ONLY else 0


_V3_ONLY = frozenset({Topic.ZONE_SET, Topic.RESPONSES})
#: The topics of VDA 5050 2.x (2.0 and 2.1).
V2_TOPICS: frozenset[Topic] = frozenset(Topic) - _V3_ONLY
#: The topics of VDA 5050 3.0.
V3_TOPICS: frozenset[Topic] = frozenset(Topic)


def topics_of(major_version: int) -> frozenset[Topic]:
    """The topics a major version defines: 3.x has zoneSet and responses, earlier ones do not."""
    return V3_TOPICS if major_version >= 3 else V2_TOPICS  # noqa: PLR2004 - the 3.0 major


def default_interface_name(major_version: int) -> str:
    """The interfaceName (first topic level) to use by default for ``major_version``: the
    texts' examples, ``uagv`` for 2.x and ``vda5050`` from 3.0 on (3.0 §4.2, T01)."""
    return "vda5050" if major_version >= 3 else "uagv"  # noqa: PLR2004 - the 3.0 major


@dataclass(frozen=True, slots=True)
class Delivery:
    """How a topic is published: MQTT QoS and retain flag."""

    qos: int
    retain: bool


#: §6.2/§6.14/§6.15: connection QoS 1 retained, factsheet QoS 0 retained, the rest QoS 0.
#: Retain is unspecified for order, instantActions and state; a retained order would be replayed
#: to a reconnecting vehicle, so they are not retained (digest §1.3 note, §11 item 11).
#: 3.0 (§4.1, §6.5, §6.10) keeps all of this and adds zoneSet and responses at QoS 0; their retain
#: flag is unspecified too, and a replayed zone set would only earn a DUPLICATE_ZONE_SET error
#: and a replayed response a stale grant, so neither is retained.
DELIVERY: dict[Topic, Delivery] = {
    Topic.ORDER: Delivery(qos=0, retain=False),
    Topic.INSTANT_ACTIONS: Delivery(qos=0, retain=False),
    Topic.STATE: Delivery(qos=0, retain=False),
    Topic.VISUALIZATION: Delivery(qos=0, retain=False),
    Topic.CONNECTION: Delivery(qos=1, retain=True),
    Topic.FACTSHEET: Delivery(qos=0, retain=True),
    Topic.ZONE_SET: Delivery(qos=0, retain=False),
    Topic.RESPONSES: Delivery(qos=0, retain=False),
}

#: Topics master (fleet) control publishes; the vehicle publishes the others (3.0 §4.3 Table 2).
MASTER_TOPICS = frozenset({Topic.ORDER, Topic.INSTANT_ACTIONS, Topic.ZONE_SET, Topic.RESPONSES})
VEHICLE_TOPICS = frozenset(Topic) - MASTER_TOPICS

_SERIAL_NUMBER = re.compile(r"[A-Za-z0-9_.:\-]+")
_MAJOR = re.compile(r"v(\d+)")
_TOPIC_BY_NAME = {topic.value: topic for topic in Topic}


@dataclass(frozen=True, slots=True)
class AgvId:
    """Identifies one vehicle: manufacturer and serial number."""

    manufacturer: str
    serial_number: str

    def __str__(self) -> str:
        return f"{self.manufacturer}/{self.serial_number}"


@dataclass(frozen=True, slots=True)
class TopicAddress:
    """A parsed VDA 5050 topic."""

    interface_name: str
    major_version: int
    agv: AgvId
    topic: Topic

    def __str__(self) -> str:
        return build_topic(self.interface_name, self.major_version, self.agv, self.topic)


def check_level(value: str, what: str) -> None:
    """Raise TopicError if ``value`` cannot be one topic level (R02).

    A level must be non-empty and must not contain ``/`` (level separator), the MQTT wildcards
    ``+`` and ``#``, ``$`` (reserved by brokers), NUL, or surrounding whitespace.
    """
    if not value:
        msg = f"{what} must not be empty"
        raise TopicError(msg)
    for char, why in (
        ("/", "a level separator"),
        ("+", "an MQTT wildcard"),
        ("#", "an MQTT wildcard"),
        ("$", "reserved by brokers"),
        ("\x00", "not allowed in MQTT topics"),
    ):
        if char in value:
            msg = f"{what} {value!r} contains {char!r}, which is {why}"
            raise TopicError(msg)
    if value != value.strip():
        msg = f"{what} {value!r} has leading or trailing whitespace"
        raise TopicError(msg)


def check_serial_number(serial_number: str) -> None:
    """Raise TopicError unless ``serial_number`` uses only ``A-Z a-z 0-9 _ . : -`` (§6.3, R02)."""
    if not _SERIAL_NUMBER.fullmatch(serial_number):
        msg = f"serialNumber {serial_number!r} may only contain A-Z a-z 0-9 _ . : -"
        raise TopicError(msg)


def check_topic_exists(topic: Topic, major_version: int) -> None:
    """Raise TopicError if ``topic`` does not exist in ``major_version`` (zoneSet under v2)."""
    if major_version < topic.since_major:
        msg = (
            f"topic {topic.value!r} exists from VDA 5050 {topic.since_major}.0 on, "
            f"not in v{major_version}"
        )
        raise TopicError(msg)


def topic_prefix(interface_name: str, major_version: int, agv: AgvId) -> str:
    """Return ``<interfaceName>/v<major>/<manufacturer>/<serialNumber>``, checking each level."""
    check_level(interface_name, "interfaceName")
    check_level(agv.manufacturer, "manufacturer")
    check_level(agv.serial_number, "serialNumber")
    check_serial_number(agv.serial_number)
    if major_version < 0:
        msg = f"major version must not be negative, got {major_version}"
        raise TopicError(msg)
    return f"{interface_name}/v{major_version}/{agv.manufacturer}/{agv.serial_number}"


def build_topic(interface_name: str, major_version: int, agv: AgvId, topic: Topic) -> str:
    """Build the topic of ``topic`` for vehicle ``agv`` (R01, R02; T02: no 3.0-only topic under
    an older major)."""
    check_topic_exists(topic, major_version)
    return f"{topic_prefix(interface_name, major_version, agv)}/{topic.value}"


def subscription_filter(
    interface_name: str, major_version: int, topic: Topic, agv: AgvId | None = None
) -> str:
    """Return a subscription filter for ``topic`` of one vehicle, or of every vehicle (``+/+``)."""
    if agv is not None:
        return build_topic(interface_name, major_version, agv, topic)
    check_level(interface_name, "interfaceName")
    check_topic_exists(topic, major_version)
    return f"{interface_name}/v{major_version}/+/+/{topic.value}"


def parse_topic(topic: str) -> TopicAddress:
    """Parse a VDA 5050 topic string, raising TopicError when it is not one (R01, R02)."""
    levels = topic.split("/")
    if len(levels) != 5:  # noqa: PLR2004 - interfaceName/vN/manufacturer/serial/topic
        msg = f"topic {topic!r} has {len(levels)} levels, expected 5"
        raise TopicError(msg)
    interface_name, major, manufacturer, serial_number, name = levels
    match = _MAJOR.fullmatch(major)
    if match is None:
        msg = f"topic {topic!r}: version level {major!r} is not 'v<major>'"
        raise TopicError(msg)
    kind = _TOPIC_BY_NAME.get(name)
    if kind is None:
        msg = f"topic {topic!r}: {name!r} is not a VDA 5050 topic"
        raise TopicError(msg)
    agv = AgvId(manufacturer, serial_number)
    major_version = int(match.group(1))
    topic_prefix(interface_name, major_version, agv)  # validates every level
    check_topic_exists(kind, major_version)
    return TopicAddress(interface_name, major_version, agv, kind)
