"""State, visualization and factsheet built from the vehicle state (§6.10, §6.13, §6.15)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vda5050.codec import EncodedBody, encode
from vda5050.models import ActionScope
from vda5050.schemas import validator
from vda5050.testing import make_order
from vda_vehicle.factsheet import FactsheetTiming, build_factsheet
from vda_vehicle.model import Motion
from vda_vehicle.order_executor import apply_order
from vda_vehicle.reporter import build_state, build_visualization, held_maps, visualization_body
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
    maps = held_maps(CAPS.map_ids) if version == "2.1.0" else None
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


def test_running_state_is_schema_valid_and_reports_progress() -> None:
    """R98, R101, R102: remaining nodes/edges with released flags, loads [], pose in range."""
    order = make_order(
        ["a", "b", "c"], released=2, node_actions={"b": [action("detectObject", "d")]}
    )
    state = run(apply_order(make_vehicle(), order, "new", CAPS), CAPS, 2)
    body = payload(build_state(state, CAPS, maps=held_maps(CAPS.map_ids)))
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
    # whole numbers, as a graph file may give them: written as floats, as the model does
    whole = make_vehicle(3, 4)
    assert visualization_body(whole) == EncodedBody.of(build_visualization(whole))


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


def test_factsheet_optional_parameters_match_what_orders_may_use() -> None:
    """R32, R112: every supported optional field is declared; trajectory is not."""
    factsheet = build_factsheet(CAPS, TIMING, version="2.1.0")
    declared = {
        p.parameter: p.support.value for p in factsheet.protocol_features.optional_parameters
    }
    assert set(declared) == set(CAPS.supported_fields)
    assert declared["order.nodes.nodePosition"] == "REQUIRED"
    assert "order.edges.trajectory" not in declared
