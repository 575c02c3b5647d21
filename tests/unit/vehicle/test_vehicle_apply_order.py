"""Applying accepted orders and updates (§6.6.2, digest §3.4, §3.5): the state they leave."""

from __future__ import annotations

from vda5050.models import ActionScope, ActionStatus, BlockingType, Order
from vda5050.testing import make_order
from vda_vehicle.instant import receive_instant_actions
from vda_vehicle.model import VehicleState, decision_point, is_busy
from vda_vehicle.order_executor import Reject, apply_order, decide_order
from vda_vehicle.testing import action, instant, make_caps, make_vehicle, run, run_until

CAPS = make_caps()


def statuses(state: VehicleState) -> dict[str, ActionStatus]:
    return {record.action_id: record.status for record in state.actions}


def accept(state: VehicleState, order: Order) -> VehicleState:
    decision = decide_order(state, order, CAPS)
    assert not isinstance(decision, Reject), decision
    return apply_order(state, order, decision.mode, CAPS)  # type: ignore[union-attr]


def test_new_order_reports_ids_and_remaining_elements() -> None:
    """R42, R98: orderId/orderUpdateId set; node and edge states with their released flags."""
    state = accept(make_vehicle(), make_order(["a", "b", "c"], released=2, order_update_id=0))
    assert (state.order_id, state.order_update_id) == ("order-1", 0)
    assert [(n.node_id, n.released) for n in state.nodes] == [("b", True), ("c", False)]
    assert [(e.edge_id, e.released) for e in state.edges] == [("a-b", True), ("b-c", False)]


def test_first_node_counts_as_traversed_at_once() -> None:
    """R39, digest §11 item 7: the first node is lastNode at once and its actions trigger."""
    order = make_order(["a", "b"], node_actions={"a": [action("detectObject", "d0")]})
    state = accept(make_vehicle(), order)
    assert (state.last_node_id, state.last_node_sequence_id) == ("a", 0)
    assert statuses(state)["d0"] is ActionStatus.RUNNING


def test_every_order_action_appears_waiting_including_horizon() -> None:
    """R68, R70, R72: actions of base and horizon stay WAITING until their node is reached."""
    order = make_order(
        ["a", "b", "c"],
        released=2,
        node_actions={"b": [action("detectObject", "d1")], "c": [action("detectObject", "d2")]},
        edge_actions={"b-c": [action("detectObject", "d3")]},
    )
    state = accept(make_vehicle(), order)
    assert statuses(state) == dict.fromkeys(("d1", "d2", "d3"), ActionStatus.WAITING)
    state = run(state, CAPS, 30)
    assert statuses(state)["d1"] is ActionStatus.FINISHED
    assert statuses(state)["d2"] is ActionStatus.WAITING
    assert statuses(state)["d3"] is ActionStatus.WAITING


def test_new_order_drops_old_actions_but_keeps_running_instant_actions() -> None:
    """R43: a new orderId removes every old actionState except instant actions still running."""
    first = accept(
        make_vehicle(), make_order(["a"], node_actions={"a": [action("detectObject", "d")]})
    )
    first = run(first, CAPS, 2)
    first = receive_instant_actions(first, instant(action("logReport", "log", reason="r")), CAPS)
    assert statuses(first) == {"d": ActionStatus.FINISHED, "log": ActionStatus.RUNNING}
    # a running instant action keeps the vehicle busy (R41); finish it but keep a charger going
    charging = receive_instant_actions(
        run(first, CAPS, 2), instant(action("startCharging", "chg")), CAPS
    )
    second = accept(run(charging, CAPS, 5), make_order(["a"], order_id="order-2"))
    assert statuses(second) == {}
    assert second.order_id == "order-2"


def test_accepting_an_order_clears_rejection_warnings() -> None:
    """R29, R103: the rejection warning stays until the next accepted order, and not after
    (cleared errors leave `errors`)."""
    state = accept(make_vehicle(), make_order(["a", "b"]))
    decision = decide_order(state, make_order(["a"], order_id="x"), CAPS)
    assert isinstance(decision, Reject)
    state = state.bumped(errors=decision.errors)
    state = run(state, CAPS, 30)
    assert [e.error_type for e in state.errors] == ["orderUpdateError"]
    state = accept(state, make_order(["b"], order_id="next", positions=[(10, 0)]))
    assert state.errors == ()


def test_update_replaces_horizon_and_its_waiting_actions() -> None:
    """R46, R52: the old horizon and its WAITING actions go; the update's elements follow."""
    order = make_order(
        ["a", "b", "c"], released=2, node_actions={"c": [action("detectObject", "old")]}
    )
    state = accept(make_vehicle(), order)
    update = make_order(
        ["b", "x", "y"],
        order_update_id=1,
        first_sequence_id=2,
        released=2,
        positions=[(10, 0), (10, 10), (10, 20)],
        node_actions={"y": [action("detectObject", "new")]},
    )
    state = accept(state, update)
    assert [(n.node_id, n.sequence_id) for n in state.nodes] == [("b", 2), ("x", 4), ("y", 6)]
    assert [e.edge_id for e in state.edges] == ["a-b", "b-x", "x-y"]
    assert "old" not in statuses(state)
    assert statuses(state)["new"] is ActionStatus.WAITING
    assert state.order_update_id == 1
    assert decision_point(state) == ("x", 4)


def test_update_without_horizon_deletes_horizon() -> None:
    """R54: an update with no unreleased elements leaves no horizon."""
    state = accept(make_vehicle(), make_order(["a", "b", "c"], released=2))
    state = accept(state, make_order(["b"], order_update_id=1, first_sequence_id=2))
    assert [n.node_id for n in state.nodes] == ["b"]
    assert all(e.released for e in state.edges)


def test_stitching_node_keeps_original_content_and_actions() -> None:
    """R51: the stitching node keeps what was first received; its actions are not duplicated."""
    order = make_order(
        ["a", "b", "c"], released=2, node_actions={"b": [action("detectObject", "b1")]}
    )
    state = accept(make_vehicle(), order)
    update = make_order(
        ["b", "c"],
        order_update_id=1,
        first_sequence_id=2,
        positions=[(99, 99), (20, 0)],
        node_actions={"b": [action("finePositioning", "b2")]},
    )
    state = accept(state, update)
    stitching = state.nodes[0]
    assert stitching.node_position is not None
    assert (stitching.node_position.x, stitching.node_position.y) == (10.0, 0.0)
    ids = [record.action_id for record in state.actions]
    assert ids == ["b1"]


def test_stitching_node_already_reached_is_not_rerun() -> None:
    """R51: at the decision point, an update does not re-run the stitching node's actions."""
    order = make_order(["a", "b"], node_actions={"b": [action("detectObject", "b1")]})
    state = run_until(accept(make_vehicle(), order), CAPS, lambda s: not is_busy(s))
    update = make_order(
        ["b", "c"],
        order_update_id=1,
        first_sequence_id=2,
        node_actions={"b": [action("detectObject", "b1-again")]},
    )
    state = accept(state, update)
    assert [record.action_id for record in state.actions] == ["b1"]
    assert [n.node_id for n in state.nodes] == ["c"]


def test_horizon_release_by_update_lets_the_vehicle_go_on() -> None:
    """R46, R55: stopped at the decision point, the vehicle drives on once the update releases."""
    state = accept(make_vehicle(), make_order(["a", "b", "c"], released=2))
    state = run(state, CAPS, 30)
    assert state.last_node_id == "b"
    assert not state.driving
    assert [n.node_id for n in state.nodes] == ["c"]
    state = accept(state, make_order(["b", "c"], order_update_id=1, first_sequence_id=2))
    state = run(state, CAPS, 30)
    assert (state.last_node_id, state.last_node_sequence_id) == ("c", 4)
    assert state.nodes == ()


def test_rejected_order_changes_nothing() -> None:
    """R28: decide_order leaves the state as it was; the running order goes on."""
    state = accept(make_vehicle(), make_order(["a", "b", "c"]))
    before = state
    decide_order(state, make_order(["q"], order_id="other"), CAPS)
    assert state == before


def test_blocking_node_action_keeps_next_edge_actions_waiting() -> None:
    """Figure 15: the next edge is entered only when the node's HARD action has finished."""
    order = make_order(
        ["a", "b"],
        node_actions={"a": [action("finePositioning", "fp", BlockingType.HARD)]},
        edge_actions={"a-b": [action("detectObject", "edge")]},
    )
    state = accept(make_vehicle(), order)
    assert statuses(state) == {"fp": ActionStatus.RUNNING, "edge": ActionStatus.WAITING}
    state = run(state, CAPS, 1)
    assert not state.driving
    assert statuses(state)["edge"] is ActionStatus.WAITING
    state = run(state, CAPS, 1.5)
    assert statuses(state)["fp"] is ActionStatus.FINISHED
    assert statuses(state)["edge"] is not ActionStatus.WAITING
    assert state.driving


def test_instant_actions_survive_as_instant_scope() -> None:
    """§6.10.6: instant actions are held with scope INSTANT, apart from order actions."""
    state = receive_instant_actions(make_vehicle(), instant(action("stateRequest", "s")), CAPS)
    assert state.actions[0].scope is ActionScope.INSTANT
