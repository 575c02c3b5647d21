"""Master control serving VDA 5050 3.0 vehicles without a broker (issue 13 item 3): a recording
publisher and a fake clock drive the service; every message it sends to a 3.0 vehicle fits the
official 3.0.0 schema. Rule ids (Tnn) are those of docs/vda5050-3.md."""

from __future__ import annotations

import functools
import json
from dataclasses import replace
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator, FormatChecker
from structlog.testing import capture_logs

from tests.spec_files import needs_official_schemas, official_schema, v3_example_files
from tests.unit.master.orders import stored
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import (
    Action,
    BlockingType,
    ConnectionState,
    ErrorLevel,
    NodePosition,
    OperatingMode,
    v3,
)
from vda5050.testing import (
    make_connection_v3,
    make_factsheet_v3,
    make_state_v3,
)
from vda5050.topics import AgvId, Topic, build_topic
from vda5050.validation3 import check_order
from vda_master.api_documents import vehicle_document
from vda_master.capabilities import ActionSpec
from vda_master.config import MasterConfig
from vda_master.dispatcher import extend_track
from vda_master.fleet import VehicleView
from vda_master.live import parse_pose
from vda_master.order_records import from_record
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.testing import RecordingPublisher, demo_graph
from vda_master.web.payloads import vehicle_payload
from vda_master.wire3 import (
    connection_from_v3,
    factsheet_from_v3,
    order_to_v3,
    state_from_v3,
)

AGV = AgvId("acme", "robot_0")
INTERFACE_V3 = "vda5050"


def topic(kind: Topic) -> str:
    return build_topic(INTERFACE_V3, 3, AGV, kind)


def service_with_v3_vehicle(**config: object) -> tuple[MasterService, RecordingPublisher]:
    publisher = RecordingPublisher()
    settings = MasterConfig.model_validate({"confirm_timeout_s": 1.0, **config})
    service = MasterService(settings, demo_graph(), publisher, FakeClock())
    service.ingest(topic(Topic.CONNECTION), encode(make_connection_v3()))
    factsheet = make_factsheet_v3(optional_parameters=["order.edges.maximumSpeed"])
    service.ingest(topic(Topic.FACTSHEET), encode(factsheet))
    service.ingest(topic(Topic.STATE), encode(make_state_v3(last_node_id="7")))
    return service, publisher


def _panel(service: MasterService, view: VehicleView) -> dict[str, object]:
    """What the live map's vehicle panel gets of ``view``."""
    return vehicle_payload(
        view,
        pose=None,
        received=None,
        active_order=None,
        settings=service.fleet_settings,
        now=0.0,
        wall_now=0.0,
    )


@functools.cache
def official(kind: str) -> Draft202012Validator:
    return Draft202012Validator(official_schema("3.0.0", kind), format_checker=FormatChecker())


def test_subscribes_to_both_majors_under_their_interface_names() -> None:
    """T01, T02: the master reads vehicles under ``uagv/v2`` and ``vda5050/v3`` (configurable
    per major)."""
    service, _ = service_with_v3_vehicle(interface_name_v3="plant3")
    filters = {f for f, _ in service.subscriptions()}
    assert "uagv/v2/+/+/state" in filters
    assert "plant3/v3/+/+/state" in filters
    assert "plant3/v3/+/+/connection" in filters


@needs_official_schemas
def test_order_goes_to_the_v3_topic_in_3_0_shape() -> None:
    """T01, T10, T18, T100: an order for a 3.0 vehicle is published under ``vda5050/v3`` with a
    3.0 header, edges without start/end node ids, and passes the official 3.0.0 schema."""
    service, publisher = service_with_v3_vehicle()
    service.create_order(OrderRequest(Target(destination="10"), AGV))
    [(sent_topic, _)] = publisher.sent
    assert sent_topic == topic(Topic.ORDER)
    [order] = publisher.orders()
    assert (order["version"], order["headerId"]) == ("3.0.0", 0)
    assert all("startNodeId" not in edge for edge in order["edges"])
    assert list(official("order").iter_errors(order)) == []
    assert service.fleet.get(AGV).version == "3.0.0"  # type: ignore[union-attr]


@needs_official_schemas
def test_cancel_is_a_3_0_instant_action() -> None:
    """T44, T49: cancelOrder goes to a 3.0 vehicle with blockingType NONE and fits the schema."""
    service, publisher = service_with_v3_vehicle()
    track = service.create_order(OrderRequest(Target(destination="10"), AGV))
    service.cancel_order(track.order_id)
    [message] = publisher.messages(Topic.INSTANT_ACTIONS)
    [action] = message["actions"]
    assert (action["actionType"], action["blockingType"]) == ("cancelOrder", "NONE")
    assert list(official("instantActions").iter_errors(message)) == []


def test_a_cancel_goes_to_an_intervened_robot_and_nothing_else_does() -> None:
    """3.0 Table 11, T58: while an operator steers (INTERVENED, read as MANUAL) the robot keeps
    its order; of the instant actions only cancelOrder may go, and it does (DELETE /orders).
    Other instant actions are refused naming the mode; a 2.x MANUAL vehicle gets no cancel."""
    service, publisher = service_with_v3_vehicle()
    track = service.create_order(OrderRequest(Target(destination="10"), AGV))
    order = publisher.orders()[-1]
    intervened = make_state_v3(
        last_node_id="7",
        order_id=track.order_id,
        order_update_id=0,
        operating_mode=v3.OperatingMode.INTERVENED,
        node_states=[
            {"nodeId": n["nodeId"], "sequenceId": n["sequenceId"], "released": n["released"]}
            for n in order["nodes"][1:]
        ],
        edge_states=[
            {"edgeId": e["edgeId"], "sequenceId": e["sequenceId"], "released": e["released"]}
            for e in order["edges"]
        ],
    )
    service.ingest(topic(Topic.STATE), encode(intervened))
    view = service.fleet.get(AGV)
    assert view is not None
    assert view.intervened
    assert service.tracks[track.order_id].status.value == "RUNNING"
    with pytest.raises(RequestError, match="operatingMode is INTERVENED"):
        service.send_instant_actions(AGV, [ActionSpec("startPause")])
    service.cancel_order(track.order_id)
    [message] = publisher.messages(Topic.INSTANT_ACTIONS)
    assert [a["actionType"] for a in message["actions"]] == ["cancelOrder"]

    back = intervened.model_copy(update={"operating_mode": v3.OperatingMode.AUTOMATIC})
    service.ingest(topic(Topic.STATE), encode(back))
    view = service.fleet.get(AGV)
    assert view is not None
    assert not view.intervened


@pytest.mark.parametrize(
    ("mode", "read_as"),
    [
        ("STARTUP", "SERVICE"),
        ("INTERVENED", "MANUAL"),
        ("TEACH_IN", "TEACHIN"),
        ("AUTOMATIC", None),
    ],
)
def test_the_api_and_the_map_show_a_3_0_robots_own_mode(mode: str, read_as: str | None) -> None:
    """operatingMode reads every vehicle in 2.x terms (what master control judges by);
    reportedOperatingMode, the map's details and a refusal use the robot's own word."""
    service, _ = service_with_v3_vehicle()
    state = make_state_v3(last_node_id="7", operating_mode=v3.OperatingMode(mode))
    service.ingest(topic(Topic.STATE), encode(state))
    view = service.fleet.get(AGV)
    assert view is not None
    document = vehicle_document(service, view)
    assert document["operatingMode"] == (read_as or mode)
    assert document["reportedOperatingMode"] == mode
    payload = _panel(service, view)
    assert payload["reportedOperatingMode"] == mode
    if read_as is not None:
        with pytest.raises(RequestError, match=f"operatingMode is {mode}"):
            service.create_order(OrderRequest(Target(destination="10"), AGV))


def test_3_0_state_is_understood() -> None:
    """T28, T70, T76, T77: instant action states join the action states; CRITICAL is not FATAL
    (the robot still takes new orders) but keeps its level in the description; FATAL stays
    FATAL; RETRIABLE is not an end state; powerSupply and mobileRobotPosition are read."""
    state = make_state_v3(
        last_node_id="7",
        action_states=[
            v3.ActionState(action_id="a", action_status=v3.ActionStatus.RETRIABLE),
        ],
        instant_action_states=[
            v3.ActionState(
                action_id="i",
                action_type="initializePosition",
                action_status=v3.ActionStatus.FINISHED,
            )
        ],
        errors=[
            v3.predefined_error(v3.ErrorType.NODE_UNREACHABLE, description="blocked"),
            v3.predefined_error(v3.ErrorType.LOCALIZATION_ERROR),
        ],
        mobile_robot_position=v3.MobileRobotPosition(
            x=1.0, y=2.0, theta=0.0, map_id="demo", localized=False
        ),
    )
    core = state_from_v3(state)
    assert [(a.action_id, a.action_status.value, a.action_type) for a in core.action_states] == [
        ("a", "RUNNING", None),
        ("i", "FINISHED", "initPosition"),
    ]
    critical, fatal = core.errors
    assert (critical.error_type, critical.error_level) == ("NODE_UNREACHABLE", ErrorLevel.WARNING)
    assert critical.error_description == "CRITICAL: blocked"
    assert fatal.error_level is ErrorLevel.FATAL
    assert core.agv_position is not None
    assert core.agv_position.position_initialized is False
    assert core.battery_state.battery_charge == 80.0


def test_operating_modes_and_connection_states() -> None:
    """T60, T65, T09: STARTUP (state not valid) and INTERVENED (only cancelOrder) are modes the
    master does not drive in; HIBERNATING is not dispatchable (no heartbeat expected);
    CONNECTION_BROKEN is the broken connection."""
    modes = {
        mode: state_from_v3(make_state_v3(operating_mode=mode)).operating_mode
        for mode in v3.OperatingMode
    }
    assert modes[v3.OperatingMode.STARTUP] is OperatingMode.SERVICE
    assert modes[v3.OperatingMode.INTERVENED] is OperatingMode.MANUAL
    assert modes[v3.OperatingMode.TEACH_IN] is OperatingMode.TEACHIN
    assert modes[v3.OperatingMode.AUTOMATIC] is OperatingMode.AUTOMATIC
    states = {
        s: connection_from_v3(make_connection_v3(s)).connection_state for s in v3.ConnectionState
    }
    assert states[v3.ConnectionState.HIBERNATING] is ConnectionState.OFFLINE
    assert states[v3.ConnectionState.CONNECTION_BROKEN] is ConnectionState.CONNECTIONBROKEN


def test_vehicle_in_startup_is_not_available() -> None:
    """T65: in STARTUP fleet control does not act: the vehicle is not available for orders."""
    service, _ = service_with_v3_vehicle()
    starting = make_state_v3(last_node_id="7", operating_mode=v3.OperatingMode.STARTUP)
    service.ingest(topic(Topic.STATE), encode(starting))
    assert service.availability_of(AGV) is not None


def test_factsheet_fields_under_2x_paths() -> None:
    """T83: the 3.0 factsheet's optional fields are read under the names the order builder
    asks about, actions under their 2.x names; SINGLE and ZONE are left aside."""
    single = v3.MobileRobotAction(
        action_type="initializePosition",
        action_scopes=[v3.ActionScope.INSTANT, v3.ActionScope.ZONE],
        blocking_types=[v3.BlockingType.NONE, v3.BlockingType.SINGLE],
        pause_allowed=False,
        cancel_allowed=False,
    )
    factsheet = make_factsheet_v3(
        actions=[single],
        optional_parameters=["order.edges.maximumSpeed", "order.nodes.nodePosition"],
    )
    core = factsheet_from_v3(factsheet)
    parameters = {p.parameter for p in core.protocol_features.optional_parameters}
    assert parameters == {"order.edges.maxSpeed", "order.nodes.nodePosition"}
    action = core.action("initPosition")
    assert action is not None
    assert [s.value for s in action.action_scopes] == ["INSTANT"]
    assert [b.value for b in action.blocking_types or ()] == ["NONE"]
    assert core.physical_parameters.speed_max == 2.0


def test_order_translation_keeps_the_plan() -> None:
    """T99, T100: a circular deviation becomes an ellipse a = b; maxSpeed is maximumSpeed;
    actions keep their blocking type; the 2.x-only fields have no 3.0 place."""
    service, _ = service_with_v3_vehicle()
    service.create_order(OrderRequest(Target(destination="10"), AGV))
    core = next(iter(service.sent.values()))
    pick = Action(action_type="pick", action_id="p", blocking_type=BlockingType.HARD)
    first = core.nodes[0].model_copy(
        update={
            "node_position": NodePosition(x=1.0, y=2.0, map_id="demo", allowed_deviation_xy=0.5),
            "actions": [pick],
        }
    )
    edge = core.edges[0].model_copy(update={"max_speed": 0.7})
    wire = order_to_v3(core.model_copy(update={"nodes": [first, *core.nodes[1:]], "edges": [edge]}))
    position = wire.nodes[0].node_position
    assert position is not None
    assert position.allowed_deviation_xy == v3.AllowedDeviationXY(a=0.5, b=0.5, theta=0.0)
    assert wire.nodes[0].actions[0].blocking_type is v3.BlockingType.HARD
    assert wire.edges[0].maximum_speed == 0.7
    assert "startNodeId" not in encode(wire).decode()


def test_3_0_plan_round_trips_through_the_store() -> None:
    """T39, T40: a 3.0 vehicle's order survives the store: the plan comes back with its
    version, and an update cut from it after a restart starts at the decision point exactly as
    it was sent (the stitching node unchanged) and translates to a valid 3.0 update."""
    service, _ = service_with_v3_vehicle(release_window_nodes=1, traffic_control=False)
    track = service.create_order(OrderRequest(Target(destination="18"), AGV))
    assert track.plan.version == "3.0.0"
    extended = extend_track(replace(track, confirmed_update_id=0, pending=None), 2)
    back = from_record(stored(extended), now=1.0)
    assert back.plan.version == "3.0.0"
    assert back.message == extended.message
    first = order_to_v3(track.message)
    update = order_to_v3(back.message)
    decision = [n for n in first.nodes if n.released][-1]
    assert update.nodes[0] == decision
    assert check_order(update, first_sequence_id=decision.sequence_id) == []


def test_hibernating_vehicle_takes_only_stop_hibernation() -> None:
    """T06, T09: a HIBERNATING vehicle is shown as hibernating, is not available, gets no
    instant action but stopHibernation (sent in 3.0 shape), and is ready again once ONLINE."""
    service, publisher = service_with_v3_vehicle()
    stop = v3.MobileRobotAction(
        action_type="stopHibernation",
        action_scopes=[v3.ActionScope.INSTANT],
        blocking_types=[v3.BlockingType.NONE],
        pause_allowed=False,
        cancel_allowed=False,
    )
    service.ingest(topic(Topic.FACTSHEET), encode(make_factsheet_v3(actions=[stop])))
    hibernating = make_connection_v3(v3.ConnectionState.HIBERNATING)
    service.ingest(topic(Topic.CONNECTION), encode(hibernating))
    vehicle = service.fleet.get(AGV)
    assert vehicle is not None
    assert vehicle.hibernating
    assert "HIBERNATING" in (service.availability_of(AGV) or "")
    with pytest.raises(RequestError) as refused:
        service.send_instant_actions(AGV, [ActionSpec("stateRequest")])
    assert refused.value.status == 409
    service.send_instant_actions(AGV, [ActionSpec("stopHibernation")])
    [message] = publisher.messages(Topic.INSTANT_ACTIONS)
    assert message["actions"][0]["actionType"] == "stopHibernation"
    service.ingest(topic(Topic.CONNECTION), encode(make_connection_v3()))
    service.ingest(topic(Topic.STATE), encode(make_state_v3(last_node_id="7")))
    assert service.availability_of(AGV) is None


@pytest.mark.parametrize(
    "path",
    [p for p in v3_example_files() if p.name.split("_")[0] in {"state", "connection", "factsheet"}],
    ids=lambda p: p.name,
)
def test_every_3_0_example_is_read_by_the_master(path: Path) -> None:
    """T16, T76: every valid 3.0 example state, connection and factsheet (loads, requests,
    vendor error types, wheels and envelopes included) is understood through the master's
    edge, and a state example folds into the fleet view."""
    kind = Topic(path.name.split("_")[0].removesuffix(".json"))
    payload = path.read_bytes()
    header = json.loads(payload)
    agv = AgvId(header["manufacturer"], header["serialNumber"])
    service = MasterService(MasterConfig(), demo_graph(), RecordingPublisher(), FakeClock())
    with capture_logs() as logs:
        service.ingest(build_topic(INTERFACE_V3, 3, agv, kind), payload)
    assert [e for e in logs if e["event"] == "message.dropped"] == []
    vehicle = service.fleet.get(agv)
    assert vehicle is not None
    assert vehicle.version == "3.0.0"


def test_live_map_reads_3_0_visualization() -> None:
    """T79: the live map takes the pose of a 3.0 visualization (mobileRobotPosition)."""
    example = next(p for p in v3_example_files() if p.name == "visualization.json")
    pose = parse_pose(example.read_bytes(), 0.0)
    assert not isinstance(pose, str)


def test_the_map_lists_a_3_0_robot_s_errors_with_the_level_it_sent() -> None:
    """T77: the core reads URGENT and CRITICAL as WARNINGs; the vehicle panel shows the robot's
    own level and description."""
    service, _ = service_with_v3_vehicle()
    errors = [
        v3.Error(error_type="NODE_UNREACHABLE", error_level=level, error_description="aisle 4")
        for level in (v3.ErrorLevel.CRITICAL, v3.ErrorLevel.URGENT, v3.ErrorLevel.WARNING)
    ]
    service.ingest(topic(Topic.STATE), encode(make_state_v3(last_node_id="7", errors=errors)))
    view = service.fleet.get(AGV)
    assert view is not None
    payload = _panel(service, view)
    assert payload["errors"] == [
        {"errorType": "NODE_UNREACHABLE", "errorLevel": level, "errorDescription": "aisle 4"}
        for level in ("CRITICAL", "URGENT", "WARNING")
    ]
