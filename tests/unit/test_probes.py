"""``vda-probe``'s steps (docs/inspect.md, *vda-probe*): what it sends a vehicle and how it
judges the states that follow, on crafted states."""

from __future__ import annotations

import math
from typing import Any

from vda5050.models import (
    ActionState,
    ActionStatus,
    AgvPosition,
    EdgeState,
    Error,
    ErrorLevel,
    ErrorReference,
    InstantActions,
    NodeState,
    OperatingMode,
    Order,
    State,
)
from vda5050.testing import make_state
from vda_inspect.probe_judges import (
    Outcome,
    Seen,
    cancelled,
    carries,
    error_key,
    rejected,
    stays,
    unchanged,
)
from vda_inspect.probes import (
    FAR_M,
    TEMPORARY_NODE,
    ProbePlan,
    Start,
    start_of,
    trigger_parameters,
    unsupported_field,
)
from vda_master.testing import ALL_FIELDS, make_factsheet

START = Start("n7", 3.0, 4.0, math.pi / 2, "hall")
O1 = "vda-probe-abc-1"


def _at(order_id: str, update_id: int, horizon: list[str] | None = None, **fields: Any) -> State:
    """A state holding ``order_id`` at its first node with ``horizon`` unreleased ahead."""
    names = horizon or []
    return make_state(
        order_id=order_id,
        order_update_id=update_id,
        last_node_id="n7",
        last_node_sequence_id=0,
        node_states=[
            NodeState(node_id=n, sequence_id=2 * (i + 1), released=False)
            for i, n in enumerate(names)
        ],
        edge_states=[
            EdgeState(edge_id=f"e{i}", sequence_id=2 * i + 1, released=False)
            for i in range(len(names))
        ],
        **fields,
    )


def _error(
    order_id: str,
    update_id: int | None,
    error_type: str = "orderUpdateError",
    description: str | None = None,
) -> Error:
    references = [ErrorReference(reference_key="orderId", reference_value=order_id)]
    if update_id is not None:
        references.append(
            ErrorReference(reference_key="orderUpdateId", reference_value=str(update_id))
        )
    return Error(
        error_type=error_type,
        error_references=references,
        error_level=ErrorLevel.WARNING,
        error_description=description,
    )


def _seen(*states: State, before: frozenset[str] = frozenset(), factsheets: int = 0) -> Seen:
    return Seen(list(states), before, factsheets)


def test_a_vehicle_is_probed_only_when_idle_automatic_and_localized() -> None:
    pose = AgvPosition(x=3.0, y=4.0, theta=0.5, map_id="hall", position_initialized=True)
    assert start_of(make_state(last_node_id="n7", agv_position=pose)) == Start(
        "n7", 3.0, 4.0, 0.5, "hall"
    )
    fresh = start_of(make_state(last_node_id="", agv_position=pose))
    assert isinstance(fresh, Start)
    assert fresh.node_id == TEMPORARY_NODE  # R38: a temporary first node where it stands
    manual = make_state(agv_position=pose, operating_mode=OperatingMode.MANUAL)
    assert "MANUAL" in str(start_of(manual))
    busy = make_state(
        agv_position=pose,
        node_states=[NodeState(node_id="x", sequence_id=2, released=True)],
        order_id="theirs",
    )
    assert "'theirs'" in str(start_of(busy))
    assert "agvPosition" in str(start_of(make_state()))


def test_the_plan_releases_nothing_but_where_the_vehicle_stands() -> None:
    """Safety: a conforming vehicle does not move. Released elsewhere are only first nodes the
    vehicle must reject: R37's 5 m ahead, R47's and R49's on the horizon 1 m away."""
    plan = ProbePlan(START, "abc", maps_reported=True, max_order_nodes=12)
    orders = [s.message for s in plan.steps if isinstance(s.message, Order)]
    assert len(orders) == 16  # R35 and R36 too
    for order in orders:
        for node in order.nodes:
            position = node.node_position
            assert position is not None
            away = math.hypot(position.x - START.x, position.y - START.y)
            if position.map_id != "hall":  # R35: where it stands, on a map it does not hold
                assert away < 1e-9
                continue
            if node.node_id == "vda-probe-far":  # R37: to be rejected, never reached
                assert math.isclose(away, FAR_M)
            elif node.released and node.sequence_id == 0:
                assert away < 1e-9, node
            else:  # the horizon, and R47's update that begins on it (to be rejected)
                assert math.isclose(away, 1.0)
                assert not node.released or order.order_update_id in (2, 7)
        assert all(e.released is False for e in order.edges)
    ahead = orders[0].nodes[1].node_position
    assert ahead is not None
    assert math.isclose(ahead.x, 3.0, abs_tol=1e-9)  # theta pi/2: ahead is +y
    assert math.isclose(ahead.y, 5.0)
    ids = {order.order_id for order in orders}
    assert ids == {f"vda-probe-abc-{n}" for n in range(1, 9)}
    (over,) = [o for o in orders if len(o.nodes) == 13]  # R36: one node over the limit of 12
    assert len(over.edges) == 12
    bare = ProbePlan(START, "abc")  # no maps listed, no limits known: neither is probed
    assert len([s for s in bare.steps if isinstance(s.message, Order)]) == 14


def test_an_order_is_carried_when_its_horizon_is_listed_as_sent() -> None:
    judge = carries(O1, 1, [("vda-probe-left", 2, False)])
    assert judge(_seen(_at(O1, 0, ["vda-probe-ahead"]))) is None  # not yet
    passed = judge(_seen(_at(O1, 1, ["vda-probe-left"])))
    assert passed is not None
    assert passed.outcome is Outcome.PASS
    old_horizon_kept = _at(O1, 1, ["vda-probe-left", "vda-probe-ahead"])
    assert judge(_seen(old_horizon_kept)) is None  # R52 not met: the step runs out of time
    refused = judge(_seen(_at(O1, 0, ["vda-probe-ahead"], errors=[_error(O1, 1)])))
    assert refused is not None
    assert refused.outcome is Outcome.FAIL


def test_a_rejection_needs_an_error_naming_the_order_and_the_order_going_on() -> None:
    judge = rejected(O1, 0, (O1, 1))
    holding = _at(O1, 1, ["vda-probe-left"])
    assert judge(_seen(holding)) is None  # no error yet
    full = judge(_seen(_at(O1, 1, ["vda-probe-left"], errors=[_error(O1, 0)])))
    assert full is not None
    assert full.outcome is Outcome.PASS
    partial = judge(_seen(_at(O1, 1, ["vda-probe-left"], errors=[_error(O1, None)])))
    assert partial is not None
    assert partial.outcome is Outcome.WARN  # R30 wants the orderUpdateId referenced too
    old = _error(O1, 0)

    stale = _seen(_at(O1, 1, errors=[old]), before=frozenset({error_key(old)}))
    assert judge(stale) is None  # an error left from before is not this step's answer
    accepted = judge(_seen(_at(O1, 0, ["vda-probe-ahead"])))
    assert accepted is not None
    assert accepted.outcome is Outcome.FAIL
    other = rejected("vda-probe-abc-2", 0, (O1, 1))
    took_it = other(_seen(_at("vda-probe-abc-2", 0, ["vda-probe-ahead"])))
    assert took_it is not None
    assert took_it.outcome is Outcome.FAIL  # R40: a new orderId while busy was taken


def test_an_unknown_action_must_not_get_an_action_state() -> None:
    judge = rejected("o4", 0, (O1, None), absent_action="o4-unknown")
    listed = _at(
        O1,
        5,
        action_states=[ActionState(action_id="o4-unknown", action_status=ActionStatus.FAILED)],
    )
    verdict = judge(_seen(listed))
    assert verdict is not None
    assert verdict.outcome is Outcome.FAIL  # R33


def test_the_horizon_is_not_driven_and_a_resend_changes_nothing() -> None:
    assert stays(O1)(_seen(_at(O1, 0, ["a"]))) is None
    drove = stays(O1)(_seen(_at(O1, 0, ["a"], driving=True)))
    assert drove is not None
    assert drove.outcome is Outcome.FAIL
    assert unchanged(O1, 0)(_seen(_at(O1, 0, ["a"]))) is None
    erred = unchanged(O1, 0)(_seen(_at(O1, 0, ["a"], errors=[_error(O1, 0)])))
    assert erred is not None
    assert erred.outcome is Outcome.FAIL  # R45: silently


def test_a_cancel_ends_finished_with_nothing_listed() -> None:
    judge = cancelled(O1, "c")

    def cancel(status: ActionStatus, horizon: list[str]) -> State:
        states = [ActionState(action_id="c", action_type="cancelOrder", action_status=status)]
        return _at(O1, 5, horizon, action_states=states)

    assert judge(_seen(cancel(ActionStatus.RUNNING, ["a"]))) is None
    done = judge(_seen(cancel(ActionStatus.FINISHED, [])))
    assert done is not None
    assert done.outcome is Outcome.PASS
    listed = judge(_seen(cancel(ActionStatus.FINISHED, ["a"])))
    assert listed is not None
    assert listed.outcome is Outcome.FAIL  # R62


def test_an_optional_field_the_factsheet_does_not_list_is_probed_and_named() -> None:
    factsheet = make_factsheet(supported=[f for f in ALL_FIELDS if f != "order.edges.direction"])
    listed = {p.parameter for p in factsheet.protocol_features.optional_parameters}
    path = unsupported_field(factsheet)
    assert path is not None
    assert path not in listed
    plan = ProbePlan(START, "abc", unsupported_field=path)
    (step,) = [s for s in plan.steps if "R32" in s.rules]
    assert isinstance(step.message, Order)
    (edge,) = step.message.edges
    assert edge.released is False  # on the horizon edge: nothing is driven
    name = path.rsplit(".", 1)[-1]
    order_id = step.message.order_id
    named = _at(O1, 5, errors=[_error(order_id, 0, "orderError", f"{name} is not supported")])
    silent = _at(O1, 5, errors=[_error(order_id, 0, "orderError", "not supported")])
    assert (verdict := step.judge(_seen(named))) is not None
    assert verdict.outcome is Outcome.PASS
    assert (vague := step.judge(_seen(silent))) is not None
    assert vague.outcome is Outcome.WARN  # R32: the error names the field


def test_a_trigger_held_where_it_stands_blocks_a_new_order_and_fails_on_cancel() -> None:
    offered = {
        "actionType": "waitForTrigger",
        "actionScopes": ["NODE"],
        "actionParameters": [
            {"key": "triggerType", "valueDataType": "STRING", "isOptional": False},
            {"key": "timeoutS", "valueDataType": "FLOAT", "isOptional": True},
        ],
    }
    assert trigger_parameters(make_factsheet(actions=[offered])) == {"triggerType": "vda-probe"}
    assert trigger_parameters(make_factsheet()) is None  # not offered on nodes
    plan = ProbePlan(START, "abc", trigger_parameters={"triggerType": "vda-probe"})
    held, stitched, refused, cancel = plan.steps[-4:]  # the trigger block comes last
    assert isinstance(held.message, Order)
    (node,) = held.message.nodes
    (wait,) = node.actions
    assert (wait.action_type, node.released) == ("waitForTrigger", True)
    assert [(p.key, p.value) for p in wait.action_parameters or ()] == [
        ("triggerType", "vda-probe")
    ]
    o10 = held.message.order_id

    def listing(status: ActionStatus, **fields: Any) -> State:
        actions = [ActionState(action_id=wait.action_id, action_status=status)]
        return _at(o10, 0, action_states=actions, **fields)

    assert (verdict := held.judge(_seen(listing(ActionStatus.RUNNING)))) is not None
    assert verdict.outcome is Outcome.PASS
    assert (early := held.judge(_seen(listing(ActionStatus.FINISHED)))) is not None
    assert early.outcome is Outcome.FAIL  # it finished with no trigger
    assert stitched.rules == ("R51", "R46")
    assert isinstance(stitched.message, Order)
    assert stitched.message.order_id == o10
    assert stitched.message.order_update_id == 1
    assert stitched.message.nodes[0] == node  # the stitching node as first sent
    assert [n.released for n in stitched.message.nodes] == [True, False]
    assert stitched.message.edges[0].released is False

    def updated(*statuses: ActionStatus) -> State:
        actions = [ActionState(action_id=wait.action_id, action_status=s) for s in statuses]
        return _at(o10, 1, ["vda-probe-ahead"], action_states=actions)

    kept = stitched.judge(_seen(updated(ActionStatus.RUNNING)))
    assert kept is not None
    assert kept.outcome is Outcome.PASS
    for rerun in [  # vda-5050-lib 1.4's AGV adds the stitching node's actions again
        updated(ActionStatus.RUNNING, ActionStatus.WAITING),
        updated(ActionStatus.WAITING),  # started again
        updated(),  # dropped
    ]:
        verdict = stitched.judge(_seen(rerun))
        assert verdict is not None
        assert verdict.outcome is Outcome.FAIL
        assert "R51" in verdict.text
    assert stitched.judge(_seen(listing(ActionStatus.RUNNING))) is None  # update 0: not yet
    assert refused.rules == ("R41", "R30")
    assert isinstance(cancel.message, InstantActions)
    (sent,) = cancel.message.actions
    ended = [
        ActionState(action_id=wait.action_id, action_status=ActionStatus.FINISHED),
        ActionState(action_id=sent.action_id, action_status=ActionStatus.FINISHED),
    ]
    wrong = cancel.judge(_seen(_at(o10, 0, action_states=ended)))
    assert wrong is not None
    assert wrong.outcome is Outcome.FAIL  # R82: the trigger ends FAILED
    ended[0] = ActionState(action_id=wait.action_id, action_status=ActionStatus.FAILED)
    right = cancel.judge(_seen(_at(o10, 0, action_states=ended)))
    assert right is not None
    assert right.outcome is Outcome.PASS
    assert [s for s in ProbePlan(START, "abc").steps if "R41" in s.rules] == []  # not offered


def test_a_differential_drive_is_asked_to_drive_sideways_on_the_horizon_only() -> None:
    """R34: only for a factsheet that says DIFF; the edge asking pi/2 is not released."""
    assert [s for s in ProbePlan(START, "abc").steps if "R34" in s.rules] == []
    (step,) = [s for s in ProbePlan(START, "abc", differential=True).steps if "R34" in s.rules]
    assert isinstance(step.message, Order)
    (edge,) = step.message.edges
    assert (edge.orientation, edge.released) == (math.pi / 2, False)
    assert [n.released for n in step.message.nodes] == [True, False]
    error = Error(
        error_type="orderError",
        error_level=ErrorLevel.WARNING,
        error_description="edge cannot be held",
        error_references=[
            ErrorReference(reference_key="orderId", reference_value=step.message.order_id),
            ErrorReference(reference_key="orderUpdateId", reference_value="0"),
        ],
    )
    verdict = step.judge(_seen(_at(O1, 0, errors=[error])))
    assert verdict is not None
    assert verdict.outcome is Outcome.PASS
    taken = step.judge(_seen(_at(step.message.order_id, 0, ["vda-probe-ahead"])))
    assert taken is not None
    assert taken.outcome is Outcome.FAIL
