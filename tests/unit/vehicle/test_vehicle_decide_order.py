"""Order acceptance, digest §3.5 (Figure 8): every accept and reject branch of decide_order."""

from __future__ import annotations

from dataclasses import replace

import pytest

from vda5050.models import (
    ActionStatus,
    BlockingType,
    Error,
    ErrorLevel,
    Order,
    Trajectory,
)
from vda5050.models.common import ControlPoint
from vda5050.models.order import Corridor
from vda5050.testing import make_order
from vda_vehicle.limits import MapExtent, ProtocolLimits
from vda_vehicle.maps import initial_maps
from vda_vehicle.model import ActionRecord, RobotMode, VehicleState
from vda_vehicle.order_executor import Accept, Ignore, Reject, apply_order, decide_order
from vda_vehicle.testing import action, make_caps, make_vehicle, reposition

CAPS = make_caps()


def rejected(decision: object, error_type: str) -> tuple[Error, ...]:
    assert isinstance(decision, Reject), decision
    assert {error.error_type for error in decision.errors} == {error_type}
    for error in decision.errors:
        assert error.error_level is ErrorLevel.WARNING
    return decision.errors


def refs(error: Error) -> dict[str, str]:
    return {ref.reference_key: ref.reference_value for ref in error.error_references or []}


def running(order: Order, mode: str = "new") -> VehicleState:
    """A vehicle at the first node that accepted ``order``."""
    return apply_order(make_vehicle(), order, "new" if mode == "new" else "update", CAPS)


def test_idle_vehicle_accepts_new_order() -> None:
    """R42: a new orderId on an idle vehicle standing on the first node is accepted."""
    assert decide_order(make_vehicle(), make_order(["a", "b"]), CAPS) == Accept("new")


def test_schema_valid_but_semantically_broken_order_is_validation_error() -> None:
    """R22, R27, R30: an order breaking the static rules is rejected with validationError,
    referencing headerId, topic, orderId and orderUpdateId."""
    order = make_order(["a", "b"]).model_copy(update={"edges": []})
    errors = rejected(decide_order(make_vehicle(), order, CAPS), "validationError")
    assert any((e.error_description or "").startswith("R22") for e in errors)
    assert {"headerId", "topic", "orderId", "orderUpdateId"} <= refs(errors[0]).keys()


def test_new_order_must_start_at_sequence_zero() -> None:
    """R25: a new order's sequenceIds start at 0."""
    order = make_order(["a", "b"], first_sequence_id=2)
    rejected(decide_order(make_vehicle(), order, CAPS), "validationError")


def test_new_order_while_nodes_remain_is_rejected() -> None:
    """R40: a new orderId while nodeStates is non-empty (even horizon only) is orderUpdateError."""
    busy = running(make_order(["a", "b", "c"], released=1))
    assert busy.nodes
    assert not any(node.released for node in busy.nodes)
    decision = decide_order(busy, make_order(["a", "x"], order_id="other"), CAPS)
    (error,) = rejected(decision, "orderUpdateError")
    assert refs(error)["orderId"] == "other"


def test_new_order_while_an_action_runs_is_rejected() -> None:
    """R41: a new orderId while an actionState is not FINISHED/FAILED is rejected."""
    record = ActionRecord(action("logReport", "l1", reason="x"), "INSTANT", -1)  # type: ignore[arg-type]
    busy = make_vehicle(actions=(replace(record, status=ActionStatus.RUNNING, triggered=True),))
    rejected(decide_order(busy, make_order(["a"]), CAPS), "orderUpdateError")


def test_unreachable_start_is_no_route_error() -> None:
    """R37: a first node outside allowedDeviationXY is rejected with noRouteError and nodeId."""
    far = make_vehicle(x=5.0)
    (error,) = rejected(decide_order(far, make_order(["a", "b"]), CAPS), "noRouteError")
    assert refs(error)["nodeId"] == "a"


def test_start_within_allowed_deviation_is_accepted() -> None:
    """R38, R39: a first node whose allowedDeviationXY covers the vehicle is reachable."""
    order = reposition(make_order(["a", "b"]), 0, allowed_deviation_xy=6.0)
    assert decide_order(make_vehicle(x=5.0), order, CAPS) == Accept("new")


def test_heading_outside_allowed_deviation_theta_is_unreachable() -> None:
    """R37: with theta and allowedDeviationTheta given, the heading must be within the band."""
    order = reposition(make_order(["a"]), 0, theta=0.0, allowed_deviation_theta=0.1)
    rejected(decide_order(make_vehicle(theta=1.0), order, CAPS), "noRouteError")
    assert decide_order(make_vehicle(theta=0.05), order, CAPS) == Accept("new")


def test_other_map_is_unreachable() -> None:
    """R37: a first node on another map than the vehicle's is not reachable."""
    caps = make_caps(map_ids=frozenset({"map", "floor2"}))
    vehicle = make_vehicle(maps=initial_maps(caps.map_ids))
    rejected(decide_order(vehicle, make_order(["a"], map_id="floor2"), caps), "noRouteError")


def test_lower_order_update_id_is_order_update_error() -> None:
    """R44: same orderId with a lower orderUpdateId is rejected; nothing changes."""
    state = running(make_order(["a", "b", "c"], released=2, order_update_id=3))
    old = make_order(["b", "c"], order_update_id=2, first_sequence_id=2)
    (error,) = rejected(decide_order(state, old, CAPS), "orderUpdateError")
    assert refs(error)["orderUpdateId"] == "2"


def test_same_order_update_id_is_ignored() -> None:
    """R45: same orderId and orderUpdateId is discarded silently."""
    order = make_order(["a", "b"])
    assert decide_order(running(order), order, CAPS) == Ignore()


def test_update_at_decision_point_while_busy_is_accepted() -> None:
    """R46: a higher orderUpdateId stitching at the decision point (nodeId and sequenceId)."""
    state = running(make_order(["a", "b", "c"], released=2))
    update = make_order(["b", "c", "d"], order_update_id=1, first_sequence_id=2)
    assert decide_order(state, update, CAPS) == Accept("update")


def test_update_skipping_update_ids_is_accepted() -> None:
    """R53: an update that stitches correctly may skip orderUpdateIds."""
    state = running(make_order(["a", "b", "c"], released=2))
    update = make_order(["b", "c"], order_update_id=5, first_sequence_id=2)
    assert decide_order(state, update, CAPS) == Accept("update")


def test_update_not_at_decision_point_is_rejected() -> None:
    """R47: an update whose first node is not the decision point is orderUpdateError."""
    state = running(make_order(["a", "b", "c"], released=2))
    update = make_order(["c", "d"], order_update_id=1, first_sequence_id=4)
    rejected(decide_order(state, update, CAPS), "orderUpdateError")


def test_update_with_right_node_but_wrong_sequence_id_is_rejected() -> None:
    """R47, digest App. A: stitching compares nodeId AND sequenceId."""
    state = running(make_order(["a", "b", "c"], released=2))
    update = make_order(["b", "c"], order_update_id=1, first_sequence_id=6)
    rejected(decide_order(state, update, CAPS), "orderUpdateError")


def test_update_resending_earlier_base_is_rejected() -> None:
    """R50: an update that re-sends base nodes before the decision point is rejected."""
    state = running(make_order(["a", "b", "c"], released=2))
    update = make_order(["a", "b", "c"], order_update_id=1)
    rejected(decide_order(state, update, CAPS), "orderUpdateError")


def test_idle_update_at_last_node_is_accepted() -> None:
    """R48: idle, an update whose first node is (lastNodeId, lastNodeSequenceId) is accepted."""
    state = replace(running(make_order(["a", "b"])), nodes=(), edges=(), last_node_id="b")
    state = replace(state, last_node_sequence_id=2)
    update = make_order(["b", "c"], order_update_id=1, first_sequence_id=2)
    assert decide_order(state, update, CAPS) == Accept("update")


def test_idle_update_elsewhere_is_rejected() -> None:
    """R49: idle, an update not starting at (lastNodeId, lastNodeSequenceId) is rejected."""
    state = replace(running(make_order(["a", "b"])), nodes=(), edges=(), last_node_id="b")
    state = replace(state, last_node_sequence_id=2)
    update = make_order(["b", "c"], order_update_id=1, first_sequence_id=4)
    rejected(decide_order(state, update, CAPS), "orderUpdateError")


def test_update_after_cancel_is_rejected() -> None:
    """§3.6 / digest §11 item 14 (derived): an update of a cancelled order is refused."""
    state = replace(running(make_order(["a"])), order_cancelled=True)
    update = make_order(["a", "b"], order_update_id=1)
    rejected(decide_order(state, update, CAPS), "orderUpdateError")


def test_unknown_action_type_is_order_error() -> None:
    """R31, R33: an unsupported actionType rejects the order with orderError naming it."""
    order = make_order(["a", "b"], node_actions={"b": [action("teleport", "t1")]})
    (error,) = rejected(decide_order(make_vehicle(), order, CAPS), "orderError")
    assert refs(error)["actionId"] == "t1"
    assert refs(error)["actionType"] == "teleport"


def test_action_in_wrong_scope_is_order_error() -> None:
    """R83: cancelOrder on a node, or waitForTrigger on an edge, rejects the order."""
    on_node = make_order(["a", "b"], node_actions={"b": [action("cancelOrder", "c1")]})
    rejected(decide_order(make_vehicle(), on_node, CAPS), "orderError")
    on_edge = make_order(
        ["a", "b"], edge_actions={"a-b": [action("waitForTrigger", "w", triggerType="go")]}
    )
    rejected(decide_order(make_vehicle(), on_edge, CAPS), "orderError")


def test_action_missing_required_parameter_is_order_error() -> None:
    """R31, R86: pick needs stationType and loadType."""
    order = make_order(["a", "b"], node_actions={"b": [action("pick", "p1", loadType="EPAL")]})
    (error,) = rejected(decide_order(make_vehicle(), order, CAPS), "orderError")
    assert "stationType" in (error.error_description or "")


def test_a_pick_or_drop_of_a_load_type_without_a_load_set_is_an_order_error() -> None:
    """The factsheet declares a loadSet per configured load type; a pick or drop naming
    another loadType is rejected, naming the action (a drop without loadType is not judged)."""
    pick = action("pick", "p1", stationType="rack", loadType="KLT")
    order = make_order(["a", "b"], node_actions={"b": [pick]})
    (error,) = rejected(decide_order(make_vehicle(), order, CAPS), "orderError")
    assert refs(error)["actionId"] == "p1"
    assert "'KLT' is not a load type of this vehicle (its load sets: 'EPAL')" in (
        error.error_description or ""
    )
    both = make_caps(load_types=("EPAL", "KLT"))
    assert isinstance(decide_order(make_vehicle(), order, both), Accept)
    drop = action("drop", "d1", loadType="KLT")
    on_edge = make_order(["a", "b"], edge_actions={"a-b": [drop]})
    (error,) = rejected(decide_order(make_vehicle(), on_edge, CAPS), "orderError")
    assert refs(error)["actionId"] == "d1"
    untyped = make_order(["a", "b"], node_actions={"b": [action("drop", "d2")]})
    assert isinstance(decide_order(make_vehicle(), untyped, CAPS), Accept)


def test_unsupported_optional_fields_are_order_errors() -> None:
    """R32, R115: direction and minHeight are not supported; trajectory and corridor are."""
    order = make_order(["a", "b"])
    trajectory = Trajectory(
        degree=1,
        knot_vector=[0, 0, 1, 1],
        control_points=[ControlPoint(x=0, y=0), ControlPoint(x=10, y=0)],
    )
    edge = order.edges[0].model_copy(
        update={
            "trajectory": trajectory,
            "corridor": Corridor(left_width=1, right_width=1),
            "direction": "left",
            "min_height": 0.1,
        }
    )
    edge = type(edge).model_validate(edge.model_dump())
    order = order.model_copy(update={"edges": [edge]})
    errors = rejected(decide_order(make_vehicle(), order, CAPS), "orderError")
    assert {refs(e)["field"] for e in errors} == {
        "order.edges.direction",
        "order.edges.minHeight",
    }


def test_supported_optional_fields_are_accepted() -> None:
    """R115: maxSpeed, orientation and allowedDeviationXY are acted on, so accepted."""
    order = make_order(["a", "b"])
    edge = type(order.edges[0]).model_validate(
        {**order.edges[0].model_dump(), "maxSpeed": 0.5, "orientation": 0.0}
    )
    assert edge.max_speed == 0.5
    order = order.model_copy(update={"edges": [edge]})
    assert decide_order(make_vehicle(), order, CAPS) == Accept("new")


def test_max_height_below_vehicle_is_order_error() -> None:
    """Digest §11 item 15: a maxHeight the vehicle cannot keep rejects the order."""
    order = make_order(["a", "b"])
    edge = type(order.edges[0]).model_validate({**order.edges[0].model_dump(), "maxHeight": 1.0})
    order = order.model_copy(update={"edges": [edge]})
    (error,) = rejected(decide_order(make_vehicle(), order, CAPS), "orderError")
    assert refs(error)["field"] == "order.edges.maxHeight"


def test_node_without_position_is_order_error() -> None:
    """R113 (vehicle side): nodePosition is REQUIRED by this vehicle's factsheet."""
    order = make_order(["a", "b"])
    bare = order.nodes[1].model_copy(update={"node_position": None})
    order = order.model_copy(update={"nodes": [order.nodes[0], bare]})
    (error,) = rejected(decide_order(make_vehicle(), order, CAPS), "orderError")
    assert refs(error)["nodeId"] == "b"


def test_unknown_map_is_rejected() -> None:
    """R35: an order using a mapId the vehicle holds no map for is rejected."""
    order = make_order(["a", "b"], map_id="moon")
    (error,) = rejected(decide_order(make_vehicle(), order, CAPS), "orderError")
    assert refs(error)["mapId"] == "moon"


def test_order_beyond_protocol_limits_is_rejected() -> None:
    """R36: more nodes than maxArrayLens order.nodes is rejected, naming the limit."""
    caps = make_caps(limits=ProtocolLimits(order_nodes=2, order_edges=1))
    (error, *_) = rejected(
        decide_order(make_vehicle(), make_order(["a", "b", "c"]), caps), "validationError"
    )
    assert "order.nodes holds 3 entries, over the limit of 2" in (error.error_description or "")


def test_too_long_id_is_rejected_naming_the_limit() -> None:
    """An orderId longer than the declared idLen is a validationError (issue 14)."""
    order = make_order(["a"], order_id="o" * 129)
    (error,) = rejected(decide_order(make_vehicle(), order, CAPS), "validationError")
    assert "order.orderId is 129 characters long, over the limit of 128" in (
        error.error_description or ""
    )


@pytest.mark.parametrize("speed", [0.0, -1.0])
def test_non_positive_speed_is_rejected(speed: float) -> None:
    """Physical sanity (issue 14): an edge maxSpeed of 0 or below is a validationError."""
    order = make_order(["a", "b"])
    edge = order.edges[0].model_copy(update={"max_speed": speed})
    order = order.model_copy(update={"edges": [edge]})
    (error,) = rejected(decide_order(make_vehicle(), order, CAPS), "validationError")
    assert refs(error)["edgeId"] == "a-b"
    assert "must be positive" in (error.error_description or "")


def test_node_far_off_the_map_is_rejected() -> None:
    """Physical sanity (issue 14): a node at x = 1e300 lies outside every map: orderError."""
    caps = make_caps(map_extents={"map": MapExtent(0.0, 0.0, 10.0, 10.0)})
    for x in (1e300, 61.0):
        order = make_order(["a", "b"], positions=[(0.0, 0.0), (x, 0.0)])
        (error,) = rejected(decide_order(make_vehicle(), order, caps), "orderError")
        assert refs(error)["nodeId"] == "b"
    near = make_order(["a", "b"], positions=[(0.0, 0.0), (59.0, 0.0)])
    assert decide_order(make_vehicle(), near, caps) == Accept("new")


def test_order_in_manual_mode_is_rejected() -> None:
    """§6.10.6 Table 1, R84 (vehicle side): no orders in MANUAL, SERVICE or TEACHIN."""
    for mode in (RobotMode.MANUAL, RobotMode.SERVICE, RobotMode.TEACHIN):
        state = make_vehicle(operating_mode=mode)
        rejected(decide_order(state, make_order(["a"]), CAPS), "orderError")
    semi = make_vehicle(operating_mode=RobotMode.SEMIAUTOMATIC)
    assert decide_order(semi, make_order(["a"]), CAPS) == Accept("new")


def test_blocking_type_is_checked_against_catalog() -> None:
    """R31: an action with a blocking type outside its declared blockingTypes is refused."""
    caps = make_caps()
    spec = replace(caps.catalog["detectObject"], blocking_types=frozenset({BlockingType.NONE}))
    caps = replace(caps, catalog={**caps.catalog, "detectObject": spec})
    order = make_order(
        ["a", "b"], node_actions={"b": [action("detectObject", "d", BlockingType.HARD)]}
    )
    rejected(decide_order(make_vehicle(), order, caps), "orderError")
