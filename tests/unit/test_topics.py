"""Topic building and parsing (digest R01, R02) and the QoS/retain table (§1.3)."""

from __future__ import annotations

import pytest

from vda5050.errors import TopicError
from vda5050.topics import (
    DELIVERY,
    V2_TOPICS,
    AgvId,
    Topic,
    build_topic,
    parse_topic,
    subscription_filter,
)

AGV = AgvId("acme", "robot_0")


def test_build_topic_follows_the_standard_layout() -> None:
    """R01: topics are interfaceName/v<major>/manufacturer/serialNumber/topic."""
    assert build_topic("uagv", 2, AGV, Topic.ORDER) == "uagv/v2/acme/robot_0/order"
    assert build_topic("uagv", 2, AGV, Topic.INSTANT_ACTIONS).endswith("/instantActions")


@pytest.mark.parametrize("topic", sorted(V2_TOPICS))
def test_parse_topic_inverts_build_topic(topic: Topic) -> None:
    """R01: every built topic parses back to the same parts."""
    address = parse_topic(build_topic("uagv", 2, AgvId("ACME", "AGV-01.a:b"), topic))
    assert (address.interface_name, address.major_version, address.topic) == ("uagv", 2, topic)
    assert address.agv == AgvId("ACME", "AGV-01.a:b")
    assert str(address) == build_topic("uagv", 2, AgvId("ACME", "AGV-01.a:b"), topic)


@pytest.mark.parametrize(
    ("topic", "fragment"),
    [
        ("uagv/v2/acme/robot_0/orders", "not a VDA 5050 topic"),
        ("uagv/v2/acme/robot_0", "has 4 levels"),
        ("uagv/v2/acme/robot/0/order", "has 6 levels"),
        ("uagv/2/acme/robot_0/order", "is not 'v<major>'"),
        ("uagv/v2/acme/robot 0/order", "may only contain"),
        ("uagv/v2/acme/robot#/order", "MQTT wildcard"),
        ("uagv/v2/ac+me/robot_0/order", "MQTT wildcard"),
        ("$SYS/v2/acme/robot_0/order", "reserved by brokers"),
        ("uagv/v2//robot_0/order", "must not be empty"),
        ("uagv/v2/acme/robot_0/Order", "not a VDA 5050 topic"),
    ],
)
def test_parse_topic_rejects_illegal_topics(topic: str, fragment: str) -> None:
    """R01/R02: wrong level count, unknown topic names and illegal characters are rejected."""
    with pytest.raises(TopicError, match=fragment):
        parse_topic(topic)


@pytest.mark.parametrize("serial", ["a/b", "a b", "a$b", "ü", ""])
def test_build_topic_rejects_illegal_serial_numbers(serial: str) -> None:
    """R02: serialNumber uses only A-Z a-z 0-9 _ . : - and contains no '/'."""
    with pytest.raises(TopicError):
        build_topic("uagv", 2, AgvId("acme", serial), Topic.STATE)


def test_build_topic_rejects_slash_in_manufacturer() -> None:
    """R02: no level contains '/'."""
    with pytest.raises(TopicError, match="level separator"):
        build_topic("uagv", 2, AgvId("ac/me", "r1"), Topic.STATE)


def test_subscription_filter_for_every_vehicle_uses_wildcards() -> None:
    """Master control subscribes to one topic of every vehicle with +/+ for the two id levels."""
    assert subscription_filter("uagv", 2, Topic.STATE) == "uagv/v2/+/+/state"
    assert subscription_filter("uagv", 2, Topic.STATE, AGV) == "uagv/v2/acme/robot_0/state"


def test_delivery_table_matches_the_standard() -> None:
    """R03-R07: connection QoS 1 retained, factsheet QoS 0 retained, everything else QoS 0."""
    assert (DELIVERY[Topic.CONNECTION].qos, DELIVERY[Topic.CONNECTION].retain) == (1, True)
    assert (DELIVERY[Topic.FACTSHEET].qos, DELIVERY[Topic.FACTSHEET].retain) == (0, True)
    for topic in (Topic.ORDER, Topic.INSTANT_ACTIONS, Topic.STATE, Topic.VISUALIZATION):
        assert (DELIVERY[topic].qos, DELIVERY[topic].retain) == (0, False)
