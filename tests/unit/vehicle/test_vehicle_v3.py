"""The 3.0 vehicle (``--vda-version 3.0.0``) without a broker: one test per 3.0 rule (Tnn,
docs/vda5050-3.md). Every message the vehicle sends validates against the official 3.0.0
schema of its topic."""

from __future__ import annotations

import functools
import json
from dataclasses import replace
from datetime import timedelta
from typing import Any

import pytest
from jsonschema import Draft202012Validator, FormatChecker

from tests.spec_files import needs_official_schemas, official_schema
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import Load, v3
from vda5050.models.v3.zone_set import Vertex
from vda5050.polygons import Point, touches
from vda5050.testing import (
    make_action_v3,
    make_instant_action_v3,
    make_instant_actions_v3,
    make_order_v3,
    make_stitching_update_v3,
    make_zone_set_v3,
    make_zone_v3,
)
from vda5050.topics import Topic
from vda_vehicle.config import VehicleSettings
from vda_vehicle.limits import MapExtent
from vda_vehicle.model import RobotMode
from vda_vehicle.runtime3 import VehicleRuntimeV3
from vda_vehicle.testing import Recorder, make_runtime_v3
from vda_vehicle.v3_inbound import stored

PREFIX = "vda5050/v3/acme/robot_0"
Json = dict[str, Any]


class Robot:
    """A 3.0 vehicle at (0, 0) on a fake clock, with what it sent."""

    def __init__(self, **settings: object) -> None:
        self.clock = FakeClock()
        self.vehicle, self.sent = make_runtime_v3(self.clock, **settings)
        self.vehicle.on_connected()

    @property
    def runtime(self) -> VehicleRuntimeV3:
        return self.vehicle

    def order(self, order: v3.Order) -> None:
        self.vehicle.handle_order(f"{PREFIX}/order", encode(order))

    def instant(self, *actions: v3.InstantAction) -> None:
        message = make_instant_actions_v3(*actions)
        self.vehicle.handle_instant_actions(f"{PREFIX}/instantActions", encode(message))

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / 0.2)):
            self.clock.advance(0.2)
            self.vehicle.tick(0.2, self.clock.monotonic())

    def state(self) -> Json:
        """The newest state, after one more tick so that deferred states go out."""
        self.run(0.2)
        return self.sent.of(Topic.STATE)[-1]

    def errors(self) -> list[tuple[str, str]]:
        return [(e["errorType"], e["errorLevel"]) for e in self.state()["errors"]]


def statuses(states: list[Json]) -> dict[str, str]:
    return {s["actionId"]: s["actionStatus"] for s in states}


@functools.cache
def _official(topic: str) -> Draft202012Validator:
    return Draft202012Validator(official_schema("3.0.0", topic), format_checker=FormatChecker())


def schema_problems(sent: Recorder) -> list[str]:
    """Every message ``sent`` that its official 3.0.0 schema refuses, with the reason."""
    return [
        f"{topic}: {error.message} at {error.json_path}"
        for topic, kind, body in sent.sent
        for error in _official(kind.value).iter_errors(json.loads(body))
    ]


def line(*xs: float) -> list[tuple[float, float]]:
    return [(x, 0.0) for x in xs]


# -- transport, connection, header -----------------------------------------------------------


def test_topics_interface_name_and_connection_states() -> None:
    """T01, T02, T05, T15: topics under ``vda5050/v3`` (the 3.x default interface name), with
    zoneSet; ONLINE after connect and a CONNECTION_BROKEN last will, 3.0 spelling."""
    robot = Robot()
    assert robot.vehicle.topics[Topic.ORDER] == f"{PREFIX}/order"
    assert robot.vehicle.topics[Topic.ZONE_SET] == f"{PREFIX}/zoneSet"
    assert robot.sent.of(Topic.CONNECTION)[0]["connectionState"] == "ONLINE"
    will = json.loads(robot.vehicle.will().payload)
    assert (will["connectionState"], will["version"]) == ("CONNECTION_BROKEN", "3.0.0")


def test_interface_name_defaults_per_major_version() -> None:
    """T01: the interface name defaults to ``vda5050`` for 3.x and ``uagv`` for 2.x; a
    configured one is kept."""
    assert VehicleSettings(vda_version="3.0.0").topic_interface_name == "vda5050"
    assert VehicleSettings(vda_version="2.1.0").topic_interface_name == "uagv"
    custom = VehicleSettings(vda_version="3.0.0", interface_name="plant")
    assert custom.topic_interface_name == "plant"


def test_idle_state_has_every_required_field() -> None:
    """T70, T74, T75: before any order orderId "", orderUpdateId 0, lastNodeId ""; errors []."""
    state = Robot().state()
    assert (state["orderId"], state["orderUpdateId"], state["lastNodeId"]) == ("", 0, "")
    assert state["instantActionStates"] == []
    assert state["errors"] == []
    assert state["powerSupply"]["stateOfCharge"] == 100.0
    assert state["mobileRobotPosition"]["localized"] is True


# -- order acceptance --------------------------------------------------------------------------


@needs_official_schemas
def test_order_is_driven_and_every_message_fits_the_official_schemas() -> None:
    """T32, T71, T10: a new order is taken, its first node counts as traversed at once and is
    not in nodeStates; nodes are passed one by one; every message sent fits its schema."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b", "c"], positions=line(0, 3, 6)))
    state = robot.state()
    assert (state["lastNodeId"], [n["nodeId"] for n in state["nodeStates"]]) == ("a", ["b", "c"])
    robot.run(12.0)
    state = robot.state()
    assert (state["lastNodeId"], state["lastNodeSequenceId"], state["nodeStates"]) == ("c", 4, [])
    assert schema_problems(robot.sent) == []
    header_ids = [s["headerId"] for s in robot.sent.of(Topic.STATE)]
    assert header_ids == list(range(len(header_ids)))  # T11


def test_the_state_answering_an_order_already_says_the_vehicle_drives() -> None:
    """T68 (R93, R94, R100 in 2.x): the state that answers an accepted order (sent at once,
    not a tick later) already shows the vehicle under way, so no second state follows only to
    say so."""
    robot = Robot()
    robot.clock.advance(1.0)  # past minStateInterval after the connect state
    before = len(robot.sent.of(Topic.STATE))
    robot.order(make_order_v3(["a", "b"], positions=line(0, 10)))
    answering = robot.sent.of(Topic.STATE)[before:]
    assert [(s["orderId"], s["driving"]) for s in answering] == [("order-1", True)]


def test_malformed_order_is_a_validation_failure() -> None:
    """T20: an order breaking T17 (edges != nodes - 1) is not taken: VALIDATION_FAILURE."""
    robot = Robot()
    order = make_order_v3(["a", "b"], positions=line(0, 3))
    robot.order(order.model_copy(update={"edges": []}))
    state = robot.state()
    assert state["orderId"] == ""
    assert set(robot.errors()) == {("VALIDATION_FAILURE", "WARNING")}


def test_unsupported_optional_field_is_critical() -> None:
    """T21: a direction or a minimum load handling device height (optional fields this
    vehicle cannot act on) rejects the order with UNSUPPORTED_PARAMETER, CRITICAL, naming the
    field."""
    robot = Robot()
    order = make_order_v3(["a", "b"], positions=line(0, 3))
    edge = order.edges[0].model_copy(update={"direction": "left"})
    robot.order(order.model_copy(update={"edges": [edge]}))
    state = robot.state()
    assert state["orderId"] == ""
    [error] = state["errors"]
    assert (error["errorType"], error["errorLevel"]) == ("UNSUPPORTED_PARAMETER", "CRITICAL")
    assert {"referenceKey": "field", "referenceValue": "order.edges.direction"} in error[
        "errorReferences"
    ]
    edge = order.edges[0].model_copy(update={"minimum_load_handling_device_height": 0.2})
    robot.order(order.model_copy(update={"edges": [edge]}))
    assert robot.errors()[-1] == ("UNSUPPORTED_PARAMETER", "CRITICAL")
    plain = make_action_v3("finePositioning", "fp2", retriable=True)
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3), node_actions={1: [plain]}))
    assert robot.state()["orderId"] == "order-1"  # retriable is supported (T52)


def test_unknown_action_is_an_invalid_order_action() -> None:
    """T22: an action the vehicle cannot perform: INVALID_ORDER_ACTION, WARNING."""
    robot = Robot()
    bad = make_action_v3("fly", "f1")
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3), node_actions={1: [bad]}))
    assert robot.errors() == [("INVALID_ORDER_ACTION", "WARNING")]


def test_unknown_map_is_refused() -> None:
    """T24: a node on a map the vehicle does not hold: UNKNOWN_MAP_ID, WARNING."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3), map_id="elsewhere"))
    assert robot.errors() == [("UNKNOWN_MAP_ID", "WARNING")]


def test_order_in_manual_mode_is_refused() -> None:
    """T26: an order in a mode other than AUTOMATIC/SEMIAUTOMATIC/INTERVENED is refused with
    MOBILE_ROBOT_NOT_AVAILABLE; T15: TEACHIN is reported as TEACH_IN."""
    robot = Robot()
    robot.vehicle.state = robot.vehicle.state.bumped(operating_mode=RobotMode.MANUAL)
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3)))
    assert robot.errors() == [("MOBILE_ROBOT_NOT_AVAILABLE", "WARNING")]
    robot.vehicle.state = robot.vehicle.state.bumped(operating_mode=RobotMode.TEACHIN)
    assert robot.state()["operatingMode"] == "TEACH_IN"


def test_other_order_active_and_the_running_order_goes_on() -> None:
    """T29, T27: a new orderId while not idle: OTHER_ORDER_ACTIVE; the first order goes on."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b"], positions=line(0, 10)))
    robot.order(make_order_v3(["a", "c"], order_id="order-2", positions=line(0, 5)))
    state = robot.state()
    assert state["orderId"] == "order-1"
    assert robot.errors() == [("OTHER_ORDER_ACTIVE", "WARNING")]


def test_new_order_with_update_id_above_zero_is_refused() -> None:
    """T30: a new orderId whose orderUpdateId is not 0 is refused (VALIDATION_FAILURE)."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3), order_update_id=2))
    assert robot.errors() == [("VALIDATION_FAILURE", "WARNING")]


def test_start_node_outside_the_deviation_ellipse() -> None:
    """T31, T99: the robot must stand inside the first node's ellipse. At 0.4 m across the
    major axis of a 1.0 x 0.2 ellipse it is outside (though within 1.0 m of the node):
    START_NODE_OUT_OF_RANGE; along the major axis it is inside and the order is taken."""
    ellipse = v3.AllowedDeviationXY(a=1.0, b=0.2, theta=0.0)
    robot = Robot()
    robot.order(make_order_v3(["a", "b"], positions=[(0.0, 0.4), (5.0, 0.4)], deviation=ellipse))
    assert robot.errors() == [("START_NODE_OUT_OF_RANGE", "WARNING")]
    robot.order(make_order_v3(["a", "b"], positions=[(0.6, 0.0), (5.0, 0.0)], deviation=ellipse))
    assert robot.state()["orderId"] == "order-1"


def test_outdated_update_and_same_update_id() -> None:
    """T33: a lower orderUpdateId is OUTDATED_ORDER_UPDATE. T35: the same orderUpdateId with
    identical content is discarded silently, with other content it is SAME_ORDER_UPDATE_ID."""
    robot = Robot()
    first = make_order_v3(["a", "b", "c"], positions=line(0, 10, 20), released=2)
    robot.order(first)
    update = make_stitching_update_v3(first, ["c", "d"])
    robot.order(update)
    assert robot.state()["orderUpdateId"] == 1
    robot.order(update.model_copy(update={"header_id": 7}))  # a resend: ignored
    assert robot.errors() == []
    robot.order(first)
    assert robot.errors() == [("OUTDATED_ORDER_UPDATE", "WARNING")]
    changed = update.model_copy(update={"order_description": "other"})
    robot.order(changed)
    assert robot.errors()[-1] == ("SAME_ORDER_UPDATE_ID", "WARNING")
    assert robot.state()["orderUpdateId"] == 1


def test_update_not_starting_at_the_decision_point_is_refused() -> None:
    """T36: an update whose first node is not the decision point (nodeId and sequenceId) is
    refused (VALIDATION_FAILURE) and the order goes on unchanged."""
    robot = Robot()
    first = make_order_v3(["a", "b", "c"], positions=line(0, 10, 20), released=2)
    robot.order(first)
    wrong = make_order_v3(
        ["c", "d"], order_update_id=1, first_sequence_id=4, positions=line(20, 30)
    )
    robot.order(wrong)
    state = robot.state()
    assert state["orderUpdateId"] == 0
    assert robot.errors() == [("VALIDATION_FAILURE", "WARNING")]


def test_stitching_node_resent_unchanged_and_appended_node_actions() -> None:
    """T40, T41, T37: the decision point is resent unchanged, with its actions, which are not
    run again; new actions at that spot ride on an appended node (sequenceId + 2); horizon
    nodes of the first message are dropped."""
    robot = Robot()
    wait = make_action_v3("finePositioning", "fp-1", v3.BlockingType.HARD)
    first = make_order_v3(
        ["a", "b", "c"], positions=line(0, 3, 20), released=2, node_actions={1: [wait]}
    )
    robot.order(first)
    robot.run(6.0)
    assert statuses(robot.state()["actionStates"])["fp-1"] == "FINISHED"
    new = make_action_v3("detectObject", "do-1", v3.BlockingType.HARD)
    update = make_stitching_update_v3(first, ["d"], decision_point_actions=[new])
    assert update.nodes[0] == first.nodes[1]  # resent unchanged, fp-1 included
    assert update.nodes[1].sequence_id == first.nodes[1].sequence_id + 2
    robot.order(update)
    state = robot.state()
    assert state["orderUpdateId"] == 1
    assert [a["actionId"] for a in state["actionStates"]] == ["fp-1", "do-1"]
    robot.run(12.0)
    state = robot.state()
    assert statuses(state["actionStates"]) == {"fp-1": "FINISHED", "do-1": "FINISHED"}
    assert state["lastNodeId"] == "d"


def test_update_following_cancel_is_refused() -> None:
    """T34: after cancelOrder an update of that order is ORDER_UPDATE_FOLLOWING_CANCEL."""
    robot = Robot()
    first = make_order_v3(["a", "b", "c"], positions=line(0, 10, 20), released=2)
    robot.order(first)
    robot.instant(make_instant_action_v3("cancelOrder", "cancel-1"))
    robot.run(10.0)
    robot.order(make_stitching_update_v3(first, ["c"]))
    assert robot.errors() == [("ORDER_UPDATE_FOLLOWING_CANCEL", "WARNING")]


# -- actions -----------------------------------------------------------------------------------


def test_single_action_runs_alone_while_the_robot_drives() -> None:
    """T48 (Table 3): a SINGLE action lets the robot drive but runs alone: the NONE action after
    it waits until it has ended. A HARD one stops driving."""
    robot = Robot(action_durations_s={"detectObject": 1.0, "finePositioning": 1.0})
    single = make_action_v3("detectObject", "single", v3.BlockingType.SINGLE)
    beside = make_action_v3("finePositioning", "beside", v3.BlockingType.NONE)
    robot.order(
        make_order_v3(["a", "b"], positions=line(0, 10), node_actions={0: [single, beside]})
    )
    robot.run(0.4)
    state = robot.state()
    assert statuses(state["actionStates"]) == {"single": "RUNNING", "beside": "WAITING"}
    assert state["driving"] is True
    robot.run(1.2)
    assert statuses(robot.state()["actionStates"])["beside"] in {"RUNNING", "FINISHED"}

    robot = Robot(action_durations_s={"detectObject": 1.0})
    hard = make_action_v3("detectObject", "hard", v3.BlockingType.HARD)
    robot.order(make_order_v3(["a", "b"], positions=line(0, 10), node_actions={0: [hard]}))
    robot.run(0.4)
    assert robot.state()["driving"] is False


def test_instant_actions_report_in_instant_action_states() -> None:
    """T28, T49: instant actions are reported in instantActionStates, not in actionStates, and
    do not keep the robot from being idle; 3.0 names (initializePosition) are understood."""
    robot = Robot()
    robot.instant(
        make_instant_action_v3(
            "initializePosition", "init", x=1.0, y=0.0, theta=0.0, mapId="map", lastNodeId="a"
        )
    )
    state = robot.state()
    assert state["actionStates"] == []
    assert statuses(state["instantActionStates"]) == {"init": "FINISHED"}
    assert state["instantActionStates"][0]["actionType"] == "initializePosition"
    assert (state["lastNodeId"], state["mobileRobotPosition"]["x"]) == ("a", 1.0)
    assert v3.State.model_validate(state).is_idle()


def test_cancel_order_with_order_id() -> None:
    """T44-T46: cancelOrder naming another order ends FAILED with NO_ORDER_TO_CANCEL (the
    actionId as reference) and the order goes on; naming the active one cancels it: FINISHED,
    node and edge states empty, orderId kept, robot idle."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b", "c"], positions=line(0, 10, 20)))
    robot.instant(make_instant_action_v3("cancelOrder", "c-1", orderId="someone-else"))
    state = robot.state()
    assert statuses(state["instantActionStates"]) == {"c-1": "FAILED"}
    [error] = state["errors"]
    assert (error["errorType"], error["errorLevel"]) == ("NO_ORDER_TO_CANCEL", "WARNING")
    assert {"referenceKey": "actionId", "referenceValue": "c-1"} in error["errorReferences"]
    assert len(state["nodeStates"]) == 2
    robot.instant(make_instant_action_v3("cancelOrder", "c-2", orderId="order-1"))
    robot.run(10.0)
    state = robot.state()
    assert statuses(state["instantActionStates"])["c-2"] == "FINISHED"
    assert (state["nodeStates"], state["edgeStates"], state["orderId"]) == ([], [], "order-1")
    assert v3.State.model_validate(state).is_idle()


def test_cancel_order_while_idle() -> None:
    """T46: cancelOrder while idle: FAILED and NO_ORDER_TO_CANCEL."""
    robot = Robot()
    robot.instant(make_instant_action_v3("cancelOrder", "c-1"))
    state = robot.state()
    assert statuses(state["instantActionStates"]) == {"c-1": "FAILED"}
    assert robot.errors() == [("NO_ORDER_TO_CANCEL", "WARNING")]


def test_unknown_or_retriable_instant_action_is_invalid() -> None:
    """Table 9: an instant action the robot cannot perform is INVALID_INSTANT_ACTION; so is
    one asking for retriable handling, which this robot does not offer."""
    robot = Robot()
    retriable = make_instant_action_v3("stateRequest", "s-1").model_copy(update={"retriable": True})
    robot.instant(make_instant_action_v3("teleport", "t-1"), retriable)
    state = robot.state()
    assert statuses(state["instantActionStates"]) == {"t-1": "FAILED", "s-1": "FAILED"}
    assert robot.errors() == [("INVALID_INSTANT_ACTION", "WARNING")] * 2


# -- zones, visualization, factsheet -----------------------------------------------------------


def test_zone_set_with_unsupported_zone_is_refused() -> None:
    """T88, T82: a zone set with a zone type the robot does not honour (LINE_GUIDED) is not
    taken over: UNSUPPORTED_PARAMETER (CRITICAL) with zoneSetId, zoneId and zoneType as
    references; a malformed one (T85: two vertices) is a VALIDATION_FAILURE."""
    robot = Robot()
    message = make_zone_set_v3(make_zone_v3("line", v3.ZoneType.LINE_GUIDED))
    robot.vehicle.handle_zone_set(f"{PREFIX}/zoneSet", encode(message))
    [error] = robot.state()["errors"]
    assert (error["errorType"], error["errorLevel"]) == ("UNSUPPORTED_PARAMETER", "CRITICAL")
    references = {r["referenceKey"]: r["referenceValue"] for r in error["errorReferences"]}
    assert references | {"zoneSetId": "zones-1", "zoneId": "line"} == references
    assert references["zoneType"] == "LINE_GUIDED"
    bad = json.loads(encode(message))
    bad["zoneSet"]["zones"][0]["vertices"] = bad["zoneSet"]["zones"][0]["vertices"][:2]
    robot.vehicle.handle_zone_set(f"{PREFIX}/zoneSet", json.dumps(bad).encode())
    assert robot.errors()[-1] == ("VALIDATION_FAILURE", "WARNING")
    assert robot.state()["zoneSets"] == []


SQUARE = ((2.0, -1.0), (4.0, -1.0), (4.0, 1.0), (2.0, 1.0))  # across the x axis at x 2..4


def send_zone_set(robot: Robot, *zones: v3.Zone, zone_set_id: str = "zones-1") -> None:
    message = make_zone_set_v3(*zones, zone_set_id=zone_set_id)
    robot.vehicle.handle_zone_set(f"{PREFIX}/zoneSet", encode(message))


def zone_set_statuses(robot: Robot) -> dict[str, str]:
    return {z["zoneSetId"]: z["zoneSetStatus"] for z in robot.state()["zoneSets"]}


@needs_official_schemas
def test_zone_sets_are_stored_disabled_enabled_and_deleted() -> None:
    """T87: a new zone set is held DISABLED; the same zoneSetId again is DUPLICATE_ZONE_SET;
    enableZoneSet enables it and disables the other set of its map; deleteZoneSet removes one;
    enabling a set not held FAILS."""
    robot = Robot()
    blocked = make_zone_v3("b", v3.ZoneType.BLOCKED, SQUARE)
    send_zone_set(robot, blocked, zone_set_id="first")
    assert zone_set_statuses(robot) == {"first": "DISABLED"}
    send_zone_set(robot, blocked, zone_set_id="first")
    assert robot.errors() == [("DUPLICATE_ZONE_SET", "WARNING")]
    send_zone_set(robot, blocked, zone_set_id="second")
    robot.instant(make_instant_action_v3("enableZoneSet", "e-1", zoneSetId="first"))
    assert zone_set_statuses(robot) == {"first": "ENABLED", "second": "DISABLED"}
    robot.instant(make_instant_action_v3("enableZoneSet", "e-2", zoneSetId="second"))
    assert zone_set_statuses(robot) == {"first": "DISABLED", "second": "ENABLED"}
    robot.instant(make_instant_action_v3("deleteZoneSet", "d-1", zoneSetId="first"))
    robot.instant(make_instant_action_v3("enableZoneSet", "e-3", zoneSetId="nothing"))
    state = robot.state()
    assert zone_set_statuses(robot) == {"second": "ENABLED"}
    assert statuses(state["instantActionStates"]) == {
        "e-1": "FINISHED",
        "e-2": "FINISHED",
        "d-1": "FINISHED",
        "e-3": "FAILED",
    }
    assert schema_problems(robot.sent) == []


def test_enabled_blocked_zone_is_never_entered() -> None:
    """T89: an order through an enabled BLOCKED zone is refused (NO_ROUTE_TO_TARGET, naming the
    zone); a DISABLED zone set does not count."""
    robot = Robot()
    send_zone_set(robot, make_zone_v3("wall", v3.ZoneType.BLOCKED, SQUARE))
    robot.order(make_order_v3(["a", "b"], positions=line(0, 6)))
    assert robot.state()["orderId"] == "order-1"  # the zone set is still DISABLED
    robot.run(6.0)
    robot.instant(make_instant_action_v3("enableZoneSet", "e-1", zoneSetId="zones-1"))
    robot.order(make_order_v3(["b", "a"], order_id="order-2", positions=line(6, 0)))
    state = robot.state()
    assert state["orderId"] == "order-1"
    [error] = state["errors"]
    assert error["errorType"] == "NO_ROUTE_TO_TARGET"
    assert {"referenceKey": "zoneId", "referenceValue": "wall"} in error["errorReferences"]


def test_a_robot_inside_a_blocked_zone_may_drive_out_but_not_through() -> None:
    """T89: BLOCKED means not entered. A robot standing in a zone enabled around it takes an
    order whose first edge leaves the zone, and drives it; an order that crosses the zone from
    outside to outside is refused."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3)))
    robot.run(3.0)
    send_zone_set(robot, make_zone_v3("wall", v3.ZoneType.BLOCKED, SQUARE))
    robot.instant(make_instant_action_v3("enableZoneSet", "e-1", zoneSetId="zones-1"))
    out = make_order_v3(["b", "c"], order_id="order-2", positions=line(3, 8))
    robot.order(out)
    assert robot.state()["orderId"] == "order-2"
    robot.run(4.0)
    assert robot.state()["lastNodeId"] == "c"
    through = make_order_v3(["c", "d"], order_id="order-3", positions=[(8.0, 0.0), (1.0, 0.0)])
    robot.order(through)
    state = robot.state()
    assert state["orderId"] == "order-2"
    assert [e["errorType"] for e in state["errors"]] == ["NO_ROUTE_TO_TARGET"]


def _curved(order: v3.Order, via: Point) -> v3.Order:
    """``order``'s one edge bent through ``via`` (a degree 2 NURBS, 3.0's default knots)."""
    start, end = (n.node_position for n in order.nodes)
    assert start is not None
    assert end is not None
    trajectory = v3.Trajectory(
        degree=2,
        control_points=[
            v3.ControlPoint(x=start.x, y=start.y),
            v3.ControlPoint(x=via[0], y=via[1]),
            v3.ControlPoint(x=end.x, y=end.y),
        ],
    )
    (edge,) = order.edges
    return order.model_copy(update={"edges": [edge.model_copy(update={"trajectory": trajectory})]})


def test_a_blocked_zone_is_judged_along_the_curve_not_the_chord() -> None:
    """T89 with trajectories: a curve round the zone is driven although its chord crosses it;
    a curve into the zone is refused although its chord passes by."""
    robot = Robot()
    send_zone_set(robot, make_zone_v3("wall", v3.ZoneType.BLOCKED, SQUARE))
    robot.instant(make_instant_action_v3("enableZoneSet", "e-1", zoneSetId="zones-1"))
    around = _curved(make_order_v3(["a", "b"], positions=line(0, 6)), via=(3.0, 5.0))
    robot.order(around)
    assert robot.state()["orderId"] == "order-1"
    robot.run(12.0)
    assert robot.state()["lastNodeId"] == "b"
    into = _curved(
        make_order_v3(["b", "c"], order_id="order-2", positions=[(6.0, 0.0), (0.0, 4.0)]),
        via=(3.0, -4.0),
    )
    robot.order(into)
    state = robot.state()
    assert state["orderId"] == "order-1"
    [error] = state["errors"]
    assert error["errorType"] == "NO_ROUTE_TO_TARGET"
    assert {"referenceKey": "zoneId", "referenceValue": "wall"} in error["errorReferences"]


def top_speed(robot: Robot, seconds: float) -> float:
    fastest = 0.0
    for _ in range(round(seconds / 0.2)):
        robot.run(0.2)
        fastest = max(fastest, abs(robot.vehicle.state.motion.vx))
    return fastest


@needs_official_schemas
def test_a_blocked_zone_enabled_ahead_of_a_running_order_is_not_entered() -> None:
    """T89: a zone set enabled while the robot drives a -> b -> c, with a BLOCKED zone across
    b -> c: the robot stops at b, never inside the zone, and reports c unreachable
    (NODE_UNREACHABLE, CRITICAL, naming the node and the zone; the official schema takes the
    state). The zone set deleted, it drives on to c; the error stays until a new order."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b", "c"], positions=line(0, 1.5, 6)))
    robot.run(0.5)
    send_zone_set(robot, make_zone_v3("wall", v3.ZoneType.BLOCKED, SQUARE))
    robot.instant(make_instant_action_v3("enableZoneSet", "e-1", zoneSetId="zones-1"))
    farthest = 0.0
    for _ in range(40):
        robot.run(0.25)
        farthest = max(farthest, robot.vehicle.state.pose.x)
    assert farthest <= 1.5 + 1e-6  # stopped at b, short of the zone (x 2..4)
    state = robot.state()
    assert (state["lastNodeId"], state["driving"]) == ("b", False)
    assert schema_problems(robot.sent) == []
    [error] = [e for e in state["errors"] if e["errorType"] == "NODE_UNREACHABLE"]
    assert error["errorLevel"] == "CRITICAL"
    references = {r["referenceKey"]: r["referenceValue"] for r in error["errorReferences"]}
    assert (references["nodeId"], references["zoneId"]) == ("c", "wall")

    robot.instant(make_instant_action_v3("deleteZoneSet", "d-1", zoneSetId="zones-1"))
    robot.run(6.0)
    assert robot.state()["lastNodeId"] == "c"
    assert [e["errorType"] for e in robot.state()["errors"]] == ["NODE_UNREACHABLE"]
    robot.order(make_order_v3(["c", "d"], order_id="order-2", positions=line(6, 7)))
    assert robot.state()["errors"] == []


def test_an_edge_into_a_blocked_zone_is_not_entered_and_its_actions_wait() -> None:
    """T89, §6.10.2 step 5: stopped at b before a BLOCKED zone across b -> c, the robot has not
    entered that edge, so the edge's action stays WAITING; the zone set deleted, the robot
    enters the edge and the action runs."""
    robot = Robot()
    order = make_order_v3(
        ["a", "b", "c"],
        positions=line(0, 1.5, 6),
        edge_actions={1: [make_action_v3("detectObject", "look-1", objectType="pallet")]},
    )
    robot.order(order)
    robot.run(0.5)
    send_zone_set(robot, make_zone_v3("wall", v3.ZoneType.BLOCKED, SQUARE))
    robot.instant(make_instant_action_v3("enableZoneSet", "e-1", zoneSetId="zones-1"))
    robot.run(8.0)
    state = robot.state()
    assert (state["lastNodeId"], state["driving"]) == ("b", False)
    assert statuses(state["actionStates"])["look-1"] == "WAITING"
    robot.instant(make_instant_action_v3("deleteZoneSet", "d-1", zoneSetId="zones-1"))
    robot.run(0.2)
    assert statuses(robot.state()["actionStates"])["look-1"] in ("RUNNING", "FINISHED")


def test_speed_limit_zone_caps_the_edges_that_touch_it() -> None:
    """T89: an edge touching an enabled SPEED_LIMIT zone is driven at most at the zone's
    maximumSpeed, overlapping limits take the lowest; edges away from it keep full speed. A
    zone set enabled during an order limits the edges still ahead."""
    robot = Robot()
    send_zone_set(
        robot,
        make_zone_v3("slow", v3.ZoneType.SPEED_LIMIT, SQUARE, maximum_speed=0.5),
        make_zone_v3("slower", v3.ZoneType.SPEED_LIMIT, SQUARE, maximum_speed=0.3),
    )
    robot.instant(make_instant_action_v3("enableZoneSet", "e-1", zoneSetId="zones-1"))
    robot.order(make_order_v3(["a", "b", "c"], positions=[(0.0, 0.0), (0.0, 4.0), (3.0, 0.0)]))
    assert top_speed(robot, 2.0) > 1.0  # a → b runs west of the zone
    while robot.vehicle.state.last_node_id != "b":
        robot.run(0.2)
    assert top_speed(robot, 6.0) <= 0.3 + 1e-9  # b → c ends inside it

    robot = Robot()
    robot.order(make_order_v3(["a", "b"], positions=line(0, 20)))
    robot.run(1.0)
    send_zone_set(robot, make_zone_v3("slow", v3.ZoneType.SPEED_LIMIT, SQUARE, maximum_speed=0.4))
    robot.instant(make_instant_action_v3("enableZoneSet", "e-1", zoneSetId="zones-1"))
    assert top_speed(robot, 2.0) <= 0.4 + 1e-9


def test_visualization_names_the_last_state() -> None:
    """T79: a visualization carries the full header and the headerId of the last state."""
    robot = Robot()
    robot.run(1.2)
    last_state = robot.sent.of(Topic.STATE)[-1]["headerId"]
    visualization = robot.sent.of(Topic.VISUALIZATION)[-1]
    assert visualization["referenceStateHeaderId"] == last_state
    assert visualization["version"] == "3.0.0"


@needs_official_schemas
def test_factsheet_in_3_0_shape() -> None:
    """T80-T82: the factsheet lists every action with 3.0 names, scopes, SINGLE where the
    robot may drive, pauseAllowed/cancelAllowed, hibernation (T06), clearInstantActions and
    the zone set actions; supportedZones lists BLOCKED, RELEASE and SPEED_LIMIT; it fits the
    official schema and is sent again on factsheetRequest."""
    robot = Robot()
    factsheet: Json = robot.sent.of(Topic.FACTSHEET)[0]
    actions = {a["actionType"]: a for a in factsheet["protocolFeatures"]["mobileRobotActions"]}
    assert {"cancelOrder", "startPause", "stopPause", "initializePosition"} <= set(actions)
    assert "initPosition" not in actions
    assert {"startHibernation", "stopHibernation", "clearInstantActions"} <= set(actions)
    assert "SINGLE" in actions["pick"]["blockingTypes"]
    assert actions["pick"]["cancelAllowed"] is False
    assert factsheet["typeSpecification"]["supportedZones"] == ["BLOCKED", "RELEASE", "SPEED_LIMIT"]
    assert {"enableZoneSet", "deleteZoneSet"} <= set(actions)
    parameters = {p["parameter"] for p in factsheet["protocolFeatures"]["optionalParameters"]}
    assert "order.edges.maximumSpeed" in parameters
    assert {"order.edges.trajectory", "order.edges.corridor"} <= parameters
    assert "order.edges.direction" not in parameters
    robot.instant(make_instant_action_v3("factsheetRequest", "f-1"))
    robot.run(0.2)
    assert len(robot.sent.of(Topic.FACTSHEET)) == 2
    assert schema_problems(robot.sent) == []


def test_undecodable_order_keeps_the_running_one() -> None:
    """T12, T20: a 2.x payload on a v3 topic is refused (VALIDATION_FAILURE); the order goes
    on."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b"], positions=line(0, 10)))
    legacy = json.loads(encode(make_order_v3(["a"], order_id="x")))
    legacy["version"] = "2.1.0"
    robot.vehicle.handle_order(f"{PREFIX}/order", json.dumps(legacy).encode())
    assert robot.state()["orderId"] == "order-1"
    assert robot.errors() == [("VALIDATION_FAILURE", "WARNING")]


@pytest.mark.parametrize("mode", [RobotMode.AUTOMATIC, RobotMode.SEMIAUTOMATIC])
def test_orders_taken_in_automatic_modes(mode: RobotMode) -> None:
    """T60: orders may be sent in AUTOMATIC and SEMIAUTOMATIC."""
    robot = Robot()
    robot.vehicle.state = replace(robot.vehicle.state, operating_mode=mode)
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3)))
    assert robot.state()["orderId"] == "order-1"


def test_instant_action_states_stay_until_cleared() -> None:
    """T57: ended instant action states survive a new order and go only with
    clearInstantActions, which removes FINISHED/FAILED entries and is itself FINISHED; the
    order's action states are replaced by the new order's."""
    robot = Robot()
    robot.instant(make_instant_action_v3("stateRequest", "s-1"))
    fine = make_action_v3("finePositioning", "fp-1")
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3), node_actions={1: [fine]}))
    robot.run(5.0)
    state = robot.state()
    assert statuses(state["instantActionStates"]) == {"s-1": "FINISHED"}
    robot.order(make_order_v3(["b", "c"], order_id="order-2", positions=line(3, 6)))
    state = robot.state()
    assert statuses(state["instantActionStates"]) == {"s-1": "FINISHED"}
    assert state["actionStates"] == []
    robot.instant(make_instant_action_v3("clearInstantActions", "clear-1"))
    assert statuses(robot.state()["instantActionStates"]) == {"clear-1": "FINISHED"}


def test_order_beyond_the_declared_limits_is_insufficient_memory() -> None:
    """T23: an order larger than the factsheet's protocolLimits is refused with
    INSUFFICIENT_MEMORY, URGENT."""
    robot = Robot()  # the default limits: 1000 nodes
    ids = [f"n{i}" for i in range(1001)]
    robot.order(make_order_v3(ids, positions=[(0.01 * i, 0.0) for i in range(1001)]))
    assert set(robot.errors()) == {("INSUFFICIENT_MEMORY", "URGENT")}  # nodes and edges
    assert robot.state()["orderId"] == ""


def test_fatal_error_blocks_orders() -> None:
    """T38: with a FATAL error active the robot takes no order (MOBILE_ROBOT_NOT_AVAILABLE)."""
    robot = Robot()
    fatal = stored(v3.predefined_error(v3.ErrorType.LOCALIZATION_ERROR))
    robot.vehicle.state = robot.vehicle.state.bumped(errors=(fatal,))
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3)))
    assert ("MOBILE_ROBOT_NOT_AVAILABLE", "WARNING") in robot.errors()
    assert ("LOCALIZATION_ERROR", "FATAL") in robot.errors()
    assert robot.state()["orderId"] == ""


def test_robot_stops_at_the_decision_point_without_an_update() -> None:
    """T43, T28: without a base extension the robot stops at the decision point; with only a
    horizon left it is not idle."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b", "c"], positions=line(0, 3, 6), released=2))
    robot.run(6.0)
    state = robot.state()
    assert (state["lastNodeId"], state["driving"]) == ("b", False)
    assert [n["nodeId"] for n in state["nodeStates"]] == ["c"]
    assert not v3.State.model_validate(state).is_idle()


def test_new_order_after_a_cancel_starts_where_the_robot_stands() -> None:
    """T47: after a cancel a new order starting at the node the robot stands on is taken."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b", "c"], positions=line(0, 3, 6)))
    robot.run(1.0)
    robot.instant(make_instant_action_v3("cancelOrder", "c-1"))
    robot.run(6.0)
    stand = robot.state()["lastNodeId"]
    x = robot.vehicle.state.pose.x
    robot.order(make_order_v3([stand, "d"], order_id="order-2", positions=[(x, 0.0), (x + 3, 0)]))
    assert robot.state()["orderId"] == "order-2"
    assert ("OTHER_ORDER_ACTIVE", "WARNING") not in robot.errors()


def test_pause_stops_driving() -> None:
    """T55, T56: startPause stops automatic driving and sets paused; stopPause resumes."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b"], positions=line(0, 10)))
    robot.run(1.0)
    robot.instant(make_instant_action_v3("startPause", "p-1"))
    robot.run(1.0)
    state = robot.state()
    assert (state["paused"], state["driving"]) == (True, False)
    robot.instant(make_instant_action_v3("stopPause", "p-2"))
    robot.run(1.0)
    state = robot.state()
    assert (state["paused"], state["driving"]) == (False, True)
    assert statuses(state["instantActionStates"]) == {"p-1": "FINISHED", "p-2": "FINISHED"}


def test_node_off_every_map_is_no_route_to_target() -> None:
    """T25: a node far outside the robot's map is refused with NO_ROUTE_TO_TARGET."""
    robot = Robot()
    caps = robot.vehicle._caps
    extents = {"map": MapExtent(-5.0, -5.0, 5.0, 5.0)}
    robot.vehicle._caps = replace(caps, map_extents=extents)
    robot.order(make_order_v3(["a", "b"], positions=[(0.0, 0.0), (900.0, 0.0)]))
    assert robot.errors() == [("NO_ROUTE_TO_TARGET", "WARNING")]


def last_sent(robot: Robot, kind: Topic) -> Json:
    message: Json = robot.sent.of(kind)[-1]
    return message


def connection_states(robot: Robot) -> list[str]:
    return [str(c["connectionState"]) for c in robot.sent.of(Topic.CONNECTION)]


@needs_official_schemas
def test_hibernation_while_idle() -> None:
    """T06: startHibernation is FINISHED in a last state, then HIBERNATING: no states, no
    visualization, orders and other instant actions are not answered; stopHibernation brings
    ONLINE and a state with it FINISHED. Every message fits the official schemas."""
    robot = Robot()
    robot.instant(make_instant_action_v3("startHibernation", "h-1"))
    robot.run(0.4)
    assert statuses(last_sent(robot, Topic.STATE)["instantActionStates"]) == {"h-1": "FINISHED"}
    assert connection_states(robot)[-1] == "HIBERNATING"
    sent_before = len(robot.sent.sent)
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3)))
    robot.instant(make_instant_action_v3("stateRequest", "s-1"))
    robot.run(40.0)  # past the heartbeat interval: still silent
    assert len(robot.sent.sent) == sent_before
    assert robot.vehicle.state.order_id == ""
    robot.instant(make_instant_action_v3("stopHibernation", "h-2"))
    robot.run(1.2)
    assert connection_states(robot)[-1] == "ONLINE"
    state = robot.state()
    assert statuses(state["instantActionStates"]) == {"h-1": "FINISHED", "h-2": "FINISHED"}
    assert last_sent(robot, Topic.VISUALIZATION)["referenceStateHeaderId"] >= 0
    assert schema_problems(robot.sent) == []


def test_hibernation_clears_the_order_first() -> None:
    """T06, T61: startHibernation on the move clears the order like a cancel (stop on the next
    node, nodeStates empty, orderId kept) and only then goes HIBERNATING."""
    robot = Robot()
    robot.order(make_order_v3(["a", "b", "c"], positions=line(0, 3, 6)))
    robot.run(1.0)
    robot.instant(make_instant_action_v3("startHibernation", "h-1"))
    assert connection_states(robot)[-1] == "ONLINE"
    robot.run(6.0)
    assert connection_states(robot)[-1] == "HIBERNATING"
    last = last_sent(robot, Topic.STATE)
    assert (last["nodeStates"], last["orderId"], last["driving"]) == ([], "order-1", False)
    assert statuses(last["instantActionStates"]) == {"h-1": "FINISHED"}


@needs_official_schemas
def test_hibernation_ends_by_itself_at_the_wake_up_time() -> None:
    """T06: startHibernation with a wakeUpTime 30 s ahead: HIBERNATING and silent until then,
    then ONLINE and states again without a stopHibernation (the wall clock decides). The
    factsheet declares the optional parameter; every message fits the official schemas."""
    robot = Robot()
    wake = (robot.clock.now() + timedelta(seconds=30)).isoformat().replace("+00:00", "Z")
    robot.instant(make_instant_action_v3("startHibernation", "h-1", wakeUpTime=wake))
    robot.run(0.4)
    assert connection_states(robot)[-1] == "HIBERNATING"
    states_before = len(robot.sent.of(Topic.STATE))
    robot.run(29.0)
    assert connection_states(robot)[-1] == "HIBERNATING"
    assert len(robot.sent.of(Topic.STATE)) == states_before
    robot.run(1.2)
    assert connection_states(robot)[-1] == "ONLINE"
    assert len(robot.sent.of(Topic.STATE)) > states_before
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3)))
    assert robot.state()["orderId"] == "order-1"  # it answers orders again
    [hibernation] = [
        a
        for a in last_sent(robot, Topic.FACTSHEET)["protocolFeatures"]["mobileRobotActions"]
        if a["actionType"] == "startHibernation"
    ]
    assert [(p["key"], p.get("isOptional")) for p in hibernation["actionParameters"]] == [
        ("wakeUpTime", True)
    ]
    assert schema_problems(robot.sent) == []


def test_a_bad_wake_up_time_and_stop_while_awake_fail() -> None:
    """T06: a wakeUpTime that is no date-time with its offset is INVALID_INSTANT_ACTION and the
    vehicle stays awake; stopHibernation while awake fails likewise."""
    robot = Robot()
    robot.instant(
        make_instant_action_v3("startHibernation", "h-1", wakeUpTime="tomorrow at nine"),
        make_instant_action_v3("stopHibernation", "h-2"),
    )
    state = robot.state()
    assert statuses(state["instantActionStates"]) == {"h-1": "FAILED", "h-2": "FAILED"}
    assert robot.errors() == [("INVALID_INSTANT_ACTION", "WARNING")] * 2
    assert connection_states(robot)[-1] == "ONLINE"
    robot.instant(make_instant_action_v3("startHibernation", "h-3", wakeUpTime="2026-01-01T09:00"))
    assert statuses(robot.state()["instantActionStates"])["h-3"] == "FAILED"  # no offset


def test_impossible_speed_is_a_validation_failure() -> None:
    """T20: a non-positive maximumSpeed is a VALIDATION_FAILURE, not a routing problem."""
    robot = Robot()
    order = make_order_v3(["a", "b"], positions=line(0, 3))
    edge = order.edges[0].model_copy(update={"maximum_speed": 0.0})
    robot.order(order.model_copy(update={"edges": [edge]}))
    assert robot.errors() == [("VALIDATION_FAILURE", "WARNING")]


@pytest.mark.parametrize(
    ("start", "end", "expected"),
    [
        ((0.0, 0.0), (6.0, 0.0), True),  # crosses
        ((2.5, 0.0), (3.5, 0.5), True),  # inside
        ((0.0, 0.0), (2.0, 0.0), True),  # ends on the border
        ((0.0, 2.0), (6.0, 2.0), False),  # passes north
        ((0.0, 0.0), (1.9, 0.0), False),  # stops short
    ],
)
def test_segment_touches_zone(start: Point, end: Point, *, expected: bool) -> None:
    """The geometry behind T89: an edge touches a zone when it enters or crosses it."""
    corners = [Vertex(x=x, y=y) for x, y in SQUARE]
    assert touches(corners, start, end) is expected


@needs_official_schemas
def test_retriable_action_waits_for_retry_or_skip() -> None:
    """T52, T53, T51: a failing action with ``retriable: true`` goes RETRIABLE (not an end: the
    robot is not idle, a HARD one holds it); ``retry`` runs it again (FINISHED once it can
    succeed), ``skipRetry`` ends it FAILED; a retry naming an action that is not RETRIABLE
    fails; without the flag a failure is FAILED at once."""
    robot = Robot(action_durations_s={"drop": 0.0})
    drop = make_action_v3("drop", "drop-1", v3.BlockingType.HARD, retriable=True)
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3), node_actions={1: [drop]}))
    robot.run(5.0)
    state = robot.state()
    assert statuses(state["actionStates"]) == {"drop-1": "RETRIABLE"}
    assert not v3.State.model_validate(state).is_idle()
    robot.instant(make_instant_action_v3("retry", "r-1", actionId="drop-1"))
    robot.run(2.0)
    assert statuses(robot.state()["actionStates"]) == {"drop-1": "RETRIABLE"}  # still no load
    load = Load(load_id="L1", load_type="EPAL", load_position="front")
    robot.vehicle.state = robot.vehicle.state.bumped(loads=(load,))
    robot.instant(make_instant_action_v3("retry", "r-2", actionId="drop-1"))
    robot.run(2.0)
    state = robot.state()
    assert statuses(state["actionStates"]) == {"drop-1": "FINISHED"}
    assert state["loads"] == []
    robot.instant(make_instant_action_v3("skipRetry", "s-1", actionId="drop-1"))
    state = robot.state()
    assert statuses(state["instantActionStates"]) == {
        "r-1": "FINISHED",
        "r-2": "FINISHED",
        "s-1": "FAILED",
    }
    assert schema_problems(robot.sent) == []

    robot = Robot(action_durations_s={"drop": 0.0})
    drop = make_action_v3("drop", "drop-2", v3.BlockingType.HARD, retriable=True)
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3), node_actions={1: [drop]}))
    robot.run(5.0)
    robot.instant(make_instant_action_v3("skipRetry", "s-2", actionId="drop-2"))
    robot.run(0.4)
    state = robot.state()
    assert statuses(state["actionStates"]) == {"drop-2": "FAILED"}
    assert v3.State.model_validate(state).is_idle()

    robot = Robot(action_durations_s={"drop": 0.0})
    drop = make_action_v3("drop", "drop-3", v3.BlockingType.HARD)
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3), node_actions={1: [drop]}))
    robot.run(5.0)
    assert statuses(robot.state()["actionStates"]) == {"drop-3": "FAILED"}


def test_cancel_ends_a_retriable_action_failed() -> None:
    """T53: cancelOrder ends a RETRIABLE action FAILED, even a non-interruptible one."""
    robot = Robot(action_durations_s={"drop": 0.0})
    drop = make_action_v3("drop", "drop-1", v3.BlockingType.HARD, retriable=True)
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3), node_actions={1: [drop]}))
    robot.run(5.0)
    robot.instant(make_instant_action_v3("cancelOrder", "c-1"))
    robot.run(0.4)
    state = robot.state()
    assert statuses(state["actionStates"]) == {"drop-1": "FAILED"}
    assert statuses(state["instantActionStates"]) == {"c-1": "FINISHED"}


@needs_official_schemas
def test_shutdown_only_while_idle_then_offline_and_silent() -> None:
    """T07: shutdown while an order runs is FAILED (the robot is not idle); while idle it is
    FINISHED in a state, then the shell is told to disconnect (it publishes OFFLINE), and the
    vehicle sends nothing more. The factsheet offers it; every message fits the schemas."""
    robot = Robot()
    shut: list[bool] = []
    robot.vehicle.on_shutdown(lambda: shut.append(True))
    robot.order(make_order_v3(["a", "b"], positions=line(0, 3)))
    robot.instant(make_instant_action_v3("shutdown", "s-1"))
    state = robot.state()
    assert statuses(state["instantActionStates"]) == {"s-1": "FAILED"}
    [failed] = state["instantActionStates"]
    assert failed["actionResult"].startswith("the robot is not idle")
    robot.run(3.0)
    assert robot.state()["nodeStates"] == []
    robot.instant(make_instant_action_v3("shutdown", "s-2"))
    robot.run(0.4)
    assert statuses(last_sent(robot, Topic.STATE)["instantActionStates"])["s-2"] == "FINISHED"
    assert shut == [True]
    assert robot.vehicle.shut_down
    sent = len(robot.sent.sent)
    robot.run(40.0)  # past the heartbeat and many visualizations
    assert len(robot.sent.sent) == sent
    actions = last_sent(robot, Topic.FACTSHEET)["protocolFeatures"]["mobileRobotActions"]
    assert "shutdown" in [a["actionType"] for a in actions]
    assert schema_problems(robot.sent) == []
