"""Skipped ticks (VehicleRuntime.tick, translator.quiet_time): a vehicle that cannot raise an
event before its next node is not simulated tick by tick, and nothing it publishes changes."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import pytest

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import Action, BlockingType, InstantActions, Order
from vda5050.testing import make_order
from vda5050.topics import Topic
from vda_vehicle import runtime as runtime_module
from vda_vehicle.config import VehicleSettings, capabilities
from vda_vehicle.model import STANDSTILL, ActionRecord, Motion, Pose, VehicleState
from vda_vehicle.navigation import NavFeedback, SimulatedStack, TargetRoute
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.testing import Recorder, make_runtime
from vda_vehicle.translator import advance, cruise_pose, quiet_time

POSITIONS = [(0.0, 0.0), (8.0, 0.0), (16.0, 0.0), (24.0, 0.0)]


def _align(action_id: str) -> Action:
    return Action(
        action_type="finePositioning", action_id=action_id, blocking_type=BlockingType.HARD
    )


def _look(action_id: str) -> Action:
    return Action(action_type="detectObject", action_id=action_id, blocking_type=BlockingType.NONE)


def _instant(action_type: str, action_id: str, header_id: int, **parameters: str) -> bytes:
    action = Action(
        action_type=action_type,
        action_id=action_id,
        blocking_type="NONE",
        action_parameters=[{"key": k, "value": v} for k, v in parameters.items()],
    )
    message = InstantActions(
        header_id=header_id,
        timestamp="2026-01-01T00:00:00.000Z",
        version="2.1.0",
        manufacturer="acme",
        serial_number="robot_0",
        actions=[action],
    )
    return encode(message)


def _drive(vehicle: VehicleRuntime, clock: FakeClock) -> None:
    """An order with a horizon, an action on an edge and one on a node, a pause on the way,
    the horizon released later."""
    actions: dict[str, Any] = {
        "node_actions": {"c": [_align("align")]},
        "edge_actions": {"b-c": [_look("look")]},
    }
    order = make_order(["a", "b", "c", "d"], positions=POSITIONS, released=3, **actions)
    # stitched on c, the decision point the vehicle waits at by then
    update = make_order(["c", "d"], positions=POSITIONS[2:], first_sequence_id=4, order_update_id=1)
    script: dict[int, Callable[[], None]] = {
        1: lambda: vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order)),
        13: lambda: vehicle.handle_instant_actions(
            vehicle.topics[Topic.INSTANT_ACTIONS], _instant("startPause", "pause", 1)
        ),
        21: lambda: vehicle.handle_instant_actions(
            vehicle.topics[Topic.INSTANT_ACTIONS], _instant("stopPause", "resume", 2)
        ),
        70: lambda: vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(update)),
    }
    for index in range(160):
        clock.advance(0.1)
        if index in script:
            script[index]()
        clock.advance(0.1)
        vehicle.tick(0.2, clock.monotonic())


def _rounded(value: Any) -> Any:
    if isinstance(value, float):
        return round(value, 6)
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    return value


def _published(recorder: Recorder) -> list[tuple[Topic, object]]:
    return [(kind, _rounded(json.loads(body))) for _, kind, body in recorder.sent]


def test_what_a_vehicle_publishes_is_the_same_with_skipped_ticks(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """R93, R94, R107, R109: states (node arrivals, actions, pause, newBaseRequest, the
    update; never closer than minStateInterval) and visualizations carry the same content at
    the same moments whether quiet ticks are skipped or not."""
    clock = FakeClock()
    lazy, lazy_sent = make_runtime(clock, speed_max_mps=2.0)
    _drive(lazy, clock)

    monkeypatch.setattr(runtime_module, "quiet_time", lambda _state, **_: 0.0)
    clock = FakeClock()
    eager, eager_sent = make_runtime(clock, speed_max_mps=2.0)
    _drive(eager, clock)

    assert _published(lazy_sent) == _published(eager_sent)
    states = lazy_sent.of(Topic.STATE)
    assert states[-1]["nodeStates"] == []
    assert states[-1]["lastNodeId"] == "d"
    assert any(s["newBaseRequest"] for s in states)
    assert any(s["paused"] for s in states)
    action_states: list[dict[str, str]] = states[-1]["actionStates"]  # type: ignore[assignment]
    finished = {a["actionId"] for a in action_states if a["actionStatus"] == "FINISHED"}
    assert finished == {"align", "look", "pause", "resume"}


def test_a_cruising_vehicle_is_simulated_about_once_per_node_and_visualized_every_second(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """R109: a visualization every second shows where the cruise has got to (2 m further each
    time at 2 m/s), without a simulation step of its own."""
    calls = 0

    def counted(*args: Any, **kwargs: Any) -> VehicleState:
        nonlocal calls
        calls += 1
        return advance(*args, **kwargs)

    monkeypatch.setattr(runtime_module, "advance", counted)
    clock = FakeClock()
    vehicle, sent = make_runtime(clock, speed_max_mps=2.0)
    order = make_order(["a", "b", "c"], positions=[(0.0, 0.0), (8.0, 0.0), (16.0, 0.0)])
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order))
    for _ in range(41):  # 16 m at 2 m/s: 8 s of 0.2 s ticks
        clock.advance(0.2)
        vehicle.tick(0.2, clock.monotonic())
    assert calls <= 6  # accepting the order, the first tick, 2 node arrivals, the ticks after
    shown = [
        (datetime.fromisoformat(str(v["timestamp"])), v["agvPosition"]["x"])  # type: ignore[index]
        for v in sent.of(Topic.VISUALIZATION)
    ]
    (first_at, first_x), cruise = shown[0], shown[1:8]
    assert [round((at - first_at).total_seconds()) for at, _ in cruise] == [1, 2, 3, 4, 5, 6, 7]
    for at, x in cruise:  # where 2 m/s puts it, to the tick
        assert x - first_x == pytest.approx(2.0 * (at - first_at).total_seconds(), abs=0.01)
    assert vehicle.state.last_node_id == "c"
    assert vehicle.state.pose.x == pytest.approx(16.0)


@dataclass
class _RobotStack:
    """A stand-in for a real robot's stack: it drives like the simulated one, but does not
    declare itself steady, so it must be asked every tick."""

    inner: SimulatedStack
    calls: int = 0

    def drive(self, pose: Pose, route: TargetRoute, *, hold: bool, dt: float) -> NavFeedback:
        self.calls += 1
        return self.inner.drive(pose, route, hold=hold, dt=dt)


def test_a_stack_that_is_not_steady_is_asked_every_tick_while_driving() -> None:
    clock = FakeClock()
    robot = _RobotStack(SimulatedStack(2.0, 1.0))
    vehicle, _ = make_runtime(clock, stack=robot, speed_max_mps=2.0)
    order = make_order(["a", "b"], positions=[(0.0, 0.0), (8.0, 0.0)])
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order))
    for _ in range(15):
        clock.advance(0.2)
        vehicle.tick(0.2, clock.monotonic())
    assert robot.calls == 1 + 15  # given the route when the order is accepted, then every tick
    assert quiet_time(_cruising(), steady_stack=False) == 0.0


def test_reading_the_state_simulates_the_skipped_ticks() -> None:
    clock = FakeClock()
    vehicle, _ = make_runtime(clock, speed_max_mps=2.0)
    order = make_order(["a", "b"], positions=[(0.0, 0.0), (20.0, 0.0)])
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order))
    for _ in range(7):
        clock.advance(0.2)
        vehicle.tick(0.2, clock.monotonic())
    assert vehicle.state.pose.x == pytest.approx(2.8)  # 7 ticks of 0.4 m
    assert vehicle.state.distance_since_last_node == pytest.approx(2.8)


def _cruising(**changes: Any) -> VehicleState:
    order = make_order(["a", "b", "c"], positions=[(0.0, 0.0), (8.0, 0.0), (16.0, 0.0)])
    state = VehicleState(
        pose=Pose(3.0, 0.0, 0.0, "map"),
        nodes=tuple(order.nodes[1:]),
        edges=tuple(order.edges),
        entered_edge=order.edges[0].sequence_id,
        motion=Motion(vx=2.0),
    )
    return VehicleState(**{**{f: getattr(state, f) for f in state.__slots__}, **changes})


def test_a_cruise_pose_is_where_a_simulation_step_puts_the_vehicle() -> None:
    caps = capabilities(VehicleSettings(speed_max_mps=2.0), None)
    stack = SimulatedStack(2.0, 1.0)
    for dt in (0.0, 0.2, 1.0, 2.4):
        stepped = advance(_cruising(), dt, caps=caps, stack=stack).pose
        predicted = cruise_pose(_cruising(), dt)
        assert (predicted.x, predicted.y, predicted.theta) == pytest.approx(
            (stepped.x, stepped.y, stepped.theta)
        )
    assert cruise_pose(_cruising(), 1.0).x == pytest.approx(5.0)  # 3 m + 1 s at 2 m/s
    standing = VehicleState(pose=Pose(1.0, 2.0, 0.5, "map"))
    assert cruise_pose(standing, 3.0) == standing.pose


def test_quiet_time_is_the_time_to_the_next_node_while_cruising() -> None:
    assert quiet_time(VehicleState(pose=Pose(0.0, 0.0, 0.0, "map"))) == math.inf
    assert quiet_time(_cruising()) == pytest.approx(2.5, abs=1e-3)  # 5 m to b at 2 m/s


@pytest.mark.parametrize(
    "changes",
    [
        {"motion": Motion(omega=0.5)},
        {"paused": True},
        {"charging": True},
        {"cancel_action_id": "cancel"},
        {"entered_edge": None},
    ],
    ids=["turning", "paused", "charging", "cancelling", "no-edge-entered"],
)
def test_quiet_time_is_zero_when_something_may_happen_within_a_tick(
    changes: dict[str, object],
) -> None:
    assert quiet_time(_cruising(**changes)) == 0.0


def test_quiet_time_is_zero_with_an_action_under_way_or_a_horizon_to_ask_for() -> None:
    running = ActionRecord(
        Action(action_type="beep", action_id="x", blocking_type=BlockingType.NONE),
        scope="EDGE",  # type: ignore[arg-type]
        group=1,
        status="RUNNING",  # type: ignore[arg-type]
        triggered=True,
        remaining_s=1.0,
    )
    assert quiet_time(_cruising(actions=(running,))) == 0.0
    horizon = _cruising()
    last = horizon.nodes[-1].model_copy(update={"released": False})
    waiting = _cruising(nodes=(*horizon.nodes[:-1], last))
    assert quiet_time(waiting) == 0.0
    assert quiet_time(_cruising(nodes=waiting.nodes, new_base_request=True)) > 0


@pytest.mark.parametrize("spacing_m", [2.0, 1.6, 3.0, 2.2])
@pytest.mark.parametrize("speed_mps", [1.0, 2.0, 0.7])
def test_arrivals_on_a_tick_boundary_are_reported_on_that_tick(
    monkeypatch: pytest.MonkeyPatch, spacing_m: float, speed_mps: float
) -> None:
    """R93: lanes whose nodes a vehicle reaches exactly as a tick ends (float sums of many small
    steps against one large one): every node is first reported on the same tick either way.
    (Other fields may differ at such a boundary: ticked one by one, the vehicle may stop for a
    tick on the node, a rounding artefact that one large step does not have.)"""

    def arrivals() -> dict[object, object]:
        clock = FakeClock()
        vehicle, sent = make_runtime(clock, speed_max_mps=speed_mps)
        nodes = [f"n{i}" for i in range(12)]
        positions = [(spacing_m * i, 0.0) for i in range(12)]
        order = make_order(nodes, positions=positions)
        vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order))
        for _ in range(int(11 * spacing_m / speed_mps / 0.2) + 3):
            clock.advance(0.2)
            vehicle.tick(0.2, clock.monotonic())
        first: dict[object, object] = {}
        for state in sent.of(Topic.STATE):
            first.setdefault(state["lastNodeId"], state["timestamp"])
        assert len(first) == len(nodes)
        return first

    lazy = arrivals()
    monkeypatch.setattr(runtime_module, "quiet_time", lambda _state, **_: 0.0)
    assert lazy == arrivals()


def _x_after_first_drive_tick(before: Callable[[VehicleRuntime, FakeClock], Order]) -> float:
    """Where a vehicle (2 m/s) stands one tick after the order ``before`` returns, which
    arrives 0.1 s before that tick."""
    clock = FakeClock()
    vehicle, _ = make_runtime(clock, speed_max_mps=2.0)
    order = before(vehicle, clock)
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order))
    clock.advance(0.1)
    vehicle.tick(0.2, clock.monotonic())
    return vehicle.state.pose.x


def test_an_order_before_the_first_tick_drives_only_from_its_arrival() -> None:
    """The tick loop's first dt runs from when it started, not from when the order came: an
    order that came 0.1 s before that tick drives 0.1 s (0.2 m), not the whole 0.2 s. (A fleet
    sent its orders as soon as it was connected finished a 16 m order in 7.95 s at 2 m/s.)"""

    def start_loop(_: VehicleRuntime, clock: FakeClock) -> Order:
        clock.advance(0.1)  # the loop started 0.2 s before its first tick, the order 0.1 s
        return make_order(["a", "b"])

    assert _x_after_first_drive_tick(start_loop) == pytest.approx(0.2)


def test_a_base_released_while_an_action_runs_drives_only_from_its_arrival() -> None:
    """A vehicle at the end of its base runs a node action that does not block driving
    (detectObject, 1 s): it is not standing by, yet the update that releases the next node
    still sets it going from the update's arrival, not from the last tick."""

    def waiting_with_an_action(vehicle: VehicleRuntime, clock: FakeClock) -> Order:
        vehicle.tick(0.2, clock.monotonic())
        first = make_order(["a", "b"], released=1, node_actions={"a": [_look("look")]})
        vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(first))
        for _ in range(2):
            clock.advance(0.2)
            vehicle.tick(0.2, clock.monotonic())
        assert vehicle.state.actions[0].status.value == "RUNNING"
        clock.advance(0.1)  # the update comes halfway through the next tick period
        return make_order(["a", "b"], order_update_id=1)

    assert _x_after_first_drive_tick(waiting_with_an_action) == pytest.approx(0.2)


def test_a_message_to_a_driving_vehicle_loses_no_time() -> None:
    """What a driving vehicle drove up to a message counts, and so does the rest of the tick:
    0.4 m per 0.2 s tick, message or not."""
    clock = FakeClock()
    vehicle, _ = make_runtime(clock, speed_max_mps=2.0)
    vehicle.tick(0.2, clock.monotonic())
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(make_order(["a", "b"])))
    clock.advance(0.2)
    vehicle.tick(0.2, clock.monotonic())
    clock.advance(0.05)
    vehicle.handle_instant_actions(
        vehicle.topics[Topic.INSTANT_ACTIONS], _instant("stateRequest", "ask", 1)
    )
    clock.advance(0.15)
    vehicle.tick(0.2, clock.monotonic())
    assert vehicle.state.pose.x == pytest.approx(0.8)


def test_a_cruising_vehicle_announces_its_arrival_and_reports_it_on_time() -> None:
    """R93: the node at the end of a cruise is reported when it is reached, not at the next
    tick after it: the runtime announces the arrival time (10 m at 2 m/s from t = 0: 5.0 s),
    and a tick at that time reports the node."""
    clock = FakeClock()
    vehicle, sent = make_runtime(clock, speed_max_mps=2.0)
    announced: list[float] = []
    vehicle.on_next_event(announced.append)
    start = clock.monotonic()
    vehicle.tick_to(start, 0.0)
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(make_order(["a", "b"])))
    for _ in range(3):
        clock.advance(0.2)
        vehicle.tick_to(clock.monotonic(), 0.2)
    assert announced
    assert announced[-1] - start == pytest.approx(5.0)
    clock.advance(announced[-1] - clock.monotonic())
    vehicle.tick_event(clock.monotonic())
    assert vehicle.state.last_node_id == "b"
    assert sent.of(Topic.STATE)[-1]["lastNodeId"] == "b"
    clock.advance(0.1)  # the next shared tick covers only what came after the event
    vehicle.tick_to(clock.monotonic(), 0.2)
    assert vehicle.state.pose.x == pytest.approx(10.0)


@pytest.mark.parametrize("offset_ms", range(12))
def test_a_vehicle_ticked_as_it_reaches_a_node_drives_on_through_it(offset_ms: int) -> None:
    """R93, R100: a tick at the very moment a node is reached (the arrival event) reports the
    node with the vehicle still driving when the next edge is released, and the vehicle goes
    on at once: no stop on the node until the next tick, no extra state for one (16 m at
    2 m/s: done 8 s after the order, whenever within the tick period the order came)."""
    clock = FakeClock()
    vehicle, sent = make_runtime(clock, speed_max_mps=2.0)
    announced: list[float] = []
    vehicle.on_next_event(announced.append)
    for _ in range(10):  # the tick loop has run for a while
        clock.advance(0.2)
        vehicle.tick_to(clock.monotonic(), 0.2)
    clock.advance(offset_ms / 1000)
    start = clock.monotonic()
    order = make_order(["a", "b", "c"], positions=[(0.0, 0.0), (8.0, 0.0), (16.0, 0.0)])
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order))
    done_after = math.inf
    while clock.monotonic() - start < 9.0:
        due = [at for at in announced if clock.monotonic() < at <= clock.monotonic() + 0.2]
        if due:  # the arrival event, exactly on time
            clock.advance(due[0] - clock.monotonic())
            vehicle.tick_event(clock.monotonic())
            announced.clear()
        else:
            clock.advance(0.2)
            vehicle.tick_to(clock.monotonic(), 0.2)
        if math.isinf(done_after) and sent.of(Topic.STATE)[-1]["nodeStates"] == []:
            done_after = clock.monotonic() - start
    states = [s for s in sent.of(Topic.STATE) if s["orderId"] == "order-1"]
    assert [(s["lastNodeId"], s["driving"]) for s in states] == [
        ("a", True),  # accepted and set off
        ("b", True),  # passing through
        ("c", False),  # done
    ]
    assert done_after == pytest.approx(8.0)


@dataclass
class _PushedRobot:
    """A real robot's stack at rest that an operator pushes: its pose is its own."""

    pose: Pose
    motion: Motion = STANDSTILL

    def drive(self, _pose: Pose, route: TargetRoute, *, hold: bool, dt: float) -> NavFeedback:
        assert route == ()  # nothing to drive
        assert dt > 0
        del hold
        return NavFeedback(self.pose, self.motion)


def test_a_real_robot_moved_by_hand_while_idle_is_reported_where_it_is() -> None:
    clock = FakeClock()
    robot = _PushedRobot(Pose(0.0, 0.0, 0.0, "map"))
    vehicle, sent = make_runtime(clock, stack=robot, speed_max_mps=2.0)
    vehicle.tick(0.2, clock.monotonic())
    revision = vehicle.state.revision
    robot.pose, robot.motion = Pose(1.5, 0.5, 0.3, "map"), Motion(vx=0.5)
    clock.advance(0.2)
    vehicle.tick(0.2, clock.monotonic())
    assert (vehicle.state.pose.x, vehicle.state.pose.y) == (1.5, 0.5)
    assert vehicle.state.driving
    assert vehicle.state.revision == revision + 1  # R93: driving is an event
    robot.motion = STANDSTILL
    for _ in range(10):
        clock.advance(0.2)
        vehicle.tick(0.2, clock.monotonic())
    assert not vehicle.state.driving
    last = sent.of(Topic.STATE)[-1]
    assert (last["agvPosition"]["x"], last["agvPosition"]["y"]) == (1.5, 0.5)
    assert (last["driving"], last["lastNodeId"]) == (False, vehicle.state.last_node_id)
    shown = sent.of(Topic.VISUALIZATION)[-1]
    assert (shown["agvPosition"]["x"], shown["agvPosition"]["theta"]) == (1.5, 0.3)


def test_only_a_stack_that_is_not_steady_is_asked_at_rest() -> None:
    assert quiet_time(_cruising(nodes=(), edges=(), motion=Motion()), steady_stack=True) == math.inf
    assert quiet_time(_cruising(nodes=(), edges=(), motion=Motion()), steady_stack=False) == 0.0
