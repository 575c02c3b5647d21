"""What a vehicle's states must say about the order it was sent (docs/inspect.md; R97, R98,
R99, R62), judged by ``vda-inspect`` on crafted traffic."""

from __future__ import annotations

from typing import Any

from vda5050.codec import encode
from vda5050.models import (
    ActionState,
    ActionStatus,
    Connection,
    EdgeState,
    InstantActions,
    NodeState,
    Order,
    State,
)
from vda5050.testing import HEADER, make_order, make_state, state_at
from vda_inspect.progress import OrderProgress
from vda_inspect.rules import Inspector
from vda_inspect.severity import Severity

BASE = "uagv/v2/acme/robot_0"
ORDER = make_order(["a", "b", "c", "d"], released=3)  # a-b-c released, d on the horizon


def _state(order: Order, passed: int, **changes: Any) -> State:
    """What a conforming vehicle reports after reaching node ``passed`` of ``order``."""
    return state_at(order, passed, **changes)


def _judged(progress: OrderProgress, state: State) -> list[tuple[str, Severity]]:
    return [(rule, severity) for rule, _, severity in progress.state(state)]


def test_states_that_follow_the_order_and_its_update_are_fine() -> None:
    progress = OrderProgress()
    progress.order(ORDER)
    assert [_judged(progress, _state(ORDER, passed)) for passed in range(3)] == [[], [], []]
    update = make_order(["c", "d", "e"], order_update_id=1, first_sequence_id=4)
    progress.order(update)
    # still before the decision point c: a and b's remains, then the update from c on
    before = _state(ORDER, 1, order_update_id=1)
    before.node_states[-1] = NodeState(node_id="d", sequence_id=6, released=True)
    before.node_states.append(NodeState(node_id="e", sequence_id=8, released=True))
    before.edge_states[-1] = EdgeState(edge_id="c-d", sequence_id=5, released=True)
    before.edge_states.append(EdgeState(edge_id="d-e", sequence_id=7, released=True))
    assert _judged(progress, before) == []
    assert _judged(progress, _state(update, 2)) == []  # at e: done, lists empty


def test_a_passed_node_still_listed_is_r97_and_a_missing_one_r98() -> None:
    progress = OrderProgress()
    progress.order(ORDER)
    late = _state(ORDER, 1)
    late.node_states.insert(0, NodeState(node_id="b", sequence_id=2, released=True))
    assert _judged(progress, late) == [("R97", Severity.VIOLATION)]
    horizon_dropped = _state(ORDER, 1)
    del horizon_dropped.node_states[-1]  # d, on the horizon, must be listed too
    ((rule, text, _),) = progress.state(horizon_dropped)
    assert rule == "R98"
    assert text == "node 'd' (sequenceId 6) not traversed but not listed"


def test_a_wrong_released_flag_or_id_is_r98() -> None:
    progress = OrderProgress()
    progress.order(ORDER)
    flag = _state(ORDER, 0)
    flag.node_states[-1] = NodeState(node_id="d", sequence_id=6, released=True)
    ((rule, text, _),) = progress.state(flag)
    assert (rule, text) == (
        "R98",
        "node 'd' (sequenceId 6) listed as released=True; the order says released=False",
    )
    renamed = _state(ORDER, 0)
    renamed.edge_states[0] = EdgeState(edge_id="x", sequence_id=1, released=True)
    assert [r for r, _, _ in progress.state(renamed)] == ["R98"]


def test_a_state_not_at_the_order_yet_or_of_another_update_is_not_judged() -> None:
    progress = OrderProgress()
    progress.order(ORDER)
    elsewhere = _state(ORDER, 0, last_node_id="z", last_node_sequence_id=12, node_states=[])
    assert _judged(progress, elsewhere) == []
    assert _judged(progress, _state(ORDER, 0, order_update_id=7, node_states=[])) == []


def test_order_id_is_kept_until_a_new_order_but_a_new_session_may_forget_it() -> None:
    progress = OrderProgress()
    progress.order(ORDER)
    done = _state(ORDER, 2)  # at the end of its base
    assert _judged(progress, done) == []
    assert _judged(progress, make_state(order_id="")) == [("R99", Severity.VIOLATION)]
    assert _judged(progress, make_state(order_id="")) == []  # reported once, on the change
    assert _judged(progress, make_state(order_id="from-elsewhere")) == [("R99", Severity.NOTICE)]
    progress.new_session()
    assert _judged(progress, make_state(order_id="")) == []  # restarted: may start empty


def test_after_a_finished_cancel_the_lists_are_empty() -> None:
    progress = OrderProgress()
    progress.order(ORDER)
    cancel = InstantActions.model_validate(
        {
            **HEADER,
            "actions": [{"actionType": "cancelOrder", "actionId": "c1", "blockingType": "HARD"}],
        }
    )
    progress.instant_actions(cancel)
    running = [ActionState(action_id="c1", action_status=ActionStatus.RUNNING)]
    stopping = _state(ORDER, 1, action_states=running, node_states=[], edge_states=[])
    assert _judged(progress, stopping) == []  # stopped between nodes: lists emptied at once
    finished = [ActionState(action_id="c1", action_status=ActionStatus.FINISHED)]
    stopped = _state(ORDER, 1, action_states=finished, node_states=[], edge_states=[])
    assert _judged(progress, stopped) == []
    stuck = _state(ORDER, 1, action_states=finished)
    assert _judged(progress, stuck) == [("R62", Severity.VIOLATION)]


def test_the_inspector_reports_them_for_the_vehicle() -> None:
    inspector = Inspector()
    online = Connection.model_validate({**HEADER, "connection_state": "ONLINE"})
    inspector.observe(f"{BASE}/connection", encode(online), qos=1, retain=False, now=0)
    inspector.observe(f"{BASE}/order", encode(ORDER), qos=0, retain=False, now=0)
    wrong = _state(ORDER, 1, header_id=1)
    del wrong.edge_states[-1]
    (found,) = inspector.observe(f"{BASE}/state", encode(wrong), qos=0, retain=False, now=0.1)
    assert (found.rule, found.side, found.vehicle) == ("R98", "vehicle", "acme/robot_0")
    retained = inspector.observe(f"{BASE}/state", encode(wrong), qos=0, retain=True, now=0.2)
    assert retained == []  # a stale retained state is not held against the order


def test_a_cancel_known_only_by_its_action_state_counts_but_not_an_earlier_order_s() -> None:
    """vda-5050-lib's master sends 2.0 instant actions under the 1.x key, which the listener
    cannot read: the state's own FINISHED cancelOrder tells. After the next order, a vehicle
    that still lists that cancel is held to the new order's lists."""
    progress = OrderProgress()
    progress.order(ORDER)
    shown = [
        ActionState(action_id="x9", action_type="cancelOrder", action_status=ActionStatus.FINISHED)
    ]
    assert (
        _judged(progress, _state(ORDER, 1, action_states=shown, node_states=[], edge_states=[]))
        == []
    )
    assert _judged(progress, _state(ORDER, 1, action_states=shown)) == [("R62", Severity.VIOLATION)]
    following = make_order(["b", "c"], order_id="order-2")
    progress.order(following)
    missing = _state(following, 0, action_states=shown, edge_states=[])
    assert _judged(progress, missing) == [("R98", Severity.VIOLATION)]


def test_the_first_node_still_listed_at_its_own_sequence_id_is_not_yet_reached() -> None:
    """vda-5050-lib's virtual AGV stands on n1 with lastNodeSequenceId 0 from before its first
    order, and lists the order's first node n1 (sequenceId 0) until it has reached it. Any
    later node listed at its own sequenceId is R97."""
    progress = OrderProgress()
    progress.order(ORDER)
    arriving = _state(ORDER, 0)
    arriving.node_states.insert(0, NodeState(node_id="a", sequence_id=0, released=True))
    assert _judged(progress, arriving) == []
    late = _state(ORDER, 1)
    late.node_states.insert(0, NodeState(node_id="b", sequence_id=2, released=True))
    assert _judged(progress, late) == [("R97", Severity.VIOLATION)]
