"""The passive conformance check (docs/inspect.md, ``vda-inspect``): each rule a listener can
judge, on crafted traffic."""

from __future__ import annotations

from typing import Any

import pytest

from vda5050.codec import encode
from vda5050.models import Connection, ConnectionState, ControlPoint, Trajectory
from vda5050.mqtt import InboundMessage
from vda5050.testing import HEADER, make_factsheet_v3, make_order, make_order_v3, make_state
from vda5050.topics import Topic
from vda_inspect.cli import InspectConfig, Listener, load_config
from vda_inspect.rules import Inspector, InspectSettings
from vda_inspect.severity import Severity
from vda_master.testing import make_factsheet
from vda_vehicle.testing import action, instant

STATE = "uagv/v2/acme/robot_0/state"
CONNECTION = "uagv/v2/acme/robot_0/connection"


def _state(header_id: int, stamp: str = "2026-11-29T10:00:00.000Z", **fields: Any) -> bytes:
    return encode(make_state(header_id=header_id, timestamp=stamp, **fields))


def _rules(found: list[Any]) -> list[tuple[str, Severity]]:
    return [(f.rule, f.severity) for f in found]


def test_a_topic_that_is_not_vda_5050_is_r01() -> None:
    inspector = Inspector()
    (finding,) = inspector.observe("uagv/v2/acme/state", b"{}", qos=0, retain=False, now=0)
    assert (finding.rule, finding.vehicle) == ("R01", "?")
    assert inspector.report()["unreadableTopics"][0]["count"] == 1  # type: ignore[index]


def test_qos_is_judged_per_topic_unless_switched_off() -> None:
    online = encode(Connection.model_validate({**HEADER, "connection_state": "ONLINE"}))
    inspector = Inspector()
    assert _rules(inspector.observe(CONNECTION, online, qos=0, retain=False, now=0)) == [
        ("R05", Severity.VIOLATION)
    ]
    assert _rules(inspector.observe(STATE, _state(0), qos=1, retain=False, now=0)) == [
        ("R04", Severity.VIOLATION)
    ]
    lenient = Inspector(InspectSettings(check_qos=False))
    assert lenient.observe(STATE, _state(0), qos=1, retain=False, now=0) == []


def test_an_invalid_message_names_what_is_wrong() -> None:
    inspector = Inspector()
    (bad,) = inspector.observe(STATE, b'{"headerId": 1}', qos=0, retain=False, now=0)
    assert bad.rule == "R14-R20"
    assert "timestamp" in bad.text
    other = encode(make_state(serial_number="robot_9"))  # the header names another vehicle
    (wrong,) = inspector.observe(STATE, other, qos=0, retain=False, now=0)
    assert "serialNumber" in wrong.text


def test_header_ids_go_up_by_one_per_topic() -> None:
    inspector = Inspector()
    seen = [
        _rules(inspector.observe(STATE, _state(header_id), qos=0, retain=False, now=0))
        for header_id in (4, 5, 6, 6, 5, 9, 0)
    ]
    assert seen == [
        [],
        [],
        [],
        [("R15", Severity.VIOLATION)],  # 6 again
        [("R15", Severity.VIOLATION)],  # back to 5
        [("R15", Severity.NOTICE)],  # 6, 7 and 8 not seen: lost on the way, perhaps
        [("R15", Severity.NOTICE)],  # back to 0: a restart
    ]
    assert inspector.violations() == 2


def _connection(header_id: int, state: ConnectionState) -> bytes:
    return encode(
        Connection.model_validate({**HEADER, "header_id": header_id, "connection_state": state})
    )


def test_a_retained_message_does_not_start_the_sequence() -> None:
    """A retained message is stale (an earlier run's, perhaps): the live ones are not held
    against it, only against each other."""
    inspector = Inspector()
    stale = _connection(7, ConnectionState.OFFLINE)
    assert inspector.observe(CONNECTION, stale, qos=1, retain=True, now=0) == []
    live = _connection(1, ConnectionState.ONLINE)
    assert inspector.observe(CONNECTION, live, qos=1, retain=False, now=1) == []
    back = _connection(0, ConnectionState.OFFLINE)
    assert _rules(inspector.observe(CONNECTION, back, qos=1, retain=False, now=2)) == [
        ("R15", Severity.NOTICE)
    ]


def test_a_vehicle_online_again_counts_anew() -> None:
    """OFFLINE (or CONNECTIONBROKEN), then ONLINE: perhaps a restarted process, whose headerIds
    start again; within a session they must go on."""
    inspector = Inspector()
    steps = [
        (CONNECTION, _connection(1, ConnectionState.ONLINE)),
        (STATE, _state(10)),
        (CONNECTION, _connection(2, ConnectionState.OFFLINE)),
        (CONNECTION, _connection(1, ConnectionState.ONLINE)),
        (STATE, _state(0)),
        (STATE, _state(1)),
    ]
    for topic, payload in steps:
        assert (
            inspector.observe(
                topic, payload, qos=1 if topic == CONNECTION else 0, retain=False, now=0
            )
            == []
        )
    assert _rules(inspector.observe(STATE, _state(1), qos=0, retain=False, now=0)) == [
        ("R15", Severity.VIOLATION)
    ]


def test_an_order_is_checked_as_a_vehicle_would() -> None:
    order = make_order(["a", "b", "c"], first_sequence_id=3)  # a new order starts at 0
    inspector = Inspector()
    found = inspector.observe(
        "uagv/v2/acme/robot_0/order", encode(order), qos=0, retain=False, now=0
    )
    assert [f.rule for f in found] == ["R21-R26"]
    assert found[0].side == "master control"


def test_a_silent_online_vehicle_is_r92_once_per_silence() -> None:
    inspector = Inspector()
    online = encode(
        Connection.model_validate({**HEADER, "connection_state": ConnectionState.ONLINE})
    )
    inspector.observe(CONNECTION, online, qos=1, retain=False, now=0.0)
    inspector.observe(STATE, _state(0), qos=0, retain=False, now=1.0)
    assert inspector.tick(20.0) == []
    (late,) = inspector.tick(34.0)
    assert late.rule == "R92"
    assert inspector.tick(40.0) == []
    assert inspector.observe(STATE, _state(1), qos=0, retain=False, now=45.0) == []  # told already
    assert _rules(inspector.observe(STATE, _state(2), qos=0, retain=False, now=80.0)) == [
        ("R92", Severity.VIOLATION)
    ]


def test_states_stamped_closer_than_min_state_interval_are_r94() -> None:
    """By the states' own timestamps: a listener that read two states in one go does not
    make them close."""
    inspector = Inspector()
    factsheet = make_factsheet()  # minStateInterval 0.1 s
    inspector.observe(
        "uagv/v2/acme/robot_0/factsheet", encode(factsheet), qos=0, retain=False, now=0
    )
    assert (
        inspector.observe(STATE, _state(0, "2026-11-29T10:00:00.000Z"), qos=0, retain=False, now=1)
        == []
    )
    assert (
        inspector.observe(STATE, _state(1, "2026-11-29T10:00:00.100Z"), qos=0, retain=False, now=1)
        == []
    )
    found = inspector.observe(
        STATE, _state(2, "2026-11-29T10:00:00.120Z"), qos=0, retain=False, now=1
    )
    assert _rules(found) == [("R94", Severity.VIOLATION)]
    assert "20 ms" in found[0].text


def test_the_report_counts_each_kind_once_with_its_first_text() -> None:
    inspector = Inspector()
    for header_id in (1, 1, 1):
        inspector.observe(STATE, _state(header_id), qos=0, retain=False, now=0)
    report = inspector.report()
    vehicle = report["vehicles"]["acme/robot_0"]  # type: ignore[index]
    assert vehicle["messages"] == {"state": 3}
    (finding,) = vehicle["findings"]
    assert (finding["rule"], finding["count"], finding["first"]) == ("R15", 2, "headerId 1 again")
    assert report["violations"] == 2


def test_interface_names_come_as_a_list_or_comma_separated() -> None:
    assert load_config(["--interface-names", "uagv, plant7"], environ={}).interface_names == [
        "uagv",
        "plant7",
    ]
    assert load_config(["--interface-names", '["x"]'], environ={}).interface_names == ["x"]
    assert load_config([], environ={}).interface_names == ["uagv", "vda5050"]


# -- master control against the vehicle's factsheet (R112-R114) -----------------------------

ORDER = "uagv/v2/acme/robot_0/order"
FACTSHEET = "uagv/v2/acme/robot_0/factsheet"


def _with_factsheet(**factsheet: Any) -> Inspector:
    inspector = Inspector()
    message = encode(make_factsheet(**factsheet))
    assert inspector.observe(FACTSHEET, message, qos=0, retain=True, now=0) == []
    return inspector


def _order_findings(inspector: Inspector, order: Any) -> list[tuple[str, str]]:
    found = inspector.observe(ORDER, encode(order), qos=0, retain=False, now=1)
    return [(f.rule, f.text) for f in found]


def test_an_optional_field_the_factsheet_does_not_list_is_r112() -> None:
    inspector = _with_factsheet(supported=())
    found = _order_findings(inspector, make_order(["a", "b"]))
    assert found[0] == (
        "R112",
        "order.nodes.nodePosition (node a) is sent, but the factsheet does not list it",
    )
    assert {rule for rule, _ in found} == {"R112"}


def test_a_field_the_factsheet_requires_is_r113_where_it_is_missing() -> None:
    inspector = _with_factsheet(required=["order.edges.maxSpeed"])
    found = _order_findings(inspector, make_order(["a", "b", "c"]))
    assert found == [
        (
            "R113",
            "order.edges.maxSpeed is REQUIRED by the factsheet but missing on edge a-b, edge b-c",
        )
    ]


def test_protocol_limits_and_the_order_interval_are_r114() -> None:
    inspector = _with_factsheet(
        array_lens={"order.nodes": 2},
        string_lens={"idNumericalOnly": True},
        min_order_interval=1.0,
    )
    first = make_order(["1", "2", "3"], order_id="7", timestamp="2026-11-29T10:00:00.000Z")
    texts = [text for rule, text in _order_findings(inspector, first) if rule == "R114"]
    assert "order.nodes holds 3 entries, over the vehicle's limit of 2" in texts
    assert "id '1-2' is not numeric (vehicle sets idNumericalOnly)" in texts
    update = make_order(
        ["3"], order_id="7", order_update_id=1, first_sequence_id=4,
        timestamp="2026-11-29T10:00:00.200Z",
    )  # fmt: skip
    texts = [text for rule, text in _order_findings(inspector, update) if rule == "R114"]
    assert texts == ["two orders stamped 200 ms apart (minOrderInterval 1 s)"]


def test_instant_actions_over_the_limits_are_r114() -> None:
    inspector = _with_factsheet(array_lens={"instantActions": 1})
    message = instant(action("startPause", "p1"), action("stopPause", "p2"))
    found = inspector.observe(
        "uagv/v2/acme/robot_0/instantActions", encode(message), qos=0, retain=False, now=1
    )
    assert [(f.rule, f.text) for f in found] == [
        ("R114", "instantActions holds 2 entries, over the vehicle's limit of 1")
    ]


def test_without_a_factsheet_nothing_is_judged_against_one() -> None:
    assert _order_findings(Inspector(), make_order(["a", "b"])) == []


def test_every_topic_has_its_qos_rule_and_side() -> None:
    """3.0's zoneSet and responses too: QoS 0, from fleet control (3.0 §4.2)."""
    inspector = Inspector()
    for topic in Topic:
        found = inspector.observe(
            f"vda5050/v3/acme/robot_0/{topic.value}", b"{}", qos=2, retain=False, now=0
        )
        qos = [f for f in found if f.rule in {"R03", "R04", "R05"}]
        assert len(qos) == 1, topic
        side = (
            "vehicle"
            if topic in {Topic.STATE, Topic.VISUALIZATION, Topic.CONNECTION, Topic.FACTSHEET}
            else "master control"
        )
        assert qos[0].side == side


async def test_a_message_the_inspector_cannot_judge_does_not_end_the_listening(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    listener = Listener(InspectConfig())
    calls: list[str] = []

    def broken(topic: str, payload: bytes, **_: object) -> list[Any]:
        calls.append(topic)
        raise ValueError("something unforeseen")

    monkeypatch.setattr(listener.inspector, "observe", broken)
    for _ in range(2):
        await listener.on_message(InboundMessage(STATE, b"{}"))
    assert calls == [STATE, STATE]
    printed = capsys.readouterr().out.splitlines()
    assert printed == [f"could not judge a message on {STATE}: ValueError('something unforeseen')"]


# -- every order answered (R93, R27-R29) --------------------------------------------------------


def _online_vehicle() -> Inspector:
    inspector = Inspector()
    inspector.observe(
        CONNECTION, _connection(0, ConnectionState.ONLINE), qos=1, retain=False, now=0
    )
    return inspector


def _send(inspector: Inspector, order: Any, now: float) -> None:
    assert inspector.observe(ORDER, encode(order), qos=0, retain=False, now=now) == []


def test_an_order_a_state_carries_or_an_error_names_is_answered() -> None:
    inspector = _online_vehicle()
    _send(inspector, make_order(["a", "b"], order_id="o1"), now=1.0)
    carried = _state(1, order_id="o1", order_update_id=0)
    inspector.observe(STATE, carried, qos=0, retain=False, now=1.2)
    _send(inspector, make_order(["b", "c"], order_id="o2", header_id=1), now=2.0)
    refused = make_state(
        header_id=2,
        errors=[
            {
                "errorType": "validationError",
                "errorLevel": "WARNING",
                "errorReferences": [{"referenceKey": "orderId", "referenceValue": "o2"}],
            }
        ],
    )
    inspector.observe(STATE, encode(refused), qos=0, retain=False, now=2.3)
    assert inspector.tick(10.0) == []


def test_an_order_nothing_answers_is_r93_once() -> None:
    inspector = _online_vehicle()
    _send(inspector, make_order(["a", "b"], order_id="o1"), now=1.0)
    inspector.observe(STATE, _state(1), qos=0, retain=False, now=1.5)  # an older order's state
    assert inspector.tick(2.5) == []
    _send(inspector, make_order(["a", "b"], order_id="o1", header_id=1), now=2.8)  # a resend
    assert inspector.tick(4.0) == []  # counted from the resend
    (late,) = inspector.tick(5.0)
    assert late.rule == "R93"
    assert (
        late.text == "no state carried order 'o1' update 0 or an error naming it within 2.2 s of it"
    )
    assert inspector.tick(9.0) == []


def test_an_order_to_a_vehicle_that_is_not_online_is_not_waited_for() -> None:
    inspector = Inspector()
    _send(inspector, make_order(["a", "b"], order_id="o1"), now=1.0)
    assert inspector.tick(10.0) == []


INSTANT = "uagv/v2/acme/robot_0/instantActions"


def test_an_instant_action_is_answered_by_its_action_state_or_an_error_naming_it() -> None:
    """R93, R79: a stateRequest shows in the state it causes; a refused action is named in an
    error; one nothing answers is reported once."""
    inspector = _online_vehicle()
    message = instant(action("stateRequest", "s1"), action("fly", "f1"), action("startPause", "p1"))
    assert inspector.observe(INSTANT, encode(message), qos=0, retain=False, now=1.0) == []
    answer = make_state(
        header_id=1,
        action_states=[
            {"actionId": "s1", "actionType": "stateRequest", "actionStatus": "FINISHED"}
        ],
        errors=[
            {
                "errorType": "actionError",
                "errorLevel": "WARNING",
                "errorReferences": [{"referenceKey": "actionId", "referenceValue": "f1"}],
            }
        ],
    )
    inspector.observe(STATE, encode(answer), qos=0, retain=False, now=1.3)
    (late,) = inspector.tick(3.5)
    assert (late.rule, late.text) == (
        "R93",
        "no state showed instant action startPause 'p1' or an error naming it within 2.5 s of it",
    )
    assert inspector.tick(10.0) == []


def test_a_3_0_order_s_renamed_fields_are_judged_by_their_3_0_names() -> None:
    """A 3.0 robot lists ``order.nodes.nodeDescriptor`` (2.x: nodeDescription, T83): master
    control may send it; an order with a field the factsheet does not list is still R112."""
    factsheet = make_factsheet_v3(
        optional_parameters=["order.nodes.nodeDescriptor", "order.nodes.nodePosition"]
    )
    inspector = Inspector()
    base = "vda5050/v3/acme/robot_0"
    assert (
        inspector.observe(f"{base}/factsheet", encode(factsheet), qos=0, retain=True, now=0) == []
    )
    order = make_order_v3(["a", "b"])
    described = order.model_copy(
        update={"nodes": [n.model_copy(update={"node_descriptor": "dock"}) for n in order.nodes]}
    )
    found = inspector.observe(f"{base}/order", encode(described), qos=0, retain=False, now=1)
    assert [(f.rule, f.text) for f in found] == []
    speedy = described.model_copy(
        update={"edges": [e.model_copy(update={"maximum_speed": 1.0}) for e in order.edges]}
    )
    found = inspector.observe(f"{base}/order", encode(speedy), qos=0, retain=False, now=2)
    assert [(f.rule, f.text) for f in found if f.rule == "R112"] == [
        ("R112", "order.edges.maximumSpeed (edge a-b) is sent, but the factsheet does not list it")
    ]


def test_a_finished_factsheet_request_must_bring_a_factsheet() -> None:
    """R80: the factsheet may come before the state that shows the request FINISHED, or up to
    2 s after it; none at all is reported once."""
    for factsheet_at, expected in ((1.1, []), (2.5, []), (None, ["R80"])):
        inspector = Inspector()
        online = encode(Connection.model_validate({**HEADER, "connection_state": "ONLINE"}))
        inspector.observe(CONNECTION, online, qos=1, retain=False, now=0)
        request = instant(action("factsheetRequest", "f1"))
        inspector.observe(INSTANT, encode(request), qos=0, retain=False, now=1)
        if factsheet_at == 1.1:
            inspector.observe(FACTSHEET, encode(make_factsheet()), qos=0, retain=False, now=1.1)
        finished = make_state(
            header_id=1,
            action_states=[{"action_id": "f1", "action_status": "FINISHED"}],
        )
        inspector.observe(STATE, encode(finished), qos=0, retain=False, now=1.2)
        if factsheet_at == 2.5:
            inspector.observe(FACTSHEET, encode(make_factsheet()), qos=0, retain=False, now=2.5)
        found = inspector.tick(5.0) + inspector.tick(9.0)
        assert [f.rule for f in found] == expected, factsheet_at


def _with_trajectory(degree: int, knots: list[float], points: list[tuple[float, float]]) -> bytes:
    """An order a -> b (0,0) -> (10,0), a within 0.1 m, whose edge carries the trajectory."""
    order = make_order(["a", "b"])
    trajectory = Trajectory(
        degree=degree,
        knot_vector=knots,
        control_points=[ControlPoint(x=x, y=y) for x, y in points],
    )
    first = order.nodes[0]
    assert first.node_position is not None
    position = first.node_position.model_copy(update={"allowed_deviation_xy": 0.1})
    nodes = [first.model_copy(update={"node_position": position}), *order.nodes[1:]]
    edges = [order.edges[0].model_copy(update={"trajectory": trajectory})]
    return encode(order.model_copy(update={"nodes": nodes, "edges": edges}))


def test_an_edge_trajectory_is_a_nurbs_from_node_to_node() -> None:
    """§6.6.6: a curve a vehicle can follow, starting within the node's allowedDeviationXY."""
    topic = "uagv/v2/acme/robot_0/order"
    inspector = Inspector()
    good = _with_trajectory(2, [0, 0, 0, 1, 1, 1], [(0, 0), (5, 3), (10, 0)])
    assert inspector.observe(topic, good, qos=0, retain=False, now=0) == []
    (short,) = Inspector().observe(
        topic,
        _with_trajectory(2, [0, 0, 1, 1], [(0, 0), (5, 3), (10, 0)]),
        qos=0,
        retain=False,
        now=0,
    )
    assert short.rule == "§6.6.6"
    assert "edge a-b's trajectory: knotVector has 4 knots" in short.text
    (off,) = Inspector().observe(
        topic, _with_trajectory(1, [0, 0, 1, 1], [(0, 2), (10, 0)]), qos=0, retain=False, now=0
    )
    assert off.text == (
        "edge a-b's trajectory starts 2.00 m from node a, beyond its allowedDeviationXY of 0.10 m"
    )
    assert off.side == "master control"
