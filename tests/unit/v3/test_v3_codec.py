"""The codec across generations: the topic's major picks the models, the payload's version must
agree, and the stamper writes 3.0 headers."""

from __future__ import annotations

import json
from datetime import UTC, datetime

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vda5050.clock import FakeClock
from vda5050.codec import (
    MODEL_BY_TOPIC,
    SUPPORTED_VERSIONS,
    DecodeFailure,
    HeaderStamper,
    decode,
    decode_as,
    encode,
    major_of,
    model_for,
)
from vda5050.models import Connection, State, v3
from vda5050.testing import (
    make_connection_v3,
    make_order_v3,
    make_state,
    make_state_v3,
    make_zone_set_v3,
)
from vda5050.topics import AgvId, Topic, TopicAddress

AGV = AgvId("acme", "robot_0")


def address(topic: Topic, major: int = 3) -> TopicAddress:
    return TopicAddress("vda5050" if major == 3 else "uagv", major, AGV, topic)


def failure(result: object) -> DecodeFailure:
    assert isinstance(result, DecodeFailure), f"expected a failure, got {result!r}"
    assert result.problems
    return result


def test_3_0_0_is_a_supported_version() -> None:
    """T12: the stack speaks 2.0.0, 2.1.0 and 3.0.0."""
    assert SUPPORTED_VERSIONS == ("2.0.0", "2.1.0", "3.0.0")
    assert major_of("3.0.0") == 3
    with pytest.raises(ValueError, match="major"):
        major_of("x.0.0")


def test_the_topic_major_picks_the_model() -> None:
    """T12: the same topic decodes into the 2.x model under v2 and the 3.0 model under v3."""
    v3_state = decode(Topic.STATE, encode(make_state_v3()), address=address(Topic.STATE))
    v2_raw = encode(make_state(manufacturer="acme", serial_number="robot_0"))
    v2_state = decode(Topic.STATE, v2_raw, address=address(Topic.STATE, 2))
    assert isinstance(v3_state, v3.State)
    assert isinstance(v2_state, State)


def test_decode_without_address_defaults_to_2x_or_takes_a_major() -> None:
    """Without a topic, decode keeps its 2.x behaviour; ``major=3`` selects the 3.0 models."""
    raw = encode(make_connection_v3())
    assert isinstance(decode(Topic.CONNECTION, raw, major=3), v3.Connection)
    result = failure(decode(Topic.CONNECTION, raw))
    assert "$.version" in [p.path for p in result.problems]


@pytest.mark.parametrize(
    ("payload_version", "topic_major", "fragment"),
    [
        ("2.1.0", 3, "does not match the topic's v3"),
        ("3.0.0", 2, "does not match the topic's v2"),
        ("4.0.0", 3, "is not a 3.x version"),
    ],
)
def test_payload_major_must_equal_the_topic_major(
    payload_version: str, topic_major: int, fragment: str
) -> None:
    """T12: a 2.x payload on a v3 topic and a 3.x payload on a v2 topic are refused."""
    raw = json.loads(encode(make_connection_v3()))
    raw["version"] = payload_version
    if topic_major == 2:
        raw["connectionState"] = "ONLINE"
    result = failure(
        decode(
            Topic.CONNECTION,
            json.dumps(raw).encode(),
            address=address(Topic.CONNECTION, topic_major),
        )
    )
    assert result.problems[0].path == "$.version"
    assert fragment in result.problems[0].reason


def test_minor_and_patch_differences_are_accepted() -> None:
    """T12: a 3.1.0 message is read with the 3.0 models (same major)."""
    raw = encode(make_connection_v3(version="3.1.0"))
    assert isinstance(
        decode(Topic.CONNECTION, raw, address=address(Topic.CONNECTION)), v3.Connection
    )


def test_decode_as_checks_the_model_generation() -> None:
    """T12: decode_as with a 2.x model refuses a v3 topic, and a 3.0 model a 3.0 payload on v2."""
    raw = encode(make_connection_v3())
    result = failure(
        decode_as(Connection, Topic.CONNECTION, raw, address=address(Topic.CONNECTION))
    )
    assert result.problems[0].path == "$.version"
    typed = decode_as(v3.Connection, Topic.CONNECTION, raw, address=address(Topic.CONNECTION))
    assert isinstance(typed, v3.Connection)
    assert typed.connection_state is v3.ConnectionState.ONLINE


def test_header_must_match_the_v3_topic() -> None:
    """T13: manufacturer and serialNumber of a 3.0 payload equal the topic levels."""
    raw = encode(make_connection_v3(serial_number="other"))
    result = failure(decode(Topic.CONNECTION, raw, address=address(Topic.CONNECTION)))
    assert [p.path for p in result.problems] == ["$.serialNumber"]


@pytest.mark.parametrize("topic", [Topic.ZONE_SET, Topic.RESPONSES])
def test_3_0_only_topics_do_not_decode_as_2x(topic: Topic) -> None:
    """T02: zoneSet and responses have no 2.x model; decoding them as 2.x fails, never raises."""
    result = failure(decode(topic, b"{}", address=address(topic, 2)))
    assert "does not exist in VDA 5050 v2" in result.problems[0].reason
    assert "does not exist" in failure(decode(topic, b"{}")).problems[0].reason
    with pytest.raises(ValueError, match="does not exist"):
        model_for(topic, 2)


def test_unspoken_major_fails_cleanly() -> None:
    """T12: a v4 topic gets a failure naming the supported majors."""
    result = failure(decode(Topic.STATE, b"{}", address=address(Topic.STATE, 4)))
    assert "v4 is not spoken" in result.problems[0].reason
    with pytest.raises(ValueError, match="not spoken"):
        model_for(Topic.STATE, 1)


def test_model_for_covers_every_topic_of_each_generation() -> None:
    """T02: 2.x has six models (unchanged), 3.0 eight."""
    assert {t: model_for(t, 2) for t in MODEL_BY_TOPIC} == dict(MODEL_BY_TOPIC)
    assert model_for(Topic.ZONE_SET, 3) is v3.ZoneSetMessage
    assert model_for(Topic.RESPONSES, 3) is v3.Responses
    assert model_for(Topic.FACTSHEET, 3) is v3.Factsheet


def test_failed_3_0_order_keeps_its_references() -> None:
    """T20: a malformed 3.0 order still yields headerId, orderId and orderUpdateId."""
    raw = json.loads(encode(make_order_v3(["a"], order_id="o-9", order_update_id=3)))
    raw["nodes"][0]["released"] = "yes"
    result = failure(decode(Topic.ORDER, json.dumps(raw).encode(), address=address(Topic.ORDER)))
    assert ("orderId", "o-9") in result.references
    assert ("orderUpdateId", "3") in result.references
    assert result.problems[0].path == "$.nodes[0].released"


def test_stamper_writes_3_0_headers_and_remembers_the_last_state() -> None:
    """T10, T11, T79: a 3.0.0 stamper counts per topic, stamps version 3.0.0, and tells the
    headerId of the last state for referenceStateHeaderId."""
    stamper = HeaderStamper(AGV, "3.0.0", FakeClock(datetime(2026, 3, 18, 10, 0, tzinfo=UTC)))
    assert stamper.major == 3
    assert stamper.last_header_id(Topic.STATE) is None
    first = stamper.stamp(Topic.STATE, make_state_v3())
    second = stamper.stamp(Topic.STATE, make_state_v3())
    zones = stamper.stamp(Topic.ZONE_SET, make_zone_set_v3())
    assert (first.header_id, second.header_id, zones.header_id) == (0, 1, 0)
    assert (second.version, second.manufacturer, second.timestamp) == (
        "3.0.0",
        "acme",
        "2026-03-18T10:00:00.000Z",
    )
    assert isinstance(second, v3.State)
    assert stamper.last_header_id(Topic.STATE) == 1


def test_stamper_refuses_messages_of_the_other_generation() -> None:
    """T12: a 2.x message cannot be stamped 3.0.0, nor a 3.0 message 2.1.0."""
    with pytest.raises(ValueError, match=r"cannot stamp a 2\.x State"):
        HeaderStamper(AGV, "3.0.0", FakeClock()).stamp(Topic.STATE, make_state())
    stamper = HeaderStamper(AGV, "2.1.0", FakeClock())
    with pytest.raises(ValueError, match=r"cannot stamp a 3\.x State"):
        stamper.stamp(Topic.STATE, make_state_v3())
    stamper.version = "3.0.0"  # a vehicle that changed its version
    assert stamper.stamp(Topic.STATE, make_state_v3()).version == "3.0.0"
    with pytest.raises(ValueError, match="version must be one of"):
        stamper.version = "3.1.0"


V3_TOPICS = sorted(Topic, key=list(Topic).index)


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(V3_TOPICS), st.binary(max_size=300))
def test_random_bytes_on_v3_topics_never_raise(topic: Topic, raw: bytes) -> None:
    """T14: arbitrary bytes on any v3 topic decode to a model or to a failure with reasons."""
    result = decode(topic, raw, address=address(topic))
    if isinstance(result, DecodeFailure):
        assert all(p.reason and p.path.startswith("$") for p in result.problems)


@settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_truncated_v3_messages_fail_with_reasons(data: st.DataObject) -> None:
    """T14: any strict prefix of a valid 3.0 order is a failure naming why."""
    raw = encode(make_order_v3(["a", "b", "c"], released=2))
    cut = data.draw(st.integers(min_value=0, max_value=len(raw) - 1))
    failure(decode(Topic.ORDER, raw[:cut], address=address(Topic.ORDER)))


def test_nan_is_rejected_in_3_0_messages() -> None:
    """T14: NaN and Infinity are refused at any depth of a 3.0 message."""
    raw = encode(make_state_v3()).replace(b'"stateOfCharge":80.0', b'"stateOfCharge":NaN')
    result = failure(decode(Topic.STATE, raw, address=address(Topic.STATE)))
    assert result.problems[0].path == "$.powerSupply.stateOfCharge"
