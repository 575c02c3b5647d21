"""State, visualization and factsheet built from the vehicle state (§6.10, §6.13, §6.15)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vda5050.codec import EncodedBody, encode
from vda5050.models import (
    Action,
    ActionScope,
    ActionStatus,
    BlockingType,
    Edge,
    Error,
    ErrorLevel,
    EStop,
    Load,
    Map,
    Node,
    OperatingMode,
)
from vda5050.models.common import NodePosition
from vda5050.models.state import ErrorReference
from vda5050.schemas import validator
from vda5050.testing import make_order
from vda_vehicle.factsheet import FactsheetTiming, build_factsheet
from vda_vehicle.maps import initial_maps
from vda_vehicle.model import ActionRecord, HeldMap, Motion, VehicleState
from vda_vehicle.order_executor import apply_order
from vda_vehicle.reporter import (
    build_state,
    build_visualization,
    held_maps,
    state_body,
    visualization_body,
)
from vda_vehicle.testing import action, make_caps, make_vehicle, run

CAPS = make_caps()
TIMING = FactsheetTiming(
    min_state_interval_s=0.2, state_interval_s=30.0, visualization_interval_s=1.0
)
REQUIRED = {
    "orderId", "orderUpdateId", "lastNodeId", "lastNodeSequenceId", "nodeStates", "edgeStates",
    "driving", "actionStates", "batteryState", "operatingMode", "errors", "safetyState",
}  # fmt: skip


def payload(message: object) -> dict[str, object]:
    return json.loads(encode(message))  # type: ignore[arg-type, no-any-return]


@pytest.mark.parametrize("version", ["2.0.0", "2.1.0"])
def test_idle_state_has_every_required_field(version: str) -> None:
    """R95, R96: before any order the state carries every required field with idle values."""
    maps = held_maps(initial_maps(CAPS.map_ids)) if version == "2.1.0" else None
    body = payload(build_state(make_vehicle(), CAPS, maps=maps))
    assert set(body) >= REQUIRED
    assert (body["orderId"], body["orderUpdateId"], body["nodeStates"], body["edgeStates"]) == (
        "",
        0,
        [],
        [],
    )
    assert (body["lastNodeId"], body["lastNodeSequenceId"]) == ("", 0)
    assert list(validator(f"{version}/state.schema.json").iter_errors(body)) == []


@pytest.mark.parametrize("version", ["2.0.0", "2.1.0"])
def test_a_battery_that_does_not_drain_reports_no_reach(version: str) -> None:
    """reach (§6.10.6, optional) is the charge over the drain per metre; with no drain
    (battery_drain_pct_per_m 0, allowed by the config) it is left out instead of dividing by
    zero, in the model and in the fast body alike."""
    caps = make_caps(battery_drain_pct_per_m=0.0)
    state = make_vehicle(battery_charge=42.0)
    body = payload(build_state(state, caps, maps=None))
    assert body["batteryState"] == {"batteryCharge": 42.0, "charging": False}
    assert state_body(state, caps, maps=None) == EncodedBody.of(build_state(state, caps, maps=None))
    assert list(validator(f"{version}/state.schema.json").iter_errors(body)) == []
    drained = payload(build_state(state, make_caps(battery_drain_pct_per_m=0.05), maps=None))
    assert drained["batteryState"]["reach"] == 840  # type: ignore[index]


def test_running_state_is_schema_valid_and_reports_progress() -> None:
    """R98, R101, R102: remaining nodes/edges with released flags, loads [], pose in range."""
    order = make_order(
        ["a", "b", "c"], released=2, node_actions={"b": [action("detectObject", "d")]}
    )
    state = run(apply_order(make_vehicle(), order, "new", CAPS), CAPS, 2)
    body = payload(build_state(state, CAPS, maps=held_maps(initial_maps(CAPS.map_ids))))
    assert [(n["nodeId"], n["released"]) for n in body["nodeStates"]] == [("b", True), ("c", False)]  # type: ignore[attr-defined]
    assert body["loads"] == []
    assert body["driving"] is True
    assert body["actionStates"] == [
        {"actionId": "d", "actionType": "detectObject", "actionStatus": "WAITING"}
    ]
    assert list(validator("2.1.0/state.schema.json").iter_errors(body)) == []


def test_visualization_carries_pose_and_velocity() -> None:
    """R109: visualization has agvPosition and velocity like state."""
    body = payload(build_visualization(make_vehicle(x=1.0, y=2.0)))
    assert body["agvPosition"]["x"] == 1.0  # type: ignore[index]
    assert set(body) >= {"agvPosition", "velocity"}
    assert list(validator("2.1.0/visualization.schema.json").iter_errors(body)) == []


_FINITE = st.floats(allow_nan=False, allow_infinity=False)


@given(
    x=_FINITE,
    y=_FINITE,
    theta=st.floats(-math.pi, math.pi),
    vx=_FINITE,
    omega=_FINITE,
    map_id=st.text(max_size=20),
    localized=st.booleans(),
)
def test_the_fast_visualization_body_is_the_models_own_bytes(
    x: float, y: float, theta: float, *, vx: float, omega: float, map_id: str, localized: bool
) -> None:
    """visualization_body (lever 53) writes exactly what the Visualization model encodes, for
    any pose, speed, map id and localisation; whole-number coordinates stay floats."""
    state = make_vehicle(
        x, y, theta, motion=Motion(vx=vx, omega=omega), position_initialized=localized
    )
    state = replace(state, pose=replace(state.pose, map_id=map_id))
    assert visualization_body(state) == EncodedBody.of(build_visualization(state))
    # at another pose (a cruise's, moved on without a tick): that pose, the rest the state's
    elsewhere = replace(state.pose, x=y, y=x)
    moved = replace(state, pose=elsewhere)
    assert visualization_body(state, elsewhere) == EncodedBody.of(build_visualization(moved))
    # whole numbers, as a graph file may give them: written as floats, as the model does
    whole = make_vehicle(3, 4)
    assert visualization_body(whole) == EncodedBody.of(build_visualization(whole))


_TEXT = st.text(max_size=12)
_UINT32 = st.integers(0, 2**32 - 1)
_ANGLE = st.just(0.0) | st.floats(-math.pi, math.pi)
_COORDINATE = _FINITE | st.integers(-1000, 1000)  # whole numbers, as a graph file may give them
_node_positions = st.builds(
    NodePosition,
    x=_COORDINATE,
    y=_COORDINATE,
    theta=st.none() | _ANGLE,
    allowed_deviation_xy=st.none() | st.floats(0, 5),
    map_id=_TEXT,
)
_nodes = st.builds(
    Node,
    node_id=_TEXT,
    sequence_id=_UINT32,
    node_description=st.none() | _TEXT,
    released=st.booleans(),
    node_position=st.none() | _node_positions,
    actions=st.just([]),
)
_edges = st.builds(
    Edge,
    edge_id=_TEXT,
    sequence_id=_UINT32,
    edge_description=st.none() | _TEXT,
    released=st.booleans(),
    start_node_id=_TEXT,
    end_node_id=_TEXT,
    max_speed=st.none() | st.floats(0.1, 3),
    actions=st.just([]),
)
_records = st.builds(
    ActionRecord,
    action=st.builds(
        Action,
        action_type=_TEXT,
        action_id=_TEXT,
        action_description=st.none() | _TEXT,
        blocking_type=st.sampled_from(BlockingType),
    ),
    scope=st.sampled_from(ActionScope),
    group=st.integers(-5, 20),
    status=st.sampled_from(ActionStatus),
    result=st.none() | _TEXT,
)
_errors = st.builds(
    Error,
    error_type=_TEXT,
    error_references=st.none()
    | st.lists(st.builds(ErrorReference, reference_key=_TEXT, reference_value=_TEXT), max_size=2),
    error_description=st.none() | _TEXT,
    error_hint=st.none() | _TEXT,
    error_level=st.sampled_from(ErrorLevel),
)
_loads = st.builds(
    Load,
    load_id=st.none() | _TEXT,
    load_type=st.none() | _TEXT,
    weight=st.none() | st.floats(0, 1e4),
)


@st.composite
def _vehicle_states(draw: st.DrawFn) -> VehicleState:
    state = make_vehicle(
        draw(_COORDINATE),
        draw(_COORDINATE),
        draw(_ANGLE),
        last_node_id=draw(_TEXT),
        position_initialized=draw(st.booleans()),
        order_id=draw(_TEXT),
        order_update_id=draw(_UINT32),
        zone_set_id=draw(st.none() | _TEXT),
        last_node_sequence_id=draw(_UINT32),
        nodes=tuple(draw(st.lists(_nodes, max_size=3))),
        edges=tuple(draw(st.lists(_edges, max_size=3))),
        cancel_action_id=draw(st.none() | _TEXT),
        actions=tuple(draw(st.lists(_records, max_size=3))),
        errors=tuple(draw(st.lists(_errors, max_size=2))),
        loads=tuple(draw(st.lists(_loads, max_size=2))),
        battery_charge=draw(st.floats(0, 100) | st.integers(0, 100)),
        charging=draw(st.booleans()),
        paused=draw(st.booleans()),
        operating_mode=draw(st.sampled_from(OperatingMode)),
        e_stop=draw(st.sampled_from(EStop)),
        field_violation=draw(st.booleans()),
        motion=Motion(vx=draw(_FINITE), vy=draw(_FINITE), omega=draw(_FINITE)),
        distance_since_last_node=draw(st.floats(0, 1e4) | st.integers(0, 100)),
        new_base_request=draw(st.booleans()),
    )
    return replace(state, pose=replace(state.pose, map_id=draw(_TEXT)))


@given(
    state=_vehicle_states(),
    maps=st.none()
    | st.lists(st.builds(HeldMap, _TEXT, _TEXT, st.booleans()), max_size=3).map(held_maps),
    more_errors=st.lists(_errors, max_size=2),
)
def test_the_fast_state_body_is_the_models_own_bytes(
    state: VehicleState, maps: list[Map] | None, more_errors: list[Error]
) -> None:
    """state_body (lever 54) writes exactly what the State model encodes (so R95-R102 hold
    for it as the tests above check them on the models), for any vehicle state: nodes with and
    without positions, a cancel that hides the edges (R63), actions in every status, loads,
    errors (the broker's after the state's own), maps for 2.1 or none."""
    model = build_state(state, CAPS, maps=maps)
    model = model.model_copy(update={"errors": [*model.errors, *more_errors]})
    assert state_body(state, CAPS, maps=maps, more_errors=more_errors) == EncodedBody.of(model)


@pytest.mark.parametrize("version", ["2.0.0", "2.1.0"])
def test_factsheet_is_complete_and_schema_valid(version: str) -> None:
    """R110: every factsheet section is present; vehicleConfig only on 2.1; schema-valid."""
    body = payload(build_factsheet(CAPS, TIMING, version=version))
    sections = {"typeSpecification", "physicalParameters", "protocolLimits", "protocolFeatures",
                "agvGeometry", "loadSpecification"}  # fmt: skip
    assert set(body) >= sections
    assert ("vehicleConfig" in body) is (version == "2.1.0")
    assert body["protocolLimits"]["timing"]["defaultStateInterval"] == 30.0  # type: ignore[index]
    assert list(validator(f"{version}/factsheet.schema.json").iter_errors(body)) == []


def test_factsheet_declares_every_action_with_scopes_and_parameters() -> None:
    """R111: agvActions lists every action the vehicle accepts, with scopes and parameters."""
    factsheet = build_factsheet(CAPS, TIMING, version="2.1.0")
    declared = {a.action_type: a for a in factsheet.protocol_features.agv_actions}
    assert set(declared) == set(CAPS.catalog)
    assert set(declared["pick"].action_scopes) == {ActionScope.NODE, ActionScope.EDGE}
    keys = {p.key: p.is_optional for p in declared["pick"].action_parameters or []}
    assert keys["loadType"] is False
    assert keys["lhd"] is True
    assert declared["trigger"].action_scopes == [ActionScope.INSTANT]


def test_factsheet_declares_a_load_set_per_load_type_the_vehicle_handles() -> None:
    """What master control reads to send a pick of a load type only to vehicles that handle
    it (load_rules); 3.0's factsheet carries the same sets."""
    caps = make_caps(load_types=("EPAL", "KLT"))
    for version in ("2.0.0", "3.0.0"):
        body = payload(build_factsheet(caps, TIMING, version=version))
        sets = body["loadSpecification"]["loadSets"]  # type: ignore[index]
        assert [(s["setName"], s["loadType"]) for s in sets] == [
            ("EPAL", "EPAL"),
            ("KLT", "KLT"),
        ]


def test_factsheet_optional_parameters_match_what_orders_may_use() -> None:
    """R32, R112: every supported optional field is declared; direction is not."""
    factsheet = build_factsheet(CAPS, TIMING, version="2.1.0")
    declared = {
        p.parameter: p.support.value for p in factsheet.protocol_features.optional_parameters
    }
    assert set(declared) == set(CAPS.supported_fields)
    assert declared["order.nodes.nodePosition"] == "REQUIRED"
    assert "order.edges.direction" not in declared
