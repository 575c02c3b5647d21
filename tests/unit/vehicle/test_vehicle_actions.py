"""Action state machines (§6.11 Figure 16), blocking (§6.12) and the predefined actions (§6.8.2)."""

from __future__ import annotations

import itertools
from dataclasses import replace

import pytest

from vda5050.models import Action, ActionScope, ActionStatus, BlockingType, Load
from vda5050.testing import make_order
from vda_vehicle.action_catalog import default_catalog, with_durations
from vda_vehicle.actions import TRANSITIONS, moved, startable
from vda_vehicle.instant import receive_instant_actions
from vda_vehicle.limits import ProtocolLimits
from vda_vehicle.model import ActionRecord, VehicleState
from vda_vehicle.order_executor import apply_order
from vda_vehicle.testing import action, instant, make_caps, make_vehicle, run

CAPS = make_caps()
S = ActionStatus
NONE, SOFT, HARD = BlockingType.NONE, BlockingType.SOFT, BlockingType.HARD


def statuses(state: VehicleState) -> dict[str, ActionStatus]:
    return {record.action_id: record.status for record in state.actions}


def send(state: VehicleState, *actions: Action) -> VehicleState:
    return receive_instant_actions(state, instant(*actions), CAPS)


def record(
    action_id: str, blocking: BlockingType, status: ActionStatus = S.WAITING
) -> ActionRecord:
    return ActionRecord(
        action("detectObject", action_id, blocking), ActionScope.NODE, 2, status, triggered=True
    )


def test_transition_table_matches_figure_16() -> None:
    """R69: only Figure 16 transitions are allowed; FINISHED and FAILED are final."""
    allowed = {
        (S.WAITING, S.INITIALIZING), (S.WAITING, S.RUNNING), (S.WAITING, S.FAILED),
        (S.INITIALIZING, S.RUNNING), (S.INITIALIZING, S.PAUSED), (S.INITIALIZING, S.FAILED),
        (S.RUNNING, S.PAUSED), (S.RUNNING, S.FINISHED), (S.RUNNING, S.FAILED),
        (S.PAUSED, S.RUNNING), (S.PAUSED, S.INITIALIZING), (S.PAUSED, S.FAILED),
    }  # fmt: skip
    for source, target in itertools.product(S, S):
        base = record("x", NONE, source)
        if (source, target) in allowed:
            assert moved(base, target).status is target
        else:
            with pytest.raises(ValueError, match="not allowed"):
                moved(base, target)
    assert TRANSITIONS[S.FINISHED] == TRANSITIONS[S.FAILED] == frozenset()


def test_none_and_soft_actions_start_together() -> None:
    """R75, §6.12: NONE and SOFT actions of one list form a parallel set, in list order."""
    group = [record("a", NONE), record("b", SOFT), record("c", NONE)]
    assert [r.action_id for r in startable(group)] == ["a", "b", "c"]


def test_hard_action_waits_for_earlier_actions_and_blocks_later_ones() -> None:
    """R74: a HARD action runs alone: after the parallel set before it, before what follows."""
    group = [record("a", NONE, S.RUNNING), record("h", HARD), record("c", NONE)]
    assert startable(group) == []
    group[0] = record("a", NONE, S.FINISHED)
    assert [r.action_id for r in startable(group)] == ["h"]
    group[1] = record("h", HARD, S.RUNNING)
    assert startable(group) == []
    group[1] = record("h", HARD, S.FINISHED)
    assert [r.action_id for r in startable(group)] == ["c"]


def test_hard_then_parallel_set_on_a_node() -> None:
    """R74: on a node, HARD runs alone, then the NONE action after it starts."""
    order = make_order(
        ["a"],
        node_actions={"a": [action("finePositioning", "h", HARD), action("detectObject", "n")]},
    )
    state = apply_order(make_vehicle(), order, "new", CAPS)
    assert statuses(state) == {"h": S.RUNNING, "n": S.WAITING}
    state = run(state, CAPS, 2.1)
    assert statuses(state) == {"h": S.FINISHED, "n": S.RUNNING}


def test_soft_node_action_stops_driving_none_does_not() -> None:
    """R73, R75: a SOFT action holds the vehicle; a NONE action runs while it drives."""
    soft = make_order(["a", "b"], node_actions={"a": [action("detectObject", "s", SOFT)]})
    state = run(apply_order(make_vehicle(), soft, "new", CAPS), CAPS, 0.5)
    assert statuses(state)["s"] is S.RUNNING
    assert not state.driving
    none = make_order(["a", "b"], node_actions={"a": [action("detectObject", "n", NONE)]})
    state = run(apply_order(make_vehicle(), none, "new", CAPS), CAPS, 0.5)
    assert statuses(state)["n"] is S.RUNNING
    assert state.driving


def test_vehicle_stops_at_node_with_blocking_action() -> None:
    """R73: the vehicle stops on a node whose SOFT/HARD actions are pending, then goes on."""
    order = make_order(["a", "b", "c"], node_actions={"b": [action("finePositioning", "fp", HARD)]})
    state = run(apply_order(make_vehicle(), order, "new", CAPS), CAPS, 7.5)
    assert state.last_node_id == "b"
    assert (state.pose.x, state.driving) == (10.0, False)
    assert statuses(state)["fp"] is S.RUNNING
    state = run(state, CAPS, 10)
    assert state.last_node_id == "c"


def test_edge_action_runs_on_the_edge_and_ends_on_leaving_it() -> None:
    """R71: an edge action starts when the edge is entered and has ended at the end node."""
    order = make_order(
        ["a", "b"], edge_actions={"a-b": [action("waitForTrigger", "w", triggerType="x")]}
    )
    specs = make_caps().catalog
    edge_wait = replace(specs["waitForTrigger"], scopes=frozenset({ActionScope.EDGE}))
    caps = make_caps(catalog={**specs, "waitForTrigger": edge_wait})
    state = apply_order(make_vehicle(), order, "new", caps)
    assert statuses(state)["w"] is S.RUNNING
    state = run(state, caps, 10)
    assert state.last_node_id == "b"
    assert statuses(state)["w"] is S.FINISHED


def test_initializing_before_running_where_the_action_prepares() -> None:
    """§6.11: pick prepares (INITIALIZING), then runs, then finishes with the load (R81)."""
    pick = action("pick", "p", HARD, stationType="rack", loadType="EPAL", loadId="L1", lhd="front")
    state = apply_order(make_vehicle(), make_order(["a"], node_actions={"a": [pick]}), "new", CAPS)
    assert statuses(state)["p"] is S.INITIALIZING
    state = run(state, CAPS, 1.5)
    assert statuses(state)["p"] is S.RUNNING
    state = run(state, CAPS, 3)
    assert statuses(state)["p"] is S.FINISHED
    assert state.loads == (Load(load_id="L1", load_type="EPAL", load_position="front"),)


def test_drop_removes_the_load_and_fails_without_one() -> None:
    """R81: drop FINISHED removes the load from loads; with nothing loaded it FAILS."""
    loaded = make_vehicle(loads=(Load(load_id="L1", load_position="front"),))
    drop = make_order(["a"], node_actions={"a": [action("drop", "d", HARD, lhd="front")]})
    state = run(apply_order(loaded, drop, "new", CAPS), CAPS, 5)
    assert statuses(state)["d"] is S.FINISHED
    assert state.loads == ()
    empty = run(apply_order(make_vehicle(), drop, "new", CAPS), CAPS, 5)
    assert statuses(empty)["d"] is S.FAILED
    assert [e.error_type for e in empty.errors] == ["actionError"]
    caps = make_caps(load_types=("EPAL", "KLT"))
    pallet = make_vehicle(loads=(Load(load_id="L1", load_type="EPAL", load_position="front"),))
    klt = make_order(["a"], node_actions={"a": [action("drop", "d", HARD, loadType="KLT")]})
    other = run(apply_order(pallet, klt, "new", caps), caps, 5)
    assert statuses(other)["d"] is S.FAILED  # it carries a pallet, not a KLT
    assert other.loads == pallet.loads


def test_pause_and_resume_while_driving() -> None:
    """R76, R106: startPause stops driving, pauses actions, paused=true; stopPause resumes."""
    order = make_order(["a", "b"], edge_actions={"a-b": [action("detectObject", "d")]})
    specs = make_caps().catalog
    caps = make_caps(catalog={**specs, "detectObject": replace(specs["detectObject"], run_s=100.0)})
    state = run(apply_order(make_vehicle(), order, "new", caps), caps, 1)
    assert state.driving
    x = state.pose.x
    state = receive_instant_actions(state, instant(action("startPause", "p1")), caps)
    assert statuses(state)["p1"] is S.FINISHED
    assert state.paused
    assert statuses(state)["d"] is S.PAUSED
    state = run(state, caps, 2)
    assert not state.driving
    assert state.pose.x == pytest.approx(x, abs=0.2)
    state = receive_instant_actions(state, instant(action("stopPause", "p2")), caps)
    assert not state.paused
    assert statuses(state)["d"] is S.RUNNING
    state = run(state, caps, 1)
    assert state.driving
    assert state.pose.x > x + 1


def test_charging_starts_and_stops() -> None:
    """R77: startCharging FINISHED => charging true and the battery fills; stopCharging => false."""
    state = send(make_vehicle(battery_charge=50.0), action("startCharging", "c1"))
    assert statuses(state)["c1"] is S.RUNNING
    state = run(state, CAPS, 2.1)
    assert statuses(state)["c1"] is S.FINISHED
    assert state.charging
    state = run(state, CAPS, 10)
    assert state.battery_charge > 54
    state = run(send(state, action("stopCharging", "c2")), CAPS, 1.1)
    assert statuses(state)["c2"] is S.FINISHED
    assert not state.charging


def test_driving_off_a_charging_spot_ends_the_charge() -> None:
    """R77 [§6.8.2]: the simulated vehicle charges standing (a charging spot): an order
    accepted while it charges drives it off the charger, which ends the charge; from then on
    the battery drains with distance instead of filling."""
    state = run(send(make_vehicle(battery_charge=50.0), action("startCharging", "c1")), CAPS, 2.1)
    assert state.charging
    state = run(apply_order(state, make_order(["a", "b"]), "new", CAPS), CAPS, 1)
    assert state.driving
    assert not state.charging
    charge = state.battery_charge
    state = run(state, CAPS, 2)
    assert state.battery_charge < charge


def test_init_position_sets_pose_and_last_node() -> None:
    """R78: initPosition FINISHED => agvPosition and lastNodeId equal the parameters."""
    init = action("initPosition", "i", x=3.0, y=4.0, theta=1.0, mapId="map", lastNodeId="n7")
    state = send(make_vehicle(), init)
    assert statuses(state)["i"] is S.FINISHED
    assert (state.pose.x, state.pose.y, state.pose.theta, state.pose.map_id) == (3, 4, 1, "map")
    assert state.last_node_id == "n7"


def test_init_position_during_an_order_fails() -> None:
    """§6.9: an instant initPosition that conflicts with the running order FAILS with an error."""
    state = apply_order(make_vehicle(), make_order(["a", "b"]), "new", CAPS)
    init = action("initPosition", "i", x=3.0, y=4.0, theta=1.0, mapId="map", lastNodeId="n7")
    state = send(state, init)
    assert statuses(state)["i"] is S.FAILED
    assert state.pose.x == 0


def test_state_request_finishes_and_triggers_a_state() -> None:
    """R79: stateRequest is FINISHED and calls for a state message (revision bumped)."""
    before = make_vehicle()
    state = send(before, action("stateRequest", "s"))
    assert statuses(state)["s"] is S.FINISHED
    assert state.revision > before.revision


def test_factsheet_request_raises_the_publish_flag() -> None:
    """R80: factsheetRequest is FINISHED and asks the shell to publish the factsheet."""
    state = send(make_vehicle(), action("factsheetRequest", "f"))
    assert statuses(state)["f"] is S.FINISHED
    assert state.factsheet_requested


def test_log_report_names_the_log() -> None:
    """§6.8.2: logReport FINISHED reports the log name in resultDescription."""
    state = run(send(make_vehicle(), action("logReport", "l", reason="crash")), CAPS, 1.1)
    (record,) = state.actions
    assert record.status is S.FINISHED
    assert record.result == "log-0001 (crash)"


def test_wait_for_trigger_finishes_on_trigger() -> None:
    """§6.8.2: waitForTrigger RUNS until the vendor instant action trigger names it."""
    wait = action("waitForTrigger", "w", HARD, triggerType="button")
    state = apply_order(make_vehicle(), make_order(["a"], node_actions={"a": [wait]}), "new", CAPS)
    state = run(state, CAPS, 60)
    assert statuses(state)["w"] is S.RUNNING
    state = send(state, action("trigger", "t", actionId="w"))
    assert statuses(state) == {"w": S.FINISHED, "t": S.FINISHED}


def test_trigger_without_a_waiting_action_fails() -> None:
    """An instant trigger naming no running waitForTrigger FAILS with a WARNING on its actionId."""
    state = send(make_vehicle(), action("trigger", "t", actionId="nothing"))
    assert statuses(state)["t"] is S.FAILED
    (error,) = state.errors
    assert {r.reference_key: r.reference_value for r in error.error_references or []}[
        "actionId"
    ] == "t"


def test_unknown_instant_action_fails_with_warning() -> None:
    """Issue item 5: an unknown instant action ends FAILED with a WARNING on its actionId."""
    state = send(make_vehicle(), action("selfDestruct", "x"))
    assert statuses(state)["x"] is S.FAILED
    (error,) = state.errors
    assert error.error_level.value == "WARNING"
    assert ("actionId", "x") in {
        (r.reference_key, r.reference_value) for r in error.error_references or []
    }


def test_instant_action_outside_its_scope_fails() -> None:
    """R83: pick as an instant action is not executed: FAILED with a WARNING."""
    state = send(make_vehicle(), action("pick", "p", stationType="s", loadType="l"))
    assert statuses(state)["p"] is S.FAILED
    assert [e.error_type for e in state.errors] == ["actionError"]
    assert state.loads == ()


def test_instant_action_keeps_its_id_in_state() -> None:
    """R67: every received instant action gets an actionState with its actionId."""
    state = send(make_vehicle(), action("stateRequest", "a1"), action("factsheetRequest", "a2"))
    assert set(statuses(state)) == {"a1", "a2"}


def test_duplicate_action_id_is_refused() -> None:
    """§6.6.6: actionIds are unique; a reused one raises a WARNING and adds no second state."""
    state = send(send(make_vehicle(), action("stateRequest", "a1")), action("stateRequest", "a1"))
    assert len(state.actions) == 1
    assert len(state.errors) == 1


def test_durations_are_configurable() -> None:
    """Issue item 5: action durations come from configuration."""
    caps = make_caps(catalog=with_durations(default_catalog(), {"logReport": 5.0}))
    state = run(
        receive_instant_actions(
            make_vehicle(), instant(action("logReport", "l", reason="r")), caps
        ),
        caps,
        4,
    )
    assert statuses(state)["l"] is S.RUNNING
    with pytest.raises(ValueError, match="unknown"):
        with_durations(default_catalog(), {"fly": 1.0})


def test_ended_instant_actions_are_capped_oldest_first() -> None:
    """A stream of instant actions cannot grow every state without bound: only the newest
    kept_instant_action_states ended ones stay until the next order (issue 14)."""
    caps = make_caps(limits=ProtocolLimits(kept_instant_action_states=3))
    state = make_vehicle()
    for n in range(10):
        state = receive_instant_actions(state, instant(action("stateRequest", f"q{n}")), caps)
    assert [r.action_id for r in state.actions] == ["q6", "q7", "q8", "q9"]
    assert all(r.status is ActionStatus.FINISHED for r in state.actions)
