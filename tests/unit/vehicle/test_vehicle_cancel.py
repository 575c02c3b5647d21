"""cancelOrder (§6.6.3, Figure 9; digest §3.6): with and without an order."""

from __future__ import annotations

from dataclasses import replace

from vda5050.models import Action, ActionStatus, BlockingType
from vda5050.testing import make_order
from vda_vehicle.capabilities import Capabilities
from vda_vehicle.instant import receive_instant_actions
from vda_vehicle.model import VehicleState
from vda_vehicle.order_executor import Accept, apply_order, decide_order
from vda_vehicle.reporter import build_state
from vda_vehicle.testing import action, instant, make_caps, make_vehicle, run, run_until

CAPS = make_caps()
#: A vehicle that can stop anywhere (§6.6.3: "if it can stop between nodes").
ANYWHERE = make_caps(stop_between_nodes=True)
S = ActionStatus


def statuses(state: VehicleState) -> dict[str, ActionStatus]:
    return {record.action_id: record.status for record in state.actions}


def send(state: VehicleState, *actions: Action, caps: Capabilities = CAPS) -> VehicleState:
    return receive_instant_actions(state, instant(*actions), caps)


def driving_order() -> VehicleState:
    order = make_order(
        ["a", "b", "c"],
        released=2,
        node_actions={"b": [action("detectObject", "wait")]},
        edge_actions={"a-b": [action("finePositioning", "edge")]},
    )
    return run(apply_order(make_vehicle(), order, "new", CAPS), CAPS, 1)


def test_cancel_while_driving_stops_and_clears_the_order() -> None:
    """R59, R60, R62 (a vehicle that can stop between nodes): RUNNING at once, WAITING actions
    FAIL, states empty, ids kept, FINISHED once standing."""
    state = driving_order()
    assert state.driving
    state = send(state, action("cancelOrder", "cancel"), caps=ANYWHERE)
    assert statuses(state)["cancel"] is S.RUNNING
    assert statuses(state)["wait"] is S.FAILED
    assert statuses(state)["edge"] is S.FAILED
    assert (state.nodes, state.edges) == ((), ())
    state = run(state, ANYWHERE, 0.2)
    assert not state.driving
    assert statuses(state)["cancel"] is S.FINISHED
    assert (state.order_id, state.order_update_id) == ("order-1", 0)
    assert set(statuses(state)) == {"wait", "edge", "cancel"}


def test_line_guided_cancel_finishes_the_edge_on_the_next_node() -> None:
    """R63, R59: the line-guided vehicle keeps only the next node's nodeState (no edgeState)
    while it drives on to it, cancelOrder stays RUNNING, and on arrival lastNodeId is that node,
    nodeStates are empty and cancelOrder is FINISHED; the order's actions there do not run."""
    state = send(driving_order(), action("cancelOrder", "cancel", BlockingType.HARD))
    assert statuses(state)["cancel"] is S.RUNNING
    assert [n.node_id for n in state.nodes] == ["b"]
    reported = build_state(state, CAPS, maps=None)
    assert [n.node_id for n in reported.node_states] == ["b"]
    assert reported.edge_states == []
    state = run(state, CAPS, 1.0)
    assert state.driving
    assert statuses(state)["cancel"] is S.RUNNING
    state = run_until(state, CAPS, lambda s: statuses(s)["cancel"] is S.FINISHED)
    assert (state.last_node_id, state.last_node_sequence_id) == ("b", 2)
    assert (state.pose.x, state.pose.y) == (10.0, 0.0)
    assert (state.nodes, state.edges, state.driving) == ((), (), False)
    assert statuses(state)["wait"] is S.FAILED


def test_new_order_at_the_node_reached_after_a_cancel_is_accepted() -> None:
    """R65: after a line-guided cancel the vehicle stands on a node; an order from there is
    accepted without any manual step."""
    state = send(driving_order(), action("cancelOrder", "cancel"))
    state = run_until(state, CAPS, lambda s: statuses(s)["cancel"] is S.FINISHED)
    order = make_order(["b", "c"], order_id="order-2", positions=[(10.0, 0.0), (20.0, 0.0)])
    assert decide_order(state, order, CAPS) == Accept("new")


def test_non_interruptible_action_delays_cancel_finished() -> None:
    """R61: a running pick is not interrupted; cancelOrder finishes only after it ends."""
    pick = action("pick", "p", BlockingType.HARD, stationType="s", loadType="EPAL")
    order = make_order(["a", "b"], node_actions={"a": [pick]})
    state = run(apply_order(make_vehicle(), order, "new", CAPS), CAPS, 1.5)
    assert statuses(state)["p"] is S.RUNNING
    state = send(state, action("cancelOrder", "cancel"))
    state = run(state, CAPS, 1)
    assert statuses(state) == {"p": S.RUNNING, "cancel": S.RUNNING}
    state = run(state, CAPS, 3)
    assert statuses(state) == {"p": S.FINISHED, "cancel": S.FINISHED}


def test_cancel_fails_a_waiting_for_trigger() -> None:
    """R82: waitForTrigger of a cancelled order ends FAILED."""
    wait = action("waitForTrigger", "w", BlockingType.HARD, triggerType="go")
    state = apply_order(make_vehicle(), make_order(["a"], node_actions={"a": [wait]}), "new", CAPS)
    state = send(state, action("cancelOrder", "cancel"))
    assert statuses(state) == {"w": S.FAILED, "cancel": S.FINISHED}


def test_cancel_without_order_fails_with_no_order_to_cancel() -> None:
    """R64: no order → cancelOrder FAILED and noOrderToCancel WARNING with the actionId."""
    state = send(make_vehicle(), action("cancelOrder", "c1"))
    assert statuses(state)["c1"] is S.FAILED
    (error,) = state.errors
    assert error.error_type == "noOrderToCancel"
    assert error.error_level.value == "WARNING"
    refs = [(r.reference_key, r.reference_value) for r in error.error_references or []]
    assert refs == [("actionId", "c1")]


def test_cancel_after_finished_order_fails() -> None:
    """R64: an order that has ended leaves nothing to cancel."""
    state = apply_order(make_vehicle(), make_order(["a", "b"]), "new", CAPS)
    state = run_until(state, CAPS, lambda s: not s.nodes and not s.driving)
    state = send(state, action("cancelOrder", "c1"))
    assert statuses(state)["c1"] is S.FAILED
    assert [e.error_type for e in state.errors] == ["noOrderToCancel"]


def test_second_cancel_fails() -> None:
    """R64: cancelling an already cancelled order fails with noOrderToCancel."""
    state = run(send(driving_order(), action("cancelOrder", "c1")), CAPS, 0.2)
    state = send(state, action("cancelOrder", "c2"))
    assert statuses(state)["c2"] is S.FAILED
    assert [e.error_type for e in state.errors] == ["noOrderToCancel"]


def test_new_order_after_cancel_from_current_pose_is_accepted() -> None:
    """R65, R38: after a cancel, a new order starting where the vehicle stands is accepted."""
    state = run(send(driving_order(), action("cancelOrder", "c1"), caps=ANYWHERE), ANYWHERE, 0.2)
    here = (state.pose.x, state.pose.y)
    order = make_order(["tmp", "b"], order_id="order-2", positions=[here, (10.0, 0.0)])
    assert decide_order(state, order, CAPS) == Accept("new")
    state = apply_order(state, order, "new", CAPS)
    assert statuses(state) == {}
    assert not state.order_cancelled


def test_cancel_right_on_a_node_stops_there() -> None:
    """Cancelled the moment it passed a node (standing on it), the line-guided vehicle stops on
    that node at once; it does not drive on to the next one."""
    order = make_order(["a", "b", "c"])
    state = apply_order(make_vehicle(), order, "new", CAPS)
    state = run_until(state, CAPS, lambda s: s.last_node_id == "b")
    state = replace(state, pose=replace(state.pose, x=10.0), distance_since_last_node=0.0)
    state = send(state, action("cancelOrder", "cancel"))
    assert (state.nodes, state.edges) == ((), ())
    state = run(state, CAPS, 0.2)
    assert statuses(state)["cancel"] is S.FINISHED
    assert (state.last_node_id, state.pose.x) == ("b", 10.0)
