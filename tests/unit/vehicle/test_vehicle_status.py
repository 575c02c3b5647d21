"""The robot's operating mode and safety chain, as its navigation stack reports them (§6.10.6
Table 1 and safetyState; R104, R105; 3.0 §6.6.6-§6.6.7, §7.8)."""

from __future__ import annotations

import functools
import json
from typing import Any

from jsonschema import Draft202012Validator, FormatChecker

from tests.spec_files import needs_official_schemas, official_schema
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import ActionStatus, BlockingType, EStop, OperatingMode, v3
from vda5050.testing import make_order, make_order_v3
from vda5050.topics import Topic
from vda_vehicle.instant import receive_instant_actions
from vda_vehicle.model import RobotMode, VehicleState
from vda_vehicle.order_executor import Accept, Reject, apply_order, decide_order
from vda_vehicle.reporter import build_state, state_body
from vda_vehicle.testing import (
    Recorder,
    action,
    instant,
    make_caps,
    make_runtime,
    make_runtime_v3,
    make_vehicle,
    run,
    run_until,
)
from vda_vehicle.vehicle_status import RULES_3_0, StackStatus, apply_status, status_of

CAPS = make_caps()
MANUAL = StackStatus(RobotMode.MANUAL)
AUTOMATIC = StackStatus(RobotMode.AUTOMATIC)
S = ActionStatus
Json = dict[str, Any]


def driving() -> VehicleState:
    """Under way from a to b of a → b → c, a pick waiting at c."""
    order = make_order(["a", "b", "c"], node_actions={"c": [action("pick", "pick")]})
    return run(apply_order(make_vehicle(), order, "new", CAPS), CAPS, 1)


def statuses(state: VehicleState) -> dict[str, ActionStatus]:
    return {record.action_id: record.status for record in state.actions}


def test_entering_manual_clears_the_order_where_the_vehicle_stands() -> None:
    """R105 (2.x Table 1), 3.0 §6.6.7: nodeStates and edgeStates empty, the waiting action
    FAILED, orderId, orderUpdateId and lastNodeId kept; the change calls for a state."""
    state = driving()
    assert state.driving
    assert state.nodes
    manual = apply_status(state, MANUAL, CAPS.catalog)
    assert (manual.nodes, manual.edges) == ((), ())
    assert statuses(manual) == {"pick": S.FAILED}
    assert (manual.order_id, manual.order_update_id) == (state.order_id, state.order_update_id)
    assert manual.last_node_id == state.last_node_id
    assert manual.operating_mode is RobotMode.MANUAL
    assert manual.revision > state.revision
    reported = build_state(manual, CAPS, maps=None)
    assert (reported.node_states, reported.edge_states) == ([], [])
    assert reported.operating_mode == "MANUAL"


def test_the_vehicle_does_not_drive_and_takes_no_order_in_manual() -> None:
    """§6.10.6 Table 1: master control does not drive a vehicle in MANUAL; the cleared order
    takes no update (a new order needs a new orderId), a new order is refused while the mode
    lasts, and one from the node the vehicle stands on is accepted once it is AUTOMATIC again."""
    manual = run(apply_status(driving(), MANUAL, CAPS.catalog), CAPS, 1)
    assert not manual.driving
    assert isinstance(decide_order(manual, make_order(["a"], order_id="order-2"), CAPS), Reject)

    order = make_order(["a", "b", "c"], released=2)
    at_b = run_until(
        apply_order(make_vehicle(), order, "new", CAPS),
        CAPS,
        lambda s: s.last_node_id == "b" and not s.driving,
    )
    cleared = apply_status(apply_status(at_b, MANUAL, CAPS.catalog), AUTOMATIC, CAPS.catalog)
    start = make_order(["b", "c"], order_id="order-2", positions=[(10.0, 0.0), (20.0, 0.0)])
    update = make_order(
        ["b", "c"], order_update_id=1, first_sequence_id=2, positions=[(10.0, 0.0), (20.0, 0.0)]
    )
    assert isinstance(decide_order(at_b, update, CAPS), Accept)
    assert isinstance(decide_order(cleared, update, CAPS), Reject)
    assert isinstance(decide_order(cleared, start, CAPS), Accept)


def test_which_mode_changes_clear_the_order() -> None:
    """Entering MANUAL, SERVICE or TEACHIN clears the order, and so does leaving MANUAL (2.x
    Table 1); SEMIAUTOMATIC keeps it, and so does an e-stop."""
    for mode in (RobotMode.MANUAL, RobotMode.SERVICE, RobotMode.TEACHIN):
        assert apply_status(driving(), StackStatus(mode), CAPS.catalog).nodes == ()
    semi = apply_status(driving(), StackStatus(RobotMode.SEMIAUTOMATIC), CAPS.catalog)
    assert semi.nodes
    assert semi.operating_mode is RobotMode.SEMIAUTOMATIC
    stopped = apply_status(driving(), StackStatus(e_stop=EStop.REMOTE), CAPS.catalog)
    assert stopped.nodes
    assert stopped.e_stop is EStop.REMOTE


def test_an_unchanged_status_is_no_event() -> None:
    """The stack may report its status as often as it likes: only a change is an event."""
    state = driving()
    assert apply_status(state, AUTOMATIC, CAPS.catalog) is state


def test_an_e_stop_holds_the_vehicle_and_it_drives_on_once_released() -> None:
    """R104: safetyState follows the robot's e-stop and protective field; the vehicle stands
    while the e-stop is active, keeps its order, and finishes it after the release."""
    state = driving()
    stopped = run(apply_status(state, StackStatus(e_stop=EStop.MANUAL), CAPS.catalog), CAPS, 2)
    assert not stopped.driving
    assert stopped.pose == run(stopped, CAPS, 1).pose
    reported = build_state(stopped, CAPS, maps=None)
    assert (reported.safety_state.e_stop, reported.safety_state.field_violation) == (
        EStop.MANUAL,
        False,
    )
    released = apply_status(stopped, StackStatus(field_violation=True), CAPS.catalog)
    assert build_state(released, CAPS, maps=None).safety_state.field_violation is True
    done = run(released, CAPS, 20)
    assert done.last_node_id == "c"
    assert done.nodes == ()


def test_the_fast_state_body_carries_the_safety_state() -> None:
    """The orjson state body says what the model says (e-stop and field violation)."""
    state = apply_status(
        driving(), StackStatus(e_stop=EStop.AUTOACK, field_violation=True), CAPS.catalog
    )
    body = json.loads(state_body(state, CAPS, maps=None).fields)
    assert body["safetyState"] == {"eStop": "AUTOACK", "fieldViolation": True}
    model = json.loads(build_state(state, CAPS, maps=None).model_dump_json(by_alias=True))
    assert body["safetyState"] == model["safetyState"]


def _published(sent: Recorder) -> list[Json]:
    return sent.of(Topic.STATE)


def test_the_runtime_reports_a_status_change_at_once() -> None:
    """The stack calls ``on_stack_status``: a state with the new operatingMode and the cleared
    order goes out without waiting for a tick (§6.10: the operatingMode changes)."""
    clock = FakeClock()
    vehicle, sent = make_runtime(clock)
    vehicle.handle_order("uagv/v2/acme/robot_0/order", encode(make_order(["a", "b"])))
    clock.advance(1.0)
    vehicle.tick(1.0, clock.monotonic())
    before = len(_published(sent))
    vehicle.on_stack_status(MANUAL)
    states = _published(sent)
    assert len(states) == before + 1
    assert states[-1]["operatingMode"] == "MANUAL"
    assert (states[-1]["nodeStates"], states[-1]["edgeStates"]) == ([], [])
    assert states[-1]["orderId"] == "order-1"
    vehicle.on_stack_status(MANUAL)
    assert len(_published(sent)) == before + 1


@functools.cache
def _schema(version: str, topic: str) -> Draft202012Validator:
    return Draft202012Validator(official_schema(version, topic), format_checker=FormatChecker())


@needs_official_schemas
def test_states_with_a_status_fit_the_official_schemas() -> None:
    """2.1 and 3.0 states with an e-stop, a field violation and MANUAL validate; 3.0 has no
    AUTOACK and reports it as a field violation (§7.8), MANUAL as MANUAL."""
    clock = FakeClock()
    vehicle, sent = make_runtime(clock)
    vehicle.on_stack_status(StackStatus(RobotMode.MANUAL, EStop.AUTOACK, True))
    (state,) = _published(sent)
    assert not list(_schema("2.1.0", "state").iter_errors(state))
    assert state["safetyState"] == {"eStop": "AUTOACK", "fieldViolation": True}

    vehicle3, sent3 = make_runtime_v3(clock)
    vehicle3.handle_order("vda5050/v3/acme/robot_0/order", encode(make_order_v3(["a", "b"])))
    clock.advance(1.0)
    vehicle3.on_stack_status(StackStatus(RobotMode.TEACHIN, EStop.AUTOACK))
    last = sent3.of(Topic.STATE)[-1]
    assert not list(_schema("3.0.0", "state").iter_errors(last))
    assert last["operatingMode"] == "TEACH_IN"
    assert last["lastNodeId"] == ""  # 3.0 T62; a 2.x vehicle keeps it
    assert last["safetyState"] == {"activeEmergencyStop": "NONE", "fieldViolation": True}
    assert (last["nodeStates"], last["edgeStates"]) == ([], [])
    clock.advance(1.0)
    vehicle3.on_stack_status(StackStatus(RobotMode.MANUAL, EStop.REMOTE))
    last = sent3.of(Topic.STATE)[-1]
    assert last["safetyState"] == {"activeEmergencyStop": "REMOTE", "fieldViolation": False}


def test_manual_during_a_cancel_stops_at_once_and_the_cancel_finishes() -> None:
    """A line-guided vehicle finishing its edge for a cancelOrder (R63) that is switched to
    MANUAL stops where it is; the cancel ends FINISHED once it stands."""
    state = receive_instant_actions(driving(), instant(action("cancelOrder", "cancel")), CAPS)
    assert [n.node_id for n in state.nodes] == ["b"]
    manual = run(apply_status(state, MANUAL, CAPS.catalog), CAPS, 0.5)
    assert (manual.nodes, manual.edges, manual.driving) == ((), (), False)
    assert statuses(manual)["cancel"] is S.FINISHED


def picking_at_b() -> VehicleState:
    """Standing on b of a → b → c, picking there (HARD, cannot be cancelled: §6.6.7 lets it run
    to its end), a drop waiting at c."""
    order = make_order(
        ["a", "b", "c"],
        node_actions={
            "b": [action("pick", "pick", BlockingType.HARD)],
            "c": [action("drop", "drop")],
        },
    )
    state = run_until(
        apply_order(make_vehicle(), order, "new", CAPS),
        CAPS,
        lambda s: statuses(s)["pick"] is S.RUNNING,
    )
    assert state.last_node_id == "b"
    return state


def test_a_3_0_robot_reports_manual_only_once_its_uncancellable_action_ended() -> None:
    """3.0 §6.6.7 (T64): while an order action that cannot be cancelled runs, MANUAL is not
    reported and nodeStates/edgeStates stay; the robot stands, the waiting drop FAILS at once,
    and the order is cleared, MANUAL reported, once the pick has FINISHED. A 2.x vehicle
    reports MANUAL and clears the order at once (2.x Table 1), the pick RUNNING to its end."""
    state = picking_at_b()
    entering = apply_status(state, MANUAL, CAPS.catalog, RULES_3_0)
    assert entering.operating_mode is RobotMode.AUTOMATIC
    assert [n.node_id for n in entering.nodes] == ["c"]
    assert statuses(entering) == {"pick": S.RUNNING, "drop": S.FAILED}
    assert isinstance(decide_order(entering, make_order(["b"], order_id="order-2"), CAPS), Reject)
    update = make_order(["b", "c"], order_update_id=1, first_sequence_id=2)
    assert isinstance(decide_order(entering, update, CAPS), Reject)  # the order is being cleared
    assert status_of(entering) == MANUAL

    picked = run_until(entering, CAPS, lambda s: statuses(s)["pick"] is S.FINISHED)
    assert picked.operating_mode is RobotMode.MANUAL
    assert (picked.nodes, picked.edges, picked.pending_mode) == ((), (), None)
    assert picked.pose == state.pose  # it never drove on towards c
    assert picked.last_node_id == "b"  # MANUAL keeps it (T62)
    assert picked.revision > entering.revision

    at_once = apply_status(state, MANUAL, CAPS.catalog)  # 2.x
    assert (at_once.operating_mode, at_once.nodes) == (RobotMode.MANUAL, ())
    assert statuses(at_once) == {"pick": S.RUNNING, "drop": S.FAILED}


def test_a_mode_changed_again_while_the_order_is_cleared_is_the_one_reported() -> None:
    """The clearing goes on to its end; the robot's newest mode is reported with it (T62: a
    SERVICE entered meanwhile forgets lastNodeId), and an e-stop meanwhile is reported at once."""
    entering = apply_status(picking_at_b(), MANUAL, CAPS.catalog, RULES_3_0)
    service = apply_status(entering, StackStatus(RobotMode.SERVICE), CAPS.catalog, RULES_3_0)
    stopped = apply_status(
        service, StackStatus(RobotMode.SERVICE, EStop.MANUAL), CAPS.catalog, RULES_3_0
    )
    assert stopped.e_stop is EStop.MANUAL
    assert stopped.operating_mode is RobotMode.AUTOMATIC  # not yet
    done = run_until(stopped, CAPS, lambda s: s.pending_mode is None)
    assert (done.operating_mode, done.last_node_id, done.nodes) == (RobotMode.SERVICE, "", ())


def test_intervened_keeps_the_order_of_a_3_0_robot_and_it_goes_on_after() -> None:
    """3.0 Table 10 (T63): in INTERVENED an operator steers; the order stays, the robot does
    not drive it, takes an update for later (Table 11), and finishes it once AUTOMATIC again.
    A 2.x vehicle has no INTERVENED: it reports MANUAL, which clears the order."""
    state = driving()
    intervened = run(
        apply_status(state, StackStatus(RobotMode.INTERVENED), CAPS.catalog, RULES_3_0), CAPS, 2
    )
    assert intervened.operating_mode is RobotMode.INTERVENED
    assert intervened.nodes
    assert not intervened.driving
    assert intervened.pose == run(intervened, CAPS, 1).pose
    update = make_order(
        ["c", "d"], order_update_id=1, first_sequence_id=4, positions=[(20.0, 0.0), (30.0, 0.0)]
    )
    assert isinstance(decide_order(intervened, update, CAPS), Accept)
    again = apply_status(intervened, AUTOMATIC, CAPS.catalog, RULES_3_0)
    done = run_until(again, CAPS, lambda s: statuses(s)["pick"] is S.FINISHED)
    assert (done.last_node_id, done.nodes) == ("c", ())

    two = apply_status(state, StackStatus(RobotMode.INTERVENED), CAPS.catalog)
    assert (two.operating_mode, two.nodes) == (RobotMode.MANUAL, ())


def test_startup_clears_the_order_and_takes_none() -> None:
    """3.0 Tables 10-11: STARTUP clears the order, forgets lastNodeId (T62) and takes no order
    (T26); a 2.x vehicle reports it as SERVICE, which takes no order either. The stack may name
    the mode in either version's spelling."""
    state = driving()
    startup = apply_status(state, StackStatus(RobotMode("STARTUP")), CAPS.catalog, RULES_3_0)
    assert (startup.operating_mode, startup.nodes, startup.last_node_id) == (
        RobotMode.STARTUP,
        (),
        "",
    )
    fresh = make_order(["a"], order_id="order-2")
    assert isinstance(decide_order(startup, fresh, CAPS), Reject)
    two = apply_status(state, StackStatus(RobotMode.STARTUP), CAPS.catalog)
    assert (two.operating_mode, two.last_node_id) == (RobotMode.SERVICE, state.last_node_id)
    assert RobotMode(v3.OperatingMode.TEACH_IN) is RobotMode.TEACHIN
    assert RobotMode(OperatingMode.SEMIAUTOMATIC) is RobotMode.SEMIAUTOMATIC


@needs_official_schemas
def test_3_0_modes_on_the_wire() -> None:
    """A 3.0 vehicle publishes INTERVENED and STARTUP (official 3.0 schema); while a clearing
    waits for an uncancellable action (T64) its states say the mode before, with the nodes."""
    clock = FakeClock()
    vehicle3, sent3 = make_runtime_v3(clock)
    vehicle3.handle_order("vda5050/v3/acme/robot_0/order", encode(make_order_v3(["a", "b"])))
    for mode in ("INTERVENED", "AUTOMATIC", "STARTUP"):
        clock.advance(1.0)
        vehicle3.on_stack_status(StackStatus(RobotMode(mode)))
        last = sent3.of(Topic.STATE)[-1]
        assert not list(_schema("3.0.0", "state").iter_errors(last))
        assert last["operatingMode"] == mode
    assert (last["nodeStates"], last["lastNodeId"]) == ([], "")
