"""The codec: decode never raises and explains every failure; encode is compact JSON (R14-R19)."""

from __future__ import annotations

import json
import re
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.spec_files import VERSIONS, example_files, needs_examples, topic_of_example
from vda5050.clock import FakeClock, format_timestamp
from vda5050.codec import DecodeFailure, EncodedBody, HeaderStamper, decode, decode_as, encode
from vda5050.models import (
    UINT32_MAX,
    AgvPosition,
    Connection,
    ConnectionState,
    Factsheet,
    InstantActions,
    Order,
    Velocity,
    Visualization,
)
from vda5050.models.base import LenientHeaderMessage, Message
from vda5050.models.instant_actions import LEGACY_ARRAY_KEY_NOTE
from vda5050.testing import (
    make_connection_v3,
    make_factsheet_v3,
    make_instant_actions,
    make_order,
    make_state,
)
from vda5050.topics import AgvId, Topic, TopicAddress
from vda_master.testing import make_factsheet

ADDRESS = TopicAddress("uagv", 2, AgvId("ExampleCorp", "AGV-0001"), Topic.CONNECTION)
CONNECTION = {
    "headerId": 7,
    "timestamp": "2024-08-19T10:15:30.123Z",
    "version": "2.1.0",
    "manufacturer": "ExampleCorp",
    "serialNumber": "AGV-0001",
    "connectionState": "ONLINE",
}


def payload(**changes: object) -> bytes:
    return json.dumps({**CONNECTION, **changes}).encode()


def failure(result: object) -> DecodeFailure:
    assert isinstance(result, DecodeFailure), f"expected a failure, got {result!r}"
    assert result.problems, "a failure must list at least one problem"
    return result


@needs_examples
@pytest.mark.parametrize(
    "path",
    [p for v in VERSIONS for p in example_files(v)],
    ids=lambda p: f"{p.parent.name}/{p.name}",
)
def test_valid_examples_decode_and_reencode_to_equal_json(path: Path) -> None:
    """Every valid example decodes, and encoding it gives back the same JSON document."""
    raw = path.read_bytes()
    message = decode(Topic(topic_of_example(path)), raw)
    assert not isinstance(message, DecodeFailure), message
    assert json.loads(encode(message)) == json.loads(raw)


SCHEMA_INVALID_PATHS = {
    "state_missing_safetyState.json": "$.safetyState",
    "state_bad_operatingMode.json": "$.operatingMode",
    "order_bad_blockingType.json": "$.nodes[0].actions[0].blockingType",
    "order_node_missing_actions.json": "$.nodes[0].actions",
    "connection_bad_enum.json": "$.connectionState",
}
#: Schema-invalid, but accepted on purpose by the tolerant reader (see the test below).
TOLERATED_EXAMPLE = "instantActions_v1_fieldname.json"


@needs_examples
@pytest.mark.parametrize(
    "path",
    [
        p
        for v in VERSIONS
        for p in example_files(v, "schema_invalid")
        if p.name != TOLERATED_EXAMPLE
    ],
    ids=lambda p: f"{p.parent.parent.name}/{p.name}",
)
def test_schema_invalid_examples_fail_at_the_wrong_path(path: Path) -> None:
    """R27: each schema-invalid example fails, and the failure names the JSON path that is wrong."""
    result = failure(decode(Topic(topic_of_example(path)), path.read_bytes()))
    assert SCHEMA_INVALID_PATHS[path.name] in [p.path for p in result.problems]


@needs_examples
def test_legacy_instant_actions_array_key_is_tolerated_and_flagged() -> None:
    """Tolerant reader (issue 8): 2.0 instantActions with the 1.x array name 'instantActions'
    (vda-5050-lib 1.4's dialect) are read as 'actions', and the message says what was tolerated;
    writing gives the spec-exact key only."""
    (path,) = [p for p in example_files("2.0.0", "schema_invalid") if p.name == TOLERATED_EXAMPLE]
    message = decode_as(InstantActions, Topic.INSTANT_ACTIONS, path.read_bytes())
    assert isinstance(message, InstantActions)
    assert message.actions
    assert message.tolerated == (LEGACY_ARRAY_KEY_NOTE,)
    written = json.loads(encode(message))
    assert "actions" in written
    assert "instantActions" not in written


def test_spec_exact_instant_actions_tolerate_nothing() -> None:
    """A message with 'actions' is read without any note."""
    message = make_instant_actions()
    decoded = decode_as(InstantActions, Topic.INSTANT_ACTIONS, encode(message))
    assert isinstance(decoded, InstantActions)
    assert decoded.tolerated == ()


def test_decode_returns_the_typed_model() -> None:
    """A valid connection message decodes into a Connection with enum values."""
    message = decode_as(Connection, Topic.CONNECTION, payload(), address=ADDRESS)
    assert isinstance(message, Connection)
    assert message.connection_state is ConnectionState.ONLINE
    assert message.header_id == 7


@pytest.mark.parametrize(
    ("raw", "reason"),
    [
        (b"\xff\xfe\x00garbage", "UTF-8"),
        (b"not json at all", "not valid JSON"),
        (b"", "not valid JSON"),
        (b"[1, 2, 3]", "should be an object"),
        (b"[" * 5000 + b"]" * 5000, "recursion limit"),
        (payload(headerId="7"), "valid integer"),
        (payload(headerId=-1), "greater than or equal to 0"),
        (payload(headerId=UINT32_MAX + 1), "less than or equal to"),
        (payload(connectionState="online"), "'ONLINE'"),
        (payload(timestamp="yesterday"), "pattern"),
        (payload(version="2.1"), "pattern"),
        (payload().replace(b'"headerId": 7', b'"headerId": NaN'), "valid integer"),
    ],
)
def test_hostile_payloads_fail_with_a_reason(raw: bytes, reason: str) -> None:
    """Malformed input never raises; the failure says what is wrong."""
    result = failure(decode(Topic.CONNECTION, raw))
    assert any(reason in problem.reason for problem in result.problems), result.problems


def test_booleans_must_be_json_booleans() -> None:
    """R19: the string "true" is not a boolean."""
    order = {
        **CONNECTION,
        "orderId": "o",
        "orderUpdateId": 0,
        "nodes": [{"nodeId": "n", "sequenceId": 0, "released": "true", "actions": []}],
        "edges": [],
    }
    result = failure(decode(Topic.ORDER, json.dumps(order).encode()))
    assert result.problems[0].path == "$.nodes[0].released"


def test_nan_and_infinity_are_rejected_even_inside_action_parameters() -> None:
    """R19: NaN and Infinity are not JSON numbers the standard allows, at any depth."""
    order = {
        **CONNECTION,
        "orderId": "o",
        "orderUpdateId": 0,
        "nodes": [
            {
                "nodeId": "n",
                "sequenceId": 0,
                "released": True,
                "actions": [
                    {
                        "actionType": "beep",
                        "actionId": "a",
                        "blockingType": "NONE",
                        "actionParameters": [{"key": "k", "value": {"deep": [1.0, "INF"]}}],
                    }
                ],
            }
        ],
        "edges": [],
    }
    raw = json.dumps(order).encode().replace(b'"INF"', b"Infinity")
    result = failure(decode(Topic.ORDER, raw))
    assert result.problems[0].path == "$.nodes[0].actions[0].actionParameters[0].value"
    assert "NaN and Infinity" in result.problems[0].reason
    positioned = make_order(["n"]).model_dump(by_alias=True, exclude_none=True)
    raw = (
        json.dumps(positioned)
        .encode()
        .replace(b'"x":0.0', b'"x":NaN')
        .replace(b'"x": 0.0', b'"x": NaN')
    )
    assert b"NaN" in raw
    assert failure(decode(Topic.ORDER, raw)).problems[0].path == "$.nodes[0].nodePosition.x"


def test_oversized_payload_is_refused_before_parsing() -> None:
    """A payload over the configured size limit fails with its size in the reason."""
    result = failure(decode(Topic.CONNECTION, payload(), max_bytes=50))
    assert result.problems[0].path == "$"
    assert "over the 50 limit" in result.problems[0].reason


def test_an_oversized_order_is_still_named_by_its_head() -> None:
    """R30: the rejection of an order too large to parse references its orderId and
    orderUpdateId, read from the payload's head; a head without them gives none."""
    big = encode(make_order([f"n{i}" for i in range(40)], order_id="huge", order_update_id=7))
    result = failure(decode(Topic.ORDER, big, max_bytes=1000))
    assert "over the 1000 limit" in result.problems[0].reason
    assert result.references == (("orderId", "huge"), ("orderUpdateId", "7"))
    tail_only = b'{"nodes": [' + b" " * 5000 + b'], "orderId": "late"}'
    assert failure(decode(Topic.ORDER, tail_only, max_bytes=1000)).references == ()
    empty = b'{"orderId": "", "orderUpdateId": 0, "nodes": [' + b" " * 2000 + b"]}"
    named = failure(decode(Topic.STATE, empty, max_bytes=1000)).references
    assert named == (("orderId", ""), ("orderUpdateId", "0"))  # a state's empty orderId too


def test_wrong_major_version_is_rejected() -> None:
    """R17: a 3.x message is not decoded as 2.x, and the topic's v2 must match."""
    result = failure(decode(Topic.CONNECTION, payload(version="3.0.0"), address=ADDRESS))
    assert result.problems[0].path == "$.version"
    assert "not a 2.x version" in result.problems[0].reason
    v3_topic = TopicAddress("uagv", 3, ADDRESS.agv, Topic.CONNECTION)
    result = failure(decode(Topic.CONNECTION, payload(), address=v3_topic))
    assert "does not match the topic's v3" in result.problems[0].reason


def test_header_must_match_the_topic() -> None:
    """R18: manufacturer and serialNumber in the payload equal the topic levels."""
    result = failure(decode(Topic.CONNECTION, payload(serialNumber="other"), address=ADDRESS))
    assert [p.path for p in result.problems] == ["$.serialNumber"]
    result = failure(decode(Topic.CONNECTION, payload(manufacturer="X"), address=ADDRESS))
    assert [p.path for p in result.problems] == ["$.manufacturer"]


def test_failure_keeps_references_for_error_reporting() -> None:
    """A failed order still yields headerId, orderId and orderUpdateId for errorReferences."""
    bad = {**CONNECTION, "orderId": "o-9", "orderUpdateId": 3, "nodes": "nope", "edges": []}
    result = failure(decode(Topic.ORDER, json.dumps(bad).encode()))
    assert result.header_id == 7
    assert ("orderId", "o-9") in result.references
    assert ("orderUpdateId", "3") in result.references
    assert "$.nodes" in result.summary()


def test_failure_lists_every_problem() -> None:
    """All problems of a payload are reported, not only the first."""
    bad = {**CONNECTION, "headerId": "x", "connectionState": "NOPE"}
    del bad["timestamp"]
    paths = {p.path for p in failure(decode(Topic.CONNECTION, json.dumps(bad).encode())).problems}
    assert paths == {"$.headerId", "$.timestamp", "$.connectionState"}


def test_unknown_vendor_fields_are_accepted_and_unset_optionals_omitted() -> None:
    """Extra fields are legal on input; encode leaves out optional fields that are not set."""
    message = decode(Topic.CONNECTION, payload(vendorField={"a": 1}))
    assert isinstance(message, Connection)
    assert b"vendorField" not in encode(message)
    order = Order.model_validate(
        {
            **CONNECTION,
            "orderId": "o",
            "orderUpdateId": 0,
            "edges": [],
            "nodes": [{"nodeId": "n", "sequenceId": 0, "released": True, "actions": []}],
        }
    )
    encoded = encode(order)
    assert b"zoneSetId" not in encoded
    assert b"nodePosition" not in encoded
    assert b" " not in encoded, "encode must be compact"


def test_stamper_counts_per_topic_and_stamps_the_header() -> None:
    """R15/R16: headerId rises by one per topic; the timestamp is UTC with milliseconds and Z."""
    clock = FakeClock(datetime(2026, 3, 4, 5, 6, 7, 891_234, tzinfo=UTC))
    stamper = HeaderStamper(AgvId("acme", "r1"), "2.0.0", clock)
    template = Connection.model_validate({**CONNECTION, "headerId": 0})
    first = stamper.stamp(Topic.CONNECTION, template)
    second = stamper.stamp(Topic.CONNECTION, template)
    other = stamper.stamp(Topic.STATE, template)
    assert (first.header_id, second.header_id, other.header_id) == (0, 1, 0)
    assert first.timestamp == "2026-03-04T05:06:07.891Z"
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z", first.timestamp)
    assert (first.version, first.manufacturer, first.serial_number) == ("2.0.0", "acme", "r1")


def test_stamper_header_id_wraps_at_uint32() -> None:
    """R15: headerId is a uint32 and wraps to 0 after its maximum."""
    stamper = HeaderStamper(AgvId("acme", "r1"), "2.1.0", FakeClock())
    stamper._last[Topic.STATE] = UINT32_MAX - 1
    assert stamper.next_header_id(Topic.STATE) == UINT32_MAX
    assert stamper.next_header_id(Topic.STATE) == 0


@pytest.mark.parametrize("version", ["2.0.0", "2.1.0"])
@pytest.mark.parametrize("serial", ["r1", 'robot "7" \\ Süd\n', "\u00e9\u4e2d\U0001f697"])
def test_encode_stamped_gives_the_bytes_of_the_stamped_copy(version: str, serial: str) -> None:
    """R14-R16: a visualization's header written in front of its encoded fields (the fast way)
    is byte for byte the stamped copy's encoding, escaping included; headerIds are shared."""
    clock = FakeClock(datetime(2026, 3, 4, 5, 6, 7, 891_234, tzinfo=UTC))
    fast = HeaderStamper(AgvId('acme "A"', serial), version, clock)
    slow = HeaderStamper(AgvId('acme "A"', serial), version, clock)
    position = AgvPosition(x=1.5, y=-2.0, theta=0.25, map_id="m", position_initialized=True)
    messages: list[Visualization | Connection] = [
        Visualization(agv_position=position, velocity=Velocity(vx=1.0)),
        Visualization(),  # nothing but the header
        Connection.model_validate({**CONNECTION, "headerId": 0}),  # a required header: stamp()
    ]
    for message in messages * 2:
        topic = Topic.CONNECTION if isinstance(message, Connection) else Topic.VISUALIZATION
        encoded = fast.encode_stamped(topic, message)
        assert encoded == encode(slow.stamp(topic, message))
        decoded = decode_as(type(message), topic, encoded)
        assert not isinstance(decoded, DecodeFailure), decoded
        assert decoded.serial_number == serial
    assert fast.last_header_id(Topic.VISUALIZATION) == 3
    other = HeaderStamper(AgvId("other", "r9"), version, clock)
    stamped = other.stamp(Topic.VISUALIZATION, messages[0])  # a header there already
    assert fast.encode_stamped(Topic.VISUALIZATION, stamped) == encode(
        slow.stamp(Topic.VISUALIZATION, stamped)
    )


@pytest.mark.parametrize("version", ["2.0.0", "2.1.0", "3.0.0"])
@pytest.mark.parametrize("serial", ["r1", 'robot "7" \\ Süd\n'])
def test_encode_body_gives_the_bytes_of_the_stamped_message(version: str, serial: str) -> None:
    """R14-R16: a body encoded once (connection, factsheet) with a fresh header in front is byte
    for byte the stamped message's encoding, and decodes for the stamper's vehicle."""
    clock = FakeClock(datetime(2026, 3, 4, 5, 6, 7, 891_234, tzinfo=UTC))
    fast = HeaderStamper(AgvId('acme "A"', serial), version, clock)
    slow = HeaderStamper(AgvId('acme "A"', serial), version, clock)
    messages: list[tuple[Topic, Message | LenientHeaderMessage]] = (
        [(Topic.CONNECTION, make_connection_v3()), (Topic.FACTSHEET, make_factsheet_v3())]
        if version == "3.0.0"
        else [
            (Topic.CONNECTION, Connection.model_validate({**CONNECTION, "headerId": 0})),
            (Topic.FACTSHEET, make_factsheet(serial_number="someone else", header_id=5)),
        ]
    )
    for topic, message in messages:
        body = EncodedBody.of(message)
        for _ in range(2):
            encoded = fast.encode_body(topic, body)
            assert encoded == encode(slow.stamp(topic, message))
            decoded = decode_as(type(message), topic, encoded)
            assert not isinstance(decoded, DecodeFailure), decoded
            assert (decoded.serial_number, decoded.version) == (serial, version)
    assert fast.last_header_id(Topic.FACTSHEET) == 1


def test_encode_body_refuses_the_other_generation() -> None:
    """R17: a 2.x body never goes out under a 3.0.0 header, nor a 3.0 one under 2.x."""
    body = EncodedBody.of(Connection.model_validate({**CONNECTION, "headerId": 0}))
    stamper = HeaderStamper(AgvId("acme", "r1"), "3.0.0", FakeClock())
    with pytest.raises(ValueError, match=r"cannot stamp a 2\.x Connection"):
        stamper.encode_body(Topic.CONNECTION, body)
    stamper = HeaderStamper(AgvId("acme", "r1"), "2.1.0", FakeClock())
    with pytest.raises(ValueError, match=r"cannot stamp a 3\.x Connection"):
        stamper.encode_body(Topic.CONNECTION, EncodedBody.of(make_connection_v3()))


def test_encode_stamped_refuses_the_other_generation() -> None:
    """A 2.x visualization never goes out under a 3.0.0 header."""
    stamper = HeaderStamper(AgvId("acme", "r1"), "3.0.0", FakeClock())
    with pytest.raises(ValueError, match=r"cannot stamp a 2\.x Visualization"):
        stamper.encode_stamped(Topic.VISUALIZATION, Visualization())


@pytest.mark.parametrize("version", ["1.1.0", "3.1.0", "2.1"])
def test_stamper_refuses_unknown_versions(version: str) -> None:
    """Only 2.0.0, 2.1.0 and 3.0.0 are spoken."""
    with pytest.raises(ValueError, match="version must be one of"):
        HeaderStamper(AgvId("acme", "r1"), version, FakeClock())


def test_format_timestamp_converts_to_utc() -> None:
    """Timestamps are always UTC even when given an aware local time."""
    local = datetime(2026, 1, 1, 1, 0, 0, 5000, tzinfo=timezone(timedelta(hours=1)))
    assert format_timestamp(local) == "2026-01-01T00:00:00.005Z"


def test_format_timestamp_truncates_to_milliseconds_with_four_digit_years() -> None:
    """Milliseconds are cut, not rounded; the year has four digits as ISO 8601 wants."""
    assert format_timestamp(datetime(2026, 3, 4, 5, 6, 7, 999999, tzinfo=UTC)) == (
        "2026-03-04T05:06:07.999Z"
    )
    assert format_timestamp(datetime(999, 1, 1, tzinfo=UTC)) == "0999-01-01T00:00:00.000Z"


@given(
    moment=st.datetimes(
        min_value=datetime(2, 1, 1),  # noqa: DTZ001 - hypothesis adds the zones
        max_value=datetime(9998, 12, 31),  # noqa: DTZ001 - UTC of them stays in range
        timezones=st.sampled_from([UTC, timezone(timedelta(hours=5, minutes=30)), timezone.min]),
    ),
    earlier=st.datetimes(timezones=st.just(UTC)),
)
def test_format_timestamp_is_isoformat_in_utc_cut_to_milliseconds(
    moment: datetime, earlier: datetime
) -> None:
    """For any moment and whatever minute was formatted before it (the kept prefix), the text
    is ``isoformat`` of the moment in UTC, cut to milliseconds, with ``Z`` (R16)."""
    format_timestamp(earlier)
    utc = moment.astimezone(UTC)
    expected = utc.replace(tzinfo=None).isoformat(timespec="milliseconds") + "Z"
    assert format_timestamp(moment) == expected


def test_state_decode_rejects_string_numbers_in_nested_objects() -> None:
    """Strict decoding applies at every depth (batteryCharge must be a number)."""
    raw = json.loads(encode(make_state()))
    raw["batteryState"]["batteryCharge"] = "80"
    result = failure(decode(Topic.STATE, json.dumps(raw).encode()))
    assert result.problems[0].path == "$.batteryState.batteryCharge"


@pytest.mark.parametrize(
    ("topic", "path", "spelling"),
    [
        (Topic.CONNECTION, ("connectionState",), "CONNECTION_BROKEN"),
        (Topic.STATE, ("operatingMode",), "TEACH_IN"),
        (Topic.STATE, ("operatingMode",), "automatic"),
        (Topic.STATE, ("safetyState", "eStop"), "AUTO_ACK"),
    ],
)
def test_enums_use_the_exact_2x_spelling(
    topic: Topic, path: tuple[str, ...], spelling: str
) -> None:
    """R20: enum values are case-sensitive 2.x spellings; 3.0 snake case is rejected."""
    base = (
        json.loads(payload(connectionState="ONLINE"))
        if topic is Topic.CONNECTION
        else json.loads(encode(make_state()))
    )
    target = base
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = spelling
    result = failure(decode(topic, json.dumps(base).encode()))
    assert result.problems[0].path == "$." + ".".join(path)


def test_action_parameters_are_key_value_pairs_of_any_json_value() -> None:
    """R85: actionParameters is an array of {key, value}; value is array, bool, number, string
    or object, never null."""
    order = json.loads(encode(make_order(["n"])))
    values: list[object] = [[1, "a"], True, 2.5, 7, "s", {"k": [1]}]
    order["nodes"][0]["actions"] = [
        {
            "actionType": "beep",
            "actionId": "a",
            "blockingType": "NONE",
            "actionParameters": [{"key": f"k{i}", "value": v} for i, v in enumerate(values)],
        }
    ]
    decoded = decode(Topic.ORDER, json.dumps(order).encode())
    assert isinstance(decoded, Order)
    assert [p.value for p in decoded.nodes[0].actions[0].action_parameters or []] == values
    order["nodes"][0]["actions"][0]["actionParameters"] = [{"key": "k", "value": None}]
    assert (
        "must not be null"
        in failure(decode(Topic.ORDER, json.dumps(order).encode())).problems[0].reason
    )
    order["nodes"][0]["actions"][0]["actionParameters"] = [{"value": 1}]
    assert (
        failure(decode(Topic.ORDER, json.dumps(order).encode()))
        .problems[0]
        .path.endswith("actionParameters[0].key")
    )


def test_factsheet_envelopes_keep_the_lowercase_d() -> None:
    """§6.15 spells agvGeometry.envelopes2d/envelopes3d with a lowercase d: read and written so,
    so that another stack's envelopes are not silently dropped."""
    payload = {
        **{k: v for k, v in json.loads(encode(make_factsheet())).items() if k != "agvGeometry"},
        "agvGeometry": {"envelopes2d": [{"set": "e", "polygonPoints": [{"x": 0, "y": 0}]}]},
    }
    decoded = decode(Topic.FACTSHEET, json.dumps(payload).encode())
    assert isinstance(decoded, Factsheet)
    assert [e.set for e in decoded.agv_geometry.envelopes2d or []] == ["e"]
    assert "envelopes2d" in json.loads(encode(decoded))["agvGeometry"]
