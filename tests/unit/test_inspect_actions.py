"""What a vehicle's action states must say about the actions it was sent (docs/inspect.md;
R60, R68-R78, R81, R89, R91), judged by ``vda-inspect`` on crafted states."""

from __future__ import annotations

from typing import Any

from vda5050.models import (
    ActionState,
    ActionStatus,
    AgvPosition,
    BatteryState,
    BlockingType,
    EdgeState,
    InstantActions,
    Load,
    Map,
    MapStatus,
    NodeState,
    State,
)
from vda5050.testing import HEADER, make_order, make_state, state_at
from vda_inspect.progress import OrderProgress
from vda_inspect.severity import Severity
from vda_vehicle.testing import action

#: a → b → c → d; pick at b, drop at d (on the horizon: only a, b, c are released)
ORDER = make_order(
    ["a", "b", "c", "d"],
    released=3,
    node_actions={"b": [action("pick", "p1")], "d": [action("drop", "d1")]},
)
WAITING, RUNNING, FINISHED, FAILED = (
    ActionStatus.WAITING,
    ActionStatus.RUNNING,
    ActionStatus.FINISHED,
    ActionStatus.FAILED,
)


def _state(passed: int, statuses: dict[str, ActionStatus], **changes: Any) -> State:
    actions = [ActionState(action_id=i, action_status=s) for i, s in statuses.items()]
    return state_at(ORDER, passed, **{"action_states": actions, **changes})


def _rules(progress: OrderProgress, state: State) -> list[tuple[str, Severity]]:
    return [(rule, severity) for rule, _, severity in progress.state(state)]


def _sent() -> OrderProgress:
    progress = OrderProgress()
    progress.order(ORDER)
    return progress


def test_actions_that_follow_their_nodes_are_fine() -> None:
    progress = _sent()
    for passed, statuses in (
        (0, {"p1": WAITING, "d1": WAITING}),
        (1, {"p1": RUNNING, "d1": WAITING}),
        (1, {"p1": FINISHED, "d1": WAITING}),
        (2, {"p1": FINISHED, "d1": WAITING}),
    ):
        assert _rules(progress, _state(passed, statuses)) == []


def test_every_action_must_be_listed_and_wait_for_its_node() -> None:
    (problem,) = _sent().state(_state(0, {"p1": WAITING}))
    assert problem[:2] == ("R68", "drop 'd1' (at sequenceId 6) not in actionStates")
    assert _rules(_sent(), _state(0, {"p1": RUNNING, "d1": WAITING})) == [
        ("R70", Severity.VIOLATION)
    ]
    assert _rules(_sent(), _state(2, {"p1": FINISHED, "d1": RUNNING})) == [
        ("R72", Severity.VIOLATION)  # d is on the horizon
    ]


def test_a_final_status_stays_final() -> None:
    progress = _sent()
    assert _rules(progress, _state(1, {"p1": FAILED, "d1": WAITING})) == []
    assert _rules(progress, _state(1, {"p1": RUNNING, "d1": WAITING})) == [
        ("R69", Severity.VIOLATION)
    ]


def test_after_a_finished_cancel_nothing_of_the_order_waits() -> None:
    progress = _sent()
    cancel = InstantActions.model_validate(
        {
            **HEADER,
            "actions": [{"actionType": "cancelOrder", "actionId": "c", "blockingType": "HARD"}],
        }
    )
    progress.instant_actions(cancel)
    cleared: dict[str, Any] = {"node_states": [], "edge_states": []}
    good = _state(1, {"p1": FAILED, "d1": FAILED, "c": FINISHED}, **cleared)
    assert _rules(progress, good) == []
    bad = _state(1, {"p1": FAILED, "d1": WAITING, "c": FINISHED}, **cleared)
    assert _rules(_sent_with(cancel), bad) == [("R60", Severity.VIOLATION)]


def _sent_with(message: InstantActions) -> OrderProgress:
    progress = _sent()
    progress.instant_actions(message)
    return progress


def _instant(action_type: str, action_id: str) -> InstantActions:
    return InstantActions.model_validate(
        {
            **HEADER,
            "actions": [{"actionType": action_type, "actionId": action_id, "blockingType": "HARD"}],
        }
    )


def test_pause_and_charging_show_in_the_state_that_finishes_them() -> None:
    progress = _sent_with(_instant("startPause", "sp"))
    quiet = {"p1": WAITING, "d1": WAITING}
    paused = _state(0, {**quiet, "sp": FINISHED}, paused=True, driving=False)
    assert _rules(progress, paused) == []
    progress = _sent_with(_instant("startPause", "sp"))
    still = _state(0, {**quiet, "sp": FINISHED}, paused=False, driving=False)
    assert _rules(progress, still) == [("R76", Severity.VIOLATION)]
    progress = _sent_with(_instant("stopCharging", "sc"))
    charging = BatteryState(battery_charge=80.0, charging=True)
    on = _state(0, {**quiet, "sc": FINISHED}, battery_state=charging)
    assert _rules(progress, on) == [("R77", Severity.VIOLATION)]
    assert _rules(progress, on) == []  # judged once, where it first shows FINISHED


def test_an_action_first_seen_finished_that_the_listener_never_saw_sent_is_not_judged() -> None:
    """A startPause FINISHED before the listener started (the vehicle resumed since): the
    first state seen is no proof of what it did when it finished."""
    progress = _sent()
    unseen = _state(0, {"p1": WAITING, "d1": WAITING}, paused=False)
    unseen.action_states.append(
        ActionState(action_id="old", action_type="startPause", action_status=FINISHED)
    )
    assert _rules(progress, unseen) == []
    progress.instant_actions(_instant("startPause", "old"))  # had it seen it sent ...
    progress.statuses.clear()
    assert _rules(progress, unseen) == [("R76", Severity.VIOLATION)]  # ... it would judge


#: a → b; at b a HARD lift first, then two NONE lamps
LIST_ORDER = make_order(
    ["a", "b"],
    node_actions={
        "b": [
            action("lift", "l1", BlockingType.HARD),
            action("lamp", "n1"),
            action("lamp", "n2"),
        ]
    },
)


def _at_b(statuses: dict[str, ActionStatus], **changes: Any) -> State:
    fields: dict[str, Any] = {
        "order_id": LIST_ORDER.order_id,
        "last_node_id": "b",
        "last_node_sequence_id": 2,
        "action_states": [ActionState(action_id=i, action_status=s) for i, s in statuses.items()],
        "driving": False,
        **changes,
    }
    return make_state(**fields)


def _list_sent() -> OrderProgress:
    progress = OrderProgress()
    progress.order(LIST_ORDER)
    return progress


def test_blocking_types_and_list_order_are_kept() -> None:
    for statuses in (
        {"l1": RUNNING, "n1": WAITING, "n2": WAITING},
        {"l1": FINISHED, "n1": RUNNING, "n2": RUNNING},
        {"l1": FINISHED, "n1": FINISHED, "n2": RUNNING},
    ):
        assert _rules(_list_sent(), _at_b(statuses)) == []
    assert _rules(_list_sent(), _at_b({"l1": RUNNING, "n1": RUNNING, "n2": WAITING})) == [
        ("R74", Severity.VIOLATION)  # nothing beside a running HARD action
    ]
    assert _rules(_list_sent(), _at_b({"l1": WAITING, "n1": RUNNING, "n2": WAITING})) == [
        ("R75", Severity.VIOLATION)  # the lamp before the lift
    ]
    driving = _at_b({"l1": RUNNING, "n1": WAITING, "n2": WAITING}, driving=True)
    assert _rules(_list_sent(), driving) == [("R73", Severity.VIOLATION)]
    lamps_on_the_move = _at_b({"l1": FINISHED, "n1": RUNNING, "n2": RUNNING}, driving=True)
    assert _rules(_list_sent(), lamps_on_the_move) == []  # NONE actions may run while driving


def test_an_edge_action_waits_until_its_edge_is_entered() -> None:
    """R71: at node a (sequenceId 0) the edge a-b may be driven and its action run; the action
    of edge b-c must still wait."""
    order = make_order(
        ["a", "b", "c"], edge_actions={"a-b": [action("lamp", "e1")], "b-c": [action("lamp", "e2")]}
    )
    progress = OrderProgress()
    progress.order(order)
    nodes = [
        NodeState(node_id=n.node_id, sequence_id=n.sequence_id, released=True)
        for n in order.nodes[1:]
    ]
    edges = [
        EdgeState(edge_id=e.edge_id, sequence_id=e.sequence_id, released=True) for e in order.edges
    ]
    at_a: dict[str, Any] = {
        "order_id": order.order_id,
        "last_node_id": "a",
        "last_node_sequence_id": 0,
        "node_states": nodes,
        "edge_states": edges,
    }

    def statuses(first: ActionStatus, second: ActionStatus) -> list[ActionState]:
        return [
            ActionState(action_id="e1", action_status=first),
            ActionState(action_id="e2", action_status=second),
        ]

    assert _rules(progress, make_state(**at_a, action_states=statuses(RUNNING, WAITING))) == []
    early = make_state(**at_a, action_states=statuses(RUNNING, RUNNING))
    assert _rules(OrderProgress(), early) == []  # no order seen: nothing to judge by
    assert _rules(progress, early) == [("R71", Severity.VIOLATION)]


def test_init_position_finished_shows_its_pose_and_node() -> None:
    sent = InstantActions.model_validate(
        {
            **HEADER,
            "actions": [
                {
                    "actionType": "initPosition",
                    "actionId": "ip",
                    "blockingType": "HARD",
                    "actionParameters": [
                        {"key": "x", "value": 5.0},
                        {"key": "y", "value": 2.0},
                        {"key": "theta", "value": 0.0},
                        {"key": "mapId", "value": "map"},
                        {"key": "lastNodeId", "value": "a"},
                    ],
                }
            ],
        }
    )
    quiet = {"p1": WAITING, "d1": WAITING}

    def at(x: float, map_id: str = "map") -> State:
        pose = AgvPosition(x=x, y=2.0, theta=0.0, map_id=map_id, position_initialized=True)
        return _state(0, {**quiet, "ip": FINISHED}, agv_position=pose)

    assert _rules(_sent_with(sent), at(5.05)) == []  # within what localisation settles to
    assert _rules(_sent_with(sent), at(7.0)) == [("R78", Severity.VIOLATION)]
    assert _rules(_sent_with(sent), at(5.0, "hall-2")) == [("R78", Severity.VIOLATION)]


def test_pick_and_drop_change_the_loads_a_vehicle_reports() -> None:
    box = [Load(load_id="box-1")]
    progress = _sent()
    assert _rules(progress, _state(0, {"p1": WAITING, "d1": WAITING}, loads=[])) == []
    assert _rules(progress, _state(1, {"p1": FINISHED, "d1": WAITING}, loads=box)) == []
    forgot = _sent()
    forgot.state(_state(0, {"p1": WAITING, "d1": WAITING}, loads=[]))
    nothing = _state(1, {"p1": FINISHED, "d1": WAITING}, loads=[])
    assert _rules(forgot, nothing) == [("R81", Severity.VIOLATION)]
    silent = _sent()  # a vehicle that does not report loads is not judged
    silent.state(_state(0, {"p1": WAITING, "d1": WAITING}))
    assert _rules(silent, _state(1, {"p1": FINISHED, "d1": WAITING})) == []


def _maps(*entries: tuple[str, str, str]) -> list[Map]:
    return [Map(map_id=m, map_version=v, map_status=MapStatus(s)) for m, v, s in entries]


def test_one_version_of_a_map_is_enabled_and_maps_go_only_by_delete_map() -> None:
    progress = _sent()
    quiet = {"p1": WAITING, "d1": WAITING}
    both = _maps(("hall", "1", "ENABLED"), ("hall", "2", "DISABLED"))
    assert _rules(progress, _state(0, quiet, maps=both)) == []
    two = _maps(("hall", "1", "ENABLED"), ("hall", "2", "ENABLED"))
    assert _rules(progress, _state(0, quiet, maps=two)) == [("R89", Severity.VIOLATION)]
    one = _maps(("hall", "1", "ENABLED"))
    assert _rules(progress, _state(0, quiet, maps=one)) == [("R91", Severity.VIOLATION)]
    progress.state(_state(0, quiet, maps=both))
    deleted = _state(
        0,
        quiet,
        maps=one,
        action_states=[
            *(ActionState(action_id=i, action_status=s) for i, s in quiet.items()),
            ActionState(action_id="del", action_type="deleteMap", action_status=FINISHED),
        ],
    )
    assert _rules(progress, deleted) == []


def _map_action(action_type: str, action_id: str, map_id: str, version: str) -> InstantActions:
    parameters = [{"key": "mapId", "value": map_id}, {"key": "mapVersion", "value": version}]
    if action_type == "downloadMap":
        parameters.append({"key": "mapDownloadLink", "value": "http://maps/hall-2"})
    return InstantActions.model_validate(
        {
            **HEADER,
            "actions": [
                {
                    "actionType": action_type,
                    "actionId": action_id,
                    "blockingType": "NONE",
                    "actionParameters": parameters,
                }
            ],
        }
    )


def _with_maps(status: ActionStatus, action_id: str, *maps: tuple[str, str, str]) -> State:
    quiet = {"p1": WAITING, "d1": WAITING, action_id: status}
    return _state(0, quiet, maps=_maps(*maps))


def test_map_actions_end_as_the_maps_they_leave_say() -> None:
    one = ("hall", "1", "ENABLED")
    progress = _sent()
    progress.state(_state(0, {"p1": WAITING, "d1": WAITING}, maps=_maps(one)))
    progress.instant_actions(_map_action("downloadMap", "dl", "hall", "2"))
    assert _rules(progress, _with_maps(RUNNING, "dl", one)) == []  # downloading
    missing = _with_maps(FINISHED, "dl", one)
    assert _rules(progress, missing) == [("R88", Severity.VIOLATION)]
    both = (one, ("hall", "2", "DISABLED"))
    progress.state(_state(0, {"p1": WAITING, "d1": WAITING}, maps=_maps(*both)))
    progress.instant_actions(_map_action("downloadMap", "again", "hall", "2"))  # held now
    assert _rules(progress, _with_maps(FINISHED, "again", *both)) == [("R87", Severity.VIOLATION)]
    progress.instant_actions(_map_action("enableMap", "en", "hall", "2"))
    stays = _with_maps(FINISHED, "en", *both)
    assert _rules(progress, stays) == [("R89", Severity.VIOLATION)]  # version 2 not ENABLED
    progress.instant_actions(_map_action("enableMap", "ghost", "hall", "9"))
    assert _rules(progress, _with_maps(FAILED, "ghost", *both)) == []  # as it must (R90)
    progress.instant_actions(_map_action("deleteMap", "gone", "hall", "9"))
    assert _rules(progress, _with_maps(FINISHED, "gone", *both)) == [("R90", Severity.VIOLATION)]
    progress.instant_actions(_map_action("deleteMap", "del", "hall", "2"))
    kept = _with_maps(FINISHED, "del", *both)
    assert _rules(progress, kept) == [("R91", Severity.VIOLATION)]  # still listed


def test_map_actions_that_do_what_they_say_are_fine() -> None:
    one = ("hall", "1", "ENABLED")
    progress = _sent()
    progress.state(_state(0, {"p1": WAITING, "d1": WAITING}, maps=_maps(one)))
    progress.instant_actions(_map_action("downloadMap", "dl", "hall", "2"))
    downloaded = (one, ("hall", "2", "DISABLED"))
    assert _rules(progress, _with_maps(FINISHED, "dl", *downloaded)) == []
    progress.instant_actions(_map_action("enableMap", "en", "hall", "2"))
    switched = (("hall", "1", "DISABLED"), ("hall", "2", "ENABLED"))
    assert _rules(progress, _with_maps(FINISHED, "en", *switched)) == []
    progress.instant_actions(_map_action("deleteMap", "del", "hall", "1"))
    deleted = _state(
        0,
        {"p1": WAITING, "d1": WAITING},
        maps=_maps(("hall", "2", "ENABLED")),
        action_states=[
            ActionState(action_id="p1", action_status=WAITING),
            ActionState(action_id="d1", action_status=WAITING),
            ActionState(action_id="del", action_type="deleteMap", action_status=FINISHED),
        ],
    )
    assert _rules(progress, deleted) == []


def test_a_waiting_trigger_of_a_cancelled_order_ends_failed() -> None:
    order = make_order(["a", "b", "c"], node_actions={"b": [action("waitForTrigger", "w")]})
    cancel = _instant("cancelOrder", "c")

    def judged(trigger: ActionStatus) -> list[tuple[str, Severity]]:
        progress = OrderProgress()
        progress.order(order)
        running = [ActionState(action_id="w", action_status=RUNNING)]
        progress.state(state_at(order, 1, action_states=running))
        progress.instant_actions(cancel)
        ended = [
            ActionState(action_id="w", action_status=trigger),
            ActionState(action_id="c", action_type="cancelOrder", action_status=FINISHED),
        ]
        after = state_at(order, 1, action_states=ended, node_states=[], edge_states=[])
        return _rules(progress, after)

    assert judged(FAILED) == []
    assert judged(FINISHED) == [("R82", Severity.VIOLATION)]
