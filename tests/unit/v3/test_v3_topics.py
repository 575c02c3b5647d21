"""3.0 topics: the eight topic names, who publishes them, QoS/retain, and 2.x kept apart."""

from __future__ import annotations

import pytest

from vda5050.errors import TopicError
from vda5050.mqtt import OFFLINE_POLICY
from vda5050.topics import (
    DELIVERY,
    MASTER_TOPICS,
    V2_TOPICS,
    V3_TOPICS,
    VEHICLE_TOPICS,
    AgvId,
    Topic,
    build_topic,
    default_interface_name,
    parse_topic,
    subscription_filter,
    topics_of,
)

AGV = AgvId("KIT", "0001")


def test_the_text_example_topic_parses() -> None:
    """T01: ``vda5050/v3/KIT/0001/order`` (§4.2's example) is a v3 order topic."""
    address = parse_topic("vda5050/v3/KIT/0001/order")
    assert (address.interface_name, address.major_version, address.topic) == (
        "vda5050",
        3,
        Topic.ORDER,
    )
    assert address.agv == AGV


@pytest.mark.parametrize("topic", sorted(V3_TOPICS))
def test_every_v3_topic_round_trips(topic: Topic) -> None:
    """T01, T02: each of the eight 3.0 topics builds and parses back under v3."""
    text = build_topic("vda5050", 3, AGV, topic)
    assert parse_topic(text).topic is topic
    assert str(parse_topic(text)) == text


def test_topic_sets_per_major() -> None:
    """T02: 3.0 adds zoneSet and responses to the six 2.x topics."""
    assert {Topic.ZONE_SET, Topic.RESPONSES} == V3_TOPICS - V2_TOPICS
    assert topics_of(2) == V2_TOPICS
    assert topics_of(3) == V3_TOPICS
    assert len(V2_TOPICS) == 6


@pytest.mark.parametrize("name", ["zoneSet", "responses"])
def test_3_0_only_topics_are_refused_under_v2(name: str) -> None:
    """T02: zoneSet and responses do not exist in 2.x: parsing, building and subscribing fail."""
    with pytest.raises(TopicError, match=r"exists from VDA 5050 3\.0 on"):
        parse_topic(f"uagv/v2/KIT/0001/{name}")
    with pytest.raises(TopicError):
        build_topic("uagv", 2, AGV, Topic(name))
    with pytest.raises(TopicError):
        subscription_filter("uagv", 2, Topic(name))
    assert subscription_filter("vda5050", 3, Topic(name)) == f"vda5050/v3/+/+/{name}"


def test_fleet_control_publishes_zone_sets_and_responses() -> None:
    """T02: fleet control publishes order, instantActions, zoneSet, responses; the robot the
    rest (§4.3 Table 2)."""
    assert {Topic.ORDER, Topic.INSTANT_ACTIONS, Topic.ZONE_SET, Topic.RESPONSES} == MASTER_TOPICS
    assert {Topic.STATE, Topic.VISUALIZATION, Topic.CONNECTION, Topic.FACTSHEET} == VEHICLE_TOPICS


def test_delivery_of_the_new_topics() -> None:
    """T03, T04: zoneSet and responses go at QoS 0, not retained; connection stays QoS 1
    retained and factsheet retained."""
    for topic in (Topic.ZONE_SET, Topic.RESPONSES):
        assert (DELIVERY[topic].qos, DELIVERY[topic].retain) == (0, False)
    assert (DELIVERY[Topic.CONNECTION].qos, DELIVERY[Topic.CONNECTION].retain) == (1, True)
    assert DELIVERY[Topic.FACTSHEET].retain
    assert set(DELIVERY) == set(Topic)
    assert set(OFFLINE_POLICY) == set(Topic), "the MQTT outbox knows every topic"


def test_default_interface_name_per_major() -> None:
    """T01: uagv for 2.x, vda5050 for 3.x."""
    assert default_interface_name(2) == "uagv"
    assert default_interface_name(3) == "vda5050"
    assert default_interface_name(4) == "vda5050"
