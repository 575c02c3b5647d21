"""The order status machine, resends and base extension (§6.6.2–§6.6.4; R45, R56–R58, R66, R84,
R114)."""

from __future__ import annotations

from dataclasses import replace

from vda5050.models import (
    Action,
    ActionState,
    ActionStatus,
    BlockingType,
    Error,
    ErrorLevel,
    ErrorReference,
    InstantActions,
    OperatingMode,
    Order,
)
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId
from vda_master.capabilities import ActionSpec
from vda_master.dispatcher import (
    BEHIND_CEILING,
    DispatchSettings,
    OrderStatus,
    OrderTrack,
    SendGate,
    anything_due,
    due_messages,
    reduce_track,
    request_cancel,
    start_track,
)
from vda_master.order_builder import OrderPlan, PlanRequest, build_message, plan_order
from vda_master.release import ReleasePolicy
from vda_master.routing import Route, shortest_route
from vda_master.testing import id_source, line_graph, make_factsheet, plan_state

SETTINGS = DispatchSettings(confirm_timeout_s=1.0, max_sends=3, release=ReleasePolicy(3))
READY = SendGate(vehicle_ready=True, order_allowed=True)


def _plan(count: int = 8, *, with_action: bool = False) -> OrderPlan:
    graph = line_graph(count)
    route = shortest_route(graph, "n0", f"n{count - 1}")
    assert isinstance(route, Route)
    actions = {count - 1: [ActionSpec("startCharging")]} if with_action else {}
    plan = plan_order(
        graph,
        PlanRequest(route, "o1", actions, {}),
        agv=AgvId("acme", "r1"),
        version="2.1.0",
        factsheet=make_factsheet() if with_action else None,
        action_ids=id_source(),
    )
    assert isinstance(plan, OrderPlan)
    return plan


def _sent(plan: OrderPlan, now: float = 0.0) -> OrderTrack:
    track, out = due_messages(
        start_track(plan, SETTINGS, max_nodes=None, now=now), now, SETTINGS, READY
    )
    assert len(out) == 1
    return track


def _cancel_message(action_id: str = "c1") -> InstantActions:
    action = Action(action_type="cancelOrder", action_id=action_id, blocking_type=BlockingType.HARD)
    return InstantActions.model_validate({**HEADER, "actions": [action]})


def _orders(messages: list[Order | InstantActions]) -> list[Order]:
    return [m for m in messages if isinstance(m, Order)]


def test_new_track_sends_update_zero_with_a_window() -> None:
    """A new order is SENT with orderUpdateId 0 and the base released three nodes ahead (R57)."""
    track, out = due_messages(
        start_track(_plan(), SETTINGS, max_nodes=None, now=0), 0, SETTINGS, READY
    )
    (order,) = _orders(out)
    assert track.status == OrderStatus.SENT
    assert order.order_update_id == 0
    assert [n.released for n in order.nodes] == [True] * 4 + [False] * 4


def test_no_resend_before_the_timeout() -> None:
    """An unconfirmed order is not sent again before confirm_timeout_s."""
    _, out = due_messages(_sent(_plan()), 0.5, SETTINGS, READY)
    assert out == []


def test_unconfirmed_order_is_resent_unchanged() -> None:
    """After the timeout the same order (same ids and content) is sent again (R45 makes it safe)."""
    track = _sent(_plan())
    track, out = due_messages(track, 1.0, SETTINGS, READY)
    assert _orders(out) == [track.message]
    assert track.pending is not None
    assert track.pending.sends == 2


def test_resends_are_bounded() -> None:
    """When no state confirms the order after max_sends sends, it is FAILED."""
    track = _sent(_plan())
    for now in (1.0, 2.0, 3.0):
        track, _ = due_messages(track, now, SETTINGS, READY)
    assert track.status == OrderStatus.FAILED
    assert "no state confirmed orderUpdateId 0 after 3 sends" in track.reason


def test_anything_due_agrees_with_due_messages() -> None:
    """The sweep's cheap check says "due" exactly when a send or a resend is due: a new order at
    once, a sent one only after the timeout, a confirmed or ended one never."""
    plan = _plan()
    assert anything_due(start_track(plan, SETTINGS, max_nodes=None, now=0), 0.0, SETTINGS)
    sent = _sent(plan)
    assert not anything_due(sent, 0.5, SETTINGS)
    assert anything_due(sent, 1.0, SETTINGS)
    assert due_messages(sent, 1.0, SETTINGS, READY)[1]
    confirmed = reduce_track(sent, plan_state(plan, released_end=3), SETTINGS)
    assert not anything_due(confirmed, 100.0, SETTINGS)
    cancelling = request_cancel(confirmed, _cancel_message())
    assert isinstance(cancelling, OrderTrack)
    assert anything_due(cancelling, 100.0, SETTINGS)
    assert not anything_due(replace(sent, status=OrderStatus.FAILED), 100.0, SETTINGS)


def test_no_resend_while_the_inbound_lags_unless_overdue_many_times() -> None:
    """While master control has unread messages (the confirmation may be among them), an
    overdue order is not resent; a first send still goes out; past BEHIND_CEILING timeouts the
    resend goes out anyway (a master that never catches up still recovers a lost order)."""
    behind = replace(READY, resend_allowed=False)
    sent = _sent(_plan())
    assert not anything_due(sent, 1.0, SETTINGS, resend=False)
    assert due_messages(sent, 1.0, SETTINGS, behind)[1] == []
    first = start_track(_plan(), SETTINGS, max_nodes=None, now=0)
    assert len(due_messages(first, 0.0, SETTINGS, behind)[1]) == 1
    late = BEHIND_CEILING * SETTINGS.confirm_timeout_s
    assert anything_due(sent, late, SETTINGS, resend=False)
    assert len(due_messages(sent, late, SETTINGS, behind)[1]) == 1


def test_nothing_is_sent_to_a_vehicle_that_is_not_ready() -> None:
    """An order is held back while the vehicle is offline or in a mode like MANUAL (R84)."""
    track = start_track(_plan(), SETTINGS, max_nodes=None, now=0)
    track, out = due_messages(track, 5.0, SETTINGS, replace(READY, vehicle_ready=False))
    assert out == []
    assert track.status == OrderStatus.SENT


def test_order_waits_for_min_order_interval() -> None:
    """An order message waits while minOrderInterval has not passed (R114)."""
    track = start_track(_plan(), SETTINGS, max_nodes=None, now=0)
    _, out = due_messages(track, 0.0, SETTINGS, replace(READY, order_allowed=False))
    assert out == []


def test_state_with_order_and_update_id_accepts_it() -> None:
    """A state showing the orderId and orderUpdateId confirms the order; with nodeStates it runs."""
    plan = _plan()
    track = reduce_track(_sent(plan), plan_state(plan, released_end=3), SETTINGS)
    assert track.pending is None
    assert track.status == OrderStatus.RUNNING


def test_confirmed_without_node_states_is_accepted() -> None:
    """A confirming state with no nodeStates yet (actions waiting) makes the order ACCEPTED."""
    plan = _plan(with_action=True)
    state = plan_state(plan, released_end=3, node_states=[], edge_states=[])
    assert reduce_track(_sent(plan), state, SETTINGS).status == OrderStatus.ACCEPTED


def test_state_of_another_order_does_not_confirm() -> None:
    """A state with a different orderId leaves the order SENT and pending."""
    plan = _plan()
    track = reduce_track(_sent(plan), make_state(order_id="old"), SETTINGS)
    assert track.status == OrderStatus.SENT
    assert track.pending is not None


def _rejection(order_id: str, update_id: str | None = "0") -> Error:
    refs = [("orderId", order_id)] + ([("orderUpdateId", update_id)] if update_id else [])
    return Error(
        error_type="validationError",
        error_level=ErrorLevel.WARNING,
        error_description="bad order",
        error_references=[ErrorReference(reference_key=k, reference_value=v) for k, v in refs],
    )


def test_error_referencing_the_order_rejects_it() -> None:
    """A state error that references the orderId and orderUpdateId makes it REJECTED (§6.6.4)."""
    plan = _plan()
    track = reduce_track(_sent(plan), make_state(errors=[_rejection("o1")]), SETTINGS)
    assert track.status == OrderStatus.REJECTED
    assert "validationError" in track.reason
    assert track.pending is None


def test_error_about_another_order_is_ignored() -> None:
    """An error referencing another order leaves this one alone."""
    plan = _plan()
    track = reduce_track(_sent(plan), make_state(errors=[_rejection("o0")]), SETTINGS)
    assert track.status == OrderStatus.SENT


def test_finished_when_empty_and_actions_finished() -> None:
    """Empty nodeStates and edgeStates with every order action FINISHED means FINISHED."""
    plan = _plan(4, with_action=True)
    running = plan_state(plan, passed=3, actions={"a1": ActionStatus.RUNNING})
    track = reduce_track(_sent(plan), running, SETTINGS)
    assert track.status == OrderStatus.RUNNING
    done = plan_state(plan, passed=3, actions={"a1": ActionStatus.FINISHED})
    assert reduce_track(track, done, SETTINGS).status == OrderStatus.FINISHED


def test_failed_action_fails_the_order() -> None:
    """An order action reported FAILED makes the order FAILED."""
    plan = _plan(4, with_action=True)
    state = plan_state(plan, passed=3, actions={"a1": ActionStatus.FAILED})
    track = reduce_track(_sent(plan), state, SETTINGS)
    assert track.status == OrderStatus.FAILED
    assert "'a1'" in track.reason


def test_order_lost_by_a_restarted_vehicle_fails_at_once() -> None:
    """A vehicle that confirmed the order and then reports orderId "" (it restarted) no longer
    holds it: FAILED with that reason, so the vehicle is free again (issue 14)."""
    plan = _plan(4)
    track = reduce_track(_sent(plan), plan_state(plan, passed=1), SETTINGS)
    assert track.status == OrderStatus.RUNNING
    lost = reduce_track(track, make_state(last_node_id="n1"), SETTINGS)
    assert lost.status == OrderStatus.FAILED
    assert "reports orderId none (it restarted" in lost.reason


def test_an_old_order_in_the_state_before_confirmation_is_not_a_loss() -> None:
    """Before the vehicle confirmed the new order, its states still show the previous order:
    that is waiting, not a loss."""
    plan = _plan(4)
    track = reduce_track(_sent(plan), make_state(order_id="older", last_node_id="n0"), SETTINGS)
    assert track.status == OrderStatus.SENT


def test_failed_order_reason_carries_the_vehicles_own_words() -> None:
    """The reason of a FAILED order quotes the vehicle: the action's resultDescription and the
    error that references it (issue 8: "there is no matching load to drop")."""
    plan = _plan(4, with_action=True)
    base = plan_state(plan, passed=3, actions={"a1": ActionStatus.FAILED})
    states = [
        a.model_copy(update={"result_description": "charger not aligned"})
        for a in base.action_states
    ]
    error = Error(
        error_type="actionError",
        error_level=ErrorLevel.WARNING,
        error_description="there is no charger here",
        error_references=[ErrorReference(reference_key="actionId", reference_value="a1")],
    )
    state = base.model_copy(update={"action_states": states, "errors": [error]})
    track = reduce_track(_sent(plan), state, SETTINGS)
    assert track.reason == (
        "startCharging action 'a1' failed: charger not aligned; "
        "actionError: there is no charger here"
    )


def test_empty_node_states_short_of_the_destination_are_not_finished() -> None:
    """Empty nodeStates and edgeStates do not finish an order whose vehicle stands short of its
    destination: only the last node reached (and every action FINISHED) does."""
    plan = _plan(4)
    track = reduce_track(_sent(plan), plan_state(plan, passed=1), SETTINGS)
    short = plan_state(plan, passed=1, node_states=[], edge_states=[])
    assert reduce_track(track, short, SETTINGS).status == OrderStatus.RUNNING


def test_an_order_the_vehicle_clears_in_manual_fails() -> None:
    """A vehicle that enters MANUAL clears its order (2.x §6.10.6 Table 1; 3.0 §6.6.7): it keeps
    orderId and lastNodeId and empties its node and edge states where it stands. The order ends
    FAILED, saying so, instead of FINISHED; the same for SERVICE and TEACHIN."""
    plan = _plan(4)
    track = reduce_track(_sent(plan), plan_state(plan, passed=1), SETTINGS)
    for mode in (OperatingMode.MANUAL, OperatingMode.SERVICE, OperatingMode.TEACHIN):
        cleared = plan_state(plan, passed=1, node_states=[], edge_states=[], operating_mode=mode)
        ended = reduce_track(track, cleared, SETTINGS)
        assert ended.status == OrderStatus.FAILED
        assert ended.reason == (
            f"the vehicle cleared the order in operatingMode {mode.value} at node n1, "
            "before reaching n3"
        )


def test_a_cleared_order_fails_with_its_actions_failed_too() -> None:
    """3.0 §6.6.7: the scheduled actions of a cleared order are reported FAILED; the order's
    reason names the clearing, not a failed action."""
    plan = _plan(4, with_action=True)
    track = reduce_track(_sent(plan), plan_state(plan, passed=1), SETTINGS)
    cleared = plan_state(
        plan,
        passed=1,
        node_states=[],
        edge_states=[],
        actions={"a1": ActionStatus.FAILED},
        operating_mode=OperatingMode.MANUAL,
    )
    ended = reduce_track(track, cleared, SETTINGS)
    assert ended.status == OrderStatus.FAILED
    assert ended.reason.startswith("the vehicle cleared the order in operatingMode MANUAL")


def test_manual_with_the_order_still_in_the_state_is_not_a_clearing() -> None:
    """A vehicle in MANUAL that still lists the order's nodes (3.0's INTERVENED, which master
    control reads as MANUAL, keeps the order) has not cleared it; nor has one standing on its
    base's end with nothing released beyond, waiting for the next update."""
    plan = _plan(8)
    track = reduce_track(_sent(plan), plan_state(plan, released_end=3), SETTINGS)
    assert (track.status, track.released_end, track.pending) == (OrderStatus.RUNNING, 3, None)
    keeps = plan_state(plan, passed=1, released_end=3, operating_mode=OperatingMode.MANUAL)
    assert reduce_track(track, keeps, SETTINGS).status == OrderStatus.RUNNING
    at_base_end = plan_state(
        plan, passed=3, node_states=[], edge_states=[], operating_mode=OperatingMode.MANUAL
    )
    assert reduce_track(track, at_base_end, SETTINGS).status == OrderStatus.RUNNING
    short_of_it = plan_state(
        plan, passed=2, node_states=[], edge_states=[], operating_mode=OperatingMode.MANUAL
    )
    assert reduce_track(track, short_of_it, SETTINGS).status == OrderStatus.FAILED


def test_not_finished_while_base_still_to_release() -> None:
    """An empty state does not finish an order whose route is not fully released yet."""
    plan = _plan(8)
    state = plan_state(plan, passed=3, node_states=[], edge_states=[])
    track = reduce_track(_sent(plan), state, SETTINGS)
    assert track.status != OrderStatus.FINISHED


def test_progress_makes_a_stitched_update() -> None:
    """Passing a node yields update 1 starting at the decision point, base one node longer (R56,
    R57)."""
    plan = _plan(8)
    track = reduce_track(_sent(plan), plan_state(plan, released_end=3), SETTINGS)
    track = reduce_track(track, plan_state(plan, passed=1, released_end=3), SETTINGS)
    update = track.message
    assert update.order_update_id == 1
    assert (update.nodes[0].node_id, update.nodes[0].sequence_id) == ("n3", 6)
    assert [n.released for n in update.nodes] == [True, True, False, False, False]
    assert track.pending is not None


def test_update_never_resends_earlier_base() -> None:
    """An update holds no node before the decision point (R56, R66)."""
    plan = _plan(8)
    track = reduce_track(_sent(plan), plan_state(plan, released_end=3), SETTINGS)
    track = reduce_track(track, plan_state(plan, passed=2, released_end=3), SETTINGS)
    assert min(n.sequence_id for n in track.message.nodes) == 6


def test_only_one_update_in_flight() -> None:
    """No further update is made before the previous one is confirmed, so every update stitches."""
    plan = _plan(8)
    track = reduce_track(_sent(plan), plan_state(plan, released_end=3), SETTINGS)
    track = reduce_track(track, plan_state(plan, passed=1, released_end=3), SETTINGS)
    again = reduce_track(track, plan_state(plan, passed=2, released_end=3), SETTINGS)
    assert again.update_id == 1
    confirmed = reduce_track(
        again, plan_state(plan, update_id=1, passed=2, released_end=4), SETTINGS
    )
    assert confirmed.update_id == 2
    assert confirmed.message.nodes[0].node_id == "n4"


def test_new_base_request_triggers_an_update() -> None:
    """newBaseRequest makes an update even before the vehicle passed a node (§6.10.3)."""
    plan = _plan(8)
    track = reduce_track(_sent(plan), plan_state(plan, released_end=3), SETTINGS)
    state = plan_state(plan, released_end=3, new_base_request=True)
    assert reduce_track(track, state, SETTINGS).update_id == 1


def test_update_is_cut_to_the_node_limit() -> None:
    """With order.nodes = 3 each message holds three nodes and the base grows within it (R114)."""
    plan = _plan(8)
    track, _ = due_messages(start_track(plan, SETTINGS, max_nodes=3, now=0), 0, SETTINGS, READY)
    assert [n.node_id for n in track.message.nodes] == ["n0", "n1", "n2"]
    track = reduce_track(track, plan_state(plan, passed=1, released_end=2), SETTINGS)
    assert [n.node_id for n in track.message.nodes] == ["n2", "n3", "n4"]


def test_cancel_sends_cancel_order_and_stops_extending() -> None:
    """After DELETE only cancelOrder goes out; the base is not extended any more (R66)."""
    plan = _plan(8)
    track = reduce_track(_sent(plan), plan_state(plan, released_end=3), SETTINGS)
    cancelled = request_cancel(track, _cancel_message())
    assert isinstance(cancelled, OrderTrack)
    cancelled, out = due_messages(cancelled, 5.0, SETTINGS, READY)
    assert [type(m) for m in out] == [InstantActions]
    progressed = reduce_track(cancelled, plan_state(plan, passed=2, released_end=3), SETTINGS)
    assert progressed.update_id == 0


def test_cancel_order_finished_means_cancelled() -> None:
    """The order is CANCELLED once cancelOrder is FINISHED (§6.6.3)."""
    plan = _plan(8)
    track = reduce_track(_sent(plan), plan_state(plan, released_end=3), SETTINGS)
    cancelled = request_cancel(track, _cancel_message("c9"))
    assert isinstance(cancelled, OrderTrack)
    done = ActionState(action_id="c9", action_status=ActionStatus.FINISHED)
    state = plan_state(plan, passed=1, node_states=[], edge_states=[], action_states=[done])
    assert reduce_track(cancelled, state, SETTINGS).status == OrderStatus.CANCELLED


def test_order_being_cancelled_is_never_finished_by_the_cancel_itself() -> None:
    """A wholly released order whose vehicle empties its node states on cancel is not FINISHED
    while cancelOrder runs, and CANCELLED once it is FINISHED (interop finding, issue 8)."""
    plan = _plan(3)
    track = reduce_track(_sent(plan), plan_state(plan, passed=0), SETTINGS)
    assert track.released_end == plan.last_index
    cancelled = request_cancel(track, _cancel_message("c9"))
    assert isinstance(cancelled, OrderTrack)
    running = ActionState(action_id="c9", action_status=ActionStatus.RUNNING)
    empty = plan_state(plan, passed=1, node_states=[], edge_states=[], action_states=[running])
    cancelled = reduce_track(cancelled, empty, SETTINGS)
    assert cancelled.status == OrderStatus.RUNNING
    done = running.model_copy(update={"action_status": ActionStatus.FINISHED})
    finished = plan_state(plan, passed=1, node_states=[], edge_states=[], action_states=[done])
    assert reduce_track(cancelled, finished, SETTINGS).status == OrderStatus.CANCELLED


def test_cancel_that_came_too_late_leaves_the_order_finished() -> None:
    """noOrderToCancel after the vehicle had done everything: the order is FINISHED."""
    plan = _plan(3)
    track = reduce_track(_sent(plan), plan_state(plan, passed=0), SETTINGS)
    cancelled = request_cancel(track, _cancel_message("c9"))
    assert isinstance(cancelled, OrderTrack)
    failed = ActionState(action_id="c9", action_status=ActionStatus.FAILED)
    state = plan_state(plan, passed=2, node_states=[], edge_states=[], action_states=[failed])
    ended = reduce_track(cancelled, state, SETTINGS)
    assert (ended.status, ended.reason) == (
        OrderStatus.FINISHED,
        "cancelOrder came after the order had finished",
    )


def test_cancel_before_acceptance_ends_cancelled() -> None:
    """cancelOrder FAILED with noOrderToCancel on a vehicle without the order also ends it."""
    cancelled = request_cancel(_sent(_plan()), _cancel_message("c9"))
    assert isinstance(cancelled, OrderTrack)
    failed = ActionState(action_id="c9", action_status=ActionStatus.FAILED)
    state = make_state(action_states=[failed])
    assert reduce_track(cancelled, state, SETTINGS).status == OrderStatus.CANCELLED


def test_cancel_of_a_finished_order_is_refused() -> None:
    """A terminal order cannot be cancelled; the reason names its status."""
    plan = _plan(2)
    track = reduce_track(_sent(plan), plan_state(plan, passed=1), SETTINGS)
    assert track.status == OrderStatus.FINISHED
    assert request_cancel(track, _cancel_message()) == "order 'o1' is already FINISHED"


def test_unconfirmed_cancel_is_resent() -> None:
    """cancelOrder travels at QoS 0 too and is resent until a state lists it."""
    cancelled = request_cancel(_sent(_plan()), _cancel_message("c9"))
    assert isinstance(cancelled, OrderTrack)
    track, first = due_messages(cancelled, 0.0, SETTINGS, READY)
    track, second = due_messages(track, 1.0, SETTINGS, READY)
    assert first == second
    seen = ActionState(action_id="c9", action_status=ActionStatus.RUNNING)
    track = reduce_track(track, make_state(action_states=[seen]), SETTINGS)
    assert track.cancel is None


def test_the_whole_message_built_for_the_size_check_is_reused_only_when_it_is_the_first() -> None:
    """R57: the first message is the same whether or not the size check's all-released message
    is passed in; it is that very message only when the base reaches the message's last node."""
    plan = _plan()
    for max_nodes in (None, 3):
        whole = build_message(
            plan, first=0, release_end=plan.last_index, update_id=0, max_nodes=max_nodes
        )
        for granted in (None, 1, plan.last_index):
            plain = start_track(plan, SETTINGS, max_nodes=max_nodes, now=0, granted_end=granted)
            given = start_track(
                plan, SETTINGS, max_nodes=max_nodes, now=0, granted_end=granted, whole=whole
            )
            assert given.message == plain.message
            assert given.released_end == plain.released_end
            all_released = all(n.released for n in plain.message.nodes)
            assert (given.message is whole) == all_released
