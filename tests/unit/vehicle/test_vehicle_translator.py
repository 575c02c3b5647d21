"""The translator tick ``advance``: node traversal bookkeeping, decision point, state events."""

from __future__ import annotations

from dataclasses import replace

import pytest

from vda5050.models import ActionStatus
from vda5050.testing import make_order
from vda_vehicle.model import RobotMode, VehicleState
from vda_vehicle.navigation import EdgeExecution, EdgeReport, NavFeedback
from vda_vehicle.order_executor import apply_order
from vda_vehicle.testing import action, make_caps, make_stack, make_vehicle, run
from vda_vehicle.translator import advance, apply_feedback, events_differ, target_route

CAPS = make_caps()


def started(*node_ids: str, **kwargs: object) -> VehicleState:
    order = make_order(list(node_ids), **kwargs)  # type: ignore[arg-type]
    return apply_order(make_vehicle(), order, "new", CAPS)


def test_node_traversal_is_complete_in_one_update() -> None:
    """R97, §6.10.2: one COMPLETED edge removes nodeState and edgeState, sets lastNode,
    ends the edge's actions and triggers the node's actions, in one state update."""
    edge_actions = {
        "a-b": [action("finePositioning", "eab")],
        "b-c": [action("detectObject", "ebc")],
    }
    node_actions = {"b": [action("detectObject", "nb")]}
    state = started("a", "b", "c", node_actions=node_actions, edge_actions=edge_actions)
    slow = tuple(
        replace(r, remaining_s=100.0) if r.action_id == "eab" else r for r in state.actions
    )
    state = replace(state, actions=slow)
    report = EdgeReport("a-b", 1, EdgeExecution.COMPLETED)
    pose = replace(state.pose, x=10.0)
    after = apply_feedback(state, NavFeedback(pose, state.motion, (report,), 10.0, 0.0), CAPS)
    assert [n.node_id for n in after.nodes] == ["c"]
    assert [e.edge_id for e in after.edges] == ["b-c"]
    assert (after.last_node_id, after.last_node_sequence_id) == ("b", 2)
    status = {r.action_id: r.status for r in after.actions}
    assert status == {
        "eab": ActionStatus.FINISHED,
        "nb": ActionStatus.RUNNING,
        "ebc": ActionStatus.RUNNING,
    }
    assert after.entered_edge == 3
    assert after.distance_since_last_node == 0.0


def test_state_event_is_raised_once_per_tick() -> None:
    """R93, R94: a tick with a traversal bumps the revision once; a quiet tick does not."""
    state = run(started("a", "b"), CAPS, 4.9)
    revision = state.revision
    quiet = advance(state, 0.1, caps=CAPS, stack=make_stack(CAPS))
    assert quiet.revision == revision
    arrived = advance(quiet, 5.0, caps=CAPS, stack=make_stack(CAPS))
    assert arrived.revision == revision + 1
    assert arrived.last_node_id == "b"
    assert not arrived.driving


def test_vehicle_stops_at_decision_point_and_never_enters_horizon() -> None:
    """R55: without a base extension the vehicle stops at the last released node."""
    state = run(started("a", "b", "c", "d", released=2), CAPS, 60)
    assert state.last_node_id == "b"
    assert (state.pose.x, state.driving) == (10.0, False)
    assert target_route(state) == ()
    assert [e.edge_id for e in state.edges] == ["b-c", "c-d"]


def test_new_base_request_near_end_of_base() -> None:
    """R107: newBaseRequest is true only while the base is close to used up and a horizon waits."""
    state = started("a", "b", "c", released=2)
    assert not state.new_base_request
    state = run(state, CAPS, 5.5)
    assert state.new_base_request
    no_horizon = run(started("a", "b"), CAPS, 5.5)
    assert not no_horizon.new_base_request


def test_driving_is_true_exactly_while_moving() -> None:
    """R100: driving is true while translating or rotating, false when standing."""
    state = started("a", "b")
    assert not state.driving
    state = run(state, CAPS, 1)
    assert state.driving
    state = run(state, CAPS, 10)
    assert not state.driving
    assert state.motion.vx == 0


def test_distance_since_last_node_and_battery_drain() -> None:
    """distanceSinceLastNode grows while driving; the battery drains with distance."""
    state = run(started("a", "b", "c"), CAPS, 2)
    assert state.distance_since_last_node == pytest.approx(3.0)
    assert state.battery_charge == pytest.approx(100 - 3.0 * CAPS.battery_drain_pct_per_m)
    state = run(state, CAPS, 5)
    assert state.last_node_id == "b"
    assert state.distance_since_last_node == pytest.approx(0.5, abs=0.16)


def test_vehicle_drives_whole_order_at_speed() -> None:
    """R99: 20 m at 1.5 m/s take about 13.3 s; then no nodes remain and orderId stays."""
    state = run(started("a", "b", "c"), CAPS, 13.0)
    assert state.nodes
    state = run(state, CAPS, 0.5)
    assert state.nodes == ()
    assert (state.last_node_id, state.last_node_sequence_id) == ("c", 4)
    assert (state.order_id, state.order_update_id) == ("order-1", 0)


def test_no_motion_outside_automatic_modes() -> None:
    """§6.10.6 Table 1: the vehicle does not drive orders in MANUAL mode."""
    state = replace(started("a", "b"), operating_mode=RobotMode.MANUAL)
    assert not run(state, CAPS, 2).driving


def test_idle_tick_changes_nothing() -> None:
    """A vehicle at rest is returned unchanged (the fast path that keeps 1000 vehicles cheap)."""
    state = make_vehicle()
    assert advance(state, 1.0, caps=CAPS, stack=make_stack(CAPS)) is state


def test_events_differ_on_each_state_event_and_not_on_motion() -> None:
    """R93: what calls for a state message; pose, speed, battery and distance alone do not."""
    state = run(started("a", "b", "c", node_actions={"c": [action("pick", "p1")]}), CAPS, 1.0)
    assert not events_differ(state, replace(state, battery_charge=3.0, distance_since_last_node=7))
    record = state.actions[0]
    changes: list[dict[str, object]] = [
        {"order_update_id": state.order_update_id + 1},
        {"last_node_sequence_id": state.last_node_sequence_id + 2},
        {"nodes": state.nodes[1:]},
        {"paused": not state.paused},
        {"operating_mode": RobotMode.MANUAL},
        {"new_base_request": not state.new_base_request},
    ]
    for change in changes:
        assert events_differ(state, replace(state, **change)), change  # type: ignore[arg-type]
    moved = replace(record, status=ActionStatus.FAILED)
    assert events_differ(state, replace(state, actions=(moved, *state.actions[1:])))
    assert events_differ(state, replace(state, actions=(replace(record, awaiting_retry=True),)))
    # the same statuses in a new tuple are no event
    assert not events_differ(state, replace(state, actions=tuple(state.actions)))


def test_target_route_follows_a_moved_node_with_the_same_ids() -> None:
    """The route edges are remembered per (edge, node) object: an order that moves a node
    under the same ids gets a route to the new position, never the remembered one."""
    first = started("a", "b", positions=[(0, 0), (10, 0)])
    moved = started("a", "b", positions=[(0, 0), (0, 6)])
    first, moved = run(first, CAPS, 0.1), run(moved, CAPS, 0.1)
    assert target_route(first)[0].end.x == 10
    assert (target_route(moved)[0].end.x, target_route(moved)[0].end.y) == (0, 6)
    assert target_route(first) == target_route(first)
