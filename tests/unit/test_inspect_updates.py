"""How master control updates an order and what it sends in which operating mode (R55-R58,
R84; docs/inspect.md), judged by ``vda-inspect`` on crafted traffic."""

from __future__ import annotations

from typing import Any

from vda5050.codec import encode
from vda5050.models import OperatingMode, Order, v3
from vda5050.testing import (
    make_instant_action_v3,
    make_instant_actions_v3,
    make_order,
    make_order_v3,
    make_state,
    make_state_v3,
    state_at,
)
from vda_inspect.progress import OrderProgress
from vda_inspect.rules import Inspector
from vda_inspect.severity import Severity
from vda_inspect.updates import UpdateDiscipline
from vda_vehicle.testing import action, instant

ORDER = make_order(["a", "b", "c", "d"], released=3)  # a-b-c released, d on the horizon
V = Severity.VIOLATION
N = Severity.NOTICE


def _sent(discipline: UpdateDiscipline, order: Order | v3.Order) -> list[tuple[str, Severity]]:
    return [(rule, severity) for rule, _, severity in discipline.sent(order)]


def _update(nodes: list[str], update_id: int, first: int, **fields: Any) -> Order:
    return make_order(nodes, order_update_id=update_id, first_sequence_id=first, **fields)


def test_updates_that_stitch_onto_the_decision_point_are_fine() -> None:
    discipline = UpdateDiscipline()
    positions = [(20.0, 0.0), (30.0, 0.0), (40.0, 0.0)]
    assert _sent(discipline, ORDER) == []
    assert _sent(discipline, ORDER) == []  # a resend of the same message
    assert _sent(discipline, _update(["c", "d", "e"], 1, 4, positions=positions)) == []
    # update 2 skips nothing and stitches onto e, the last node update 1 released
    assert _sent(discipline, _update(["e", "f"], 2, 8, positions=[*positions[2:], (50, 0)])) == []
    # a new order starts afresh at update 0
    assert _sent(discipline, make_order(["f", "g"], order_id="order-2")) == []


def test_update_ids_that_repeat_with_other_content_or_go_back_are_r57() -> None:
    discipline = UpdateDiscipline()
    positions = [(20.0, 0.0), (30.0, 0.0), (40.0, 0.0)]
    discipline.sent(ORDER)
    discipline.sent(_update(["c", "d", "e"], 1, 4, positions=positions))
    changed = _update(["c", "d", "x"], 1, 4, positions=positions)
    assert _sent(discipline, changed) == [("R57", V)]  # the vehicle drops it silently (R45)
    assert _sent(discipline, ORDER) == [("R57", N)]  # update 0 again, unchanged: odd only
    back = make_order(["a", "b", "c", "d"], released=2)  # update 0 again, but changed
    assert _sent(discipline, back) == [("R57", V)]
    # a new orderId after an earlier one is expected to begin at 0
    assert _sent(discipline, make_order(["a", "b"], order_id="order-2", order_update_id=3)) == [
        ("R57", N)
    ]


def test_an_update_that_does_not_start_at_the_decision_point_is_r56() -> None:
    discipline = UpdateDiscipline()
    discipline.sent(ORDER)
    # starts at b, before the decision point c: re-sends released base
    early = _update(["b", "c", "d"], 1, 2, positions=[(10.0, 0.0), (20.0, 0.0), (30.0, 0.0)])
    (problem,) = discipline.sent(early)
    assert (problem[0], problem[2]) == ("R56", V)
    assert "'c' (sequenceId 4)" in problem[1]
    # with an update the listener did not hear in between, only a notice
    later = UpdateDiscipline()
    later.sent(ORDER)
    assert _sent(later, _update(["e", "f"], 3, 8, positions=[(40.0, 0.0), (50.0, 0.0)])) == [
        ("R56", N)
    ]


def test_a_stitching_node_resent_with_other_content_is_r58() -> None:
    discipline = UpdateDiscipline()
    discipline.sent(ORDER)
    moved = _update(["c", "d"], 1, 4, positions=[(21.0, 0.0), (30.0, 0.0)])
    assert _sent(discipline, moved) == [("R58", V)]
    with_action = _update(
        ["c", "d"],
        1,
        4,
        positions=[(20.0, 0.0), (30.0, 0.0)],
        node_actions={"c": [action("beep", "c-beep")]},
    )
    fresh = UpdateDiscipline()
    fresh.sent(ORDER)
    assert _sent(fresh, with_action) == [("R58", V)]  # actions added at the decision point
    # 3.0 alike
    three = UpdateDiscipline()
    three.sent(make_order_v3(["a", "b", "c"], released=2))
    stitched = make_order_v3(  # a new horizon only: b stays the decision point
        ["b", "c"],
        order_update_id=1,
        first_sequence_id=2,
        released=1,
        positions=[(10.0, 0.0), (20.0, 0.0)],
    )
    assert _sent(three, stitched) == []
    shifted = make_order_v3(
        ["b", "c"],
        order_update_id=2,
        first_sequence_id=2,
        released=1,
        positions=[(11.0, 0.0), (20.0, 0.0)],
    )
    assert _sent(three, shifted) == [("R58", V)]


def test_a_vehicle_that_reports_a_horizon_node_traversed_is_r55() -> None:
    progress = OrderProgress()
    progress.order(ORDER)
    at_base_end = [rule for rule, _, _ in progress.state(state_at(ORDER, 2))]
    assert at_base_end == []
    beyond = progress.state(state_at(ORDER, 3))
    assert [(rule, severity) for rule, _, severity in beyond] == [("R55", V)]
    assert "'d' (sequenceId 6)" in beyond[0][1]


ROBOT = "uagv/v2/acme/robot_0"


def _publish(inspector: Inspector, topic: str, message: Any, now: float) -> list[str]:
    found = inspector.observe(f"{ROBOT}/{topic}", encode(message), qos=0, retain=False, now=now)
    return [f"{f.rule}:{f.severity.value}" for f in found]


def test_orders_and_actions_to_a_vehicle_in_manual_are_r84_after_a_grace() -> None:
    inspector = Inspector()
    manual = make_state(header_id=0, operating_mode=OperatingMode.MANUAL)
    _publish(inspector, "state", manual, now=0.0)
    # sent before the master can have read that state: not held against it
    assert _publish(inspector, "order", ORDER, now=0.2) == []
    assert _publish(inspector, "order", make_order(["a"], order_id="o2", header_id=1), 1.0) == [
        "R84:violation"
    ]
    pause = instant(action("startPause", "p1"), header_id=0)
    assert _publish(inspector, "instantActions", pause, now=1.0) == ["R84:violation"]
    ask = instant(action("stateRequest", "s1"), header_id=1)
    assert _publish(inspector, "instantActions", ask, now=1.1) == []  # information only (2.x)
    automatic = make_state(header_id=1, operating_mode=OperatingMode.AUTOMATIC)
    _publish(inspector, "state", automatic, now=2.0)
    assert _publish(inspector, "order", make_order(["a"], order_id="o3", header_id=2), 3.0) == []


def test_a_3_0_robot_intervened_takes_orders_and_only_cancel_order() -> None:
    inspector = Inspector()
    robot = "uagv/v3/acme/robot_0"

    def publish(topic: str, message: Any, now: float) -> list[str]:
        found = inspector.observe(f"{robot}/{topic}", encode(message), qos=0, retain=False, now=now)
        return [f"{f.rule}:{f.severity.value}" for f in found]

    publish("state", make_state_v3(header_id=0, operating_mode="INTERVENED"), 0.0)
    assert publish("order", make_order_v3(["a", "b"]), 1.0) == []
    cancel = make_instant_actions_v3(make_instant_action_v3("cancelOrder", "c1"), header_id=0)
    assert publish("instantActions", cancel, 1.0) == []
    pause = make_instant_actions_v3(make_instant_action_v3("startPause", "p1"), header_id=1)
    assert publish("instantActions", pause, 1.1) == ["R84:violation"]
    publish("state", make_state_v3(header_id=1, operating_mode="STARTUP"), 2.0)
    ask = make_instant_actions_v3(make_instant_action_v3("factsheetRequest", "f1"), header_id=2)
    assert publish("instantActions", ask, 3.0) == ["R84:violation"]  # 3.0: nothing in STARTUP
    assert publish("order", make_order_v3(["a"], order_id="o2", header_id=1), 3.0) == [
        "R84:violation"
    ]
