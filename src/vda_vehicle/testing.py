"""Factories for vehicle tests and tools (complements ``vda5050.testing``)."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import replace
from typing import TypeVar

from vda5050.clock import FakeClock
from vda5050.codec import HeaderStamper
from vda5050.models import Action, ActionParameter, BlockingType, InstantActions, Order
from vda5050.mqtt import Payload
from vda5050.testing import HEADER
from vda5050.topics import AgvId, Topic
from vda_vehicle.capabilities import Capabilities
from vda_vehicle.config import VehicleSettings, capabilities
from vda_vehicle.maps import initial_maps
from vda_vehicle.model import Pose, VehicleState
from vda_vehicle.navigation import NavigationStack, SimulatedStack
from vda_vehicle.runtime import Metrics, Timing, VehicleRuntime
from vda_vehicle.runtime3 import VehicleRuntimeV3
from vda_vehicle.translator import advance

MAP = "map"


class Recorder:
    """Collects what a runtime publishes, building each payload as a sender would."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, Topic, bytes]] = []

    def __call__(self, topic: str, kind: Topic, payload: Payload) -> None:
        self.sent.append((topic, kind, payload() if callable(payload) else payload))

    def of(self, kind: Topic) -> list[dict[str, object]]:
        """The JSON objects published on ``kind``, oldest first."""
        return [json.loads(body) for _, k, body in self.sent if k is kind]


_R = TypeVar("_R", bound=VehicleRuntime)


def make_runtime(
    clock: FakeClock, *, stack: NavigationStack | None = None, **settings: object
) -> tuple[VehicleRuntime, Recorder]:
    """One 2.1.0 vehicle ``acme/robot_0`` at (0, 0) on map ``map``, publishing into a recorder;
    ``stack`` replaces the simulated navigation stack."""
    return _runtime(VehicleRuntime, "2.1.0", "uagv", clock, settings, stack=stack)


def make_runtime_v3(clock: FakeClock, **settings: object) -> tuple[VehicleRuntimeV3, Recorder]:
    """One 3.0.0 vehicle ``acme/robot_0`` at (0, 0) on map ``map``, topics under
    ``vda5050/v3``, publishing into a recorder."""
    return _runtime(VehicleRuntimeV3, "3.0.0", "vda5050", clock, settings)


def _runtime(
    kind: type[_R],
    version: str,
    interface_name: str,
    clock: FakeClock,
    settings: dict[str, object],
    *,
    stack: NavigationStack | None = None,
) -> tuple[_R, Recorder]:
    agv = AgvId("acme", "robot_0")
    caps = capabilities(VehicleSettings.model_validate(settings), None)
    vehicle = kind(
        agv=agv,
        state=VehicleState(pose=Pose(0.0, 0.0, 0.0, MAP), maps=initial_maps(caps.map_ids)),
        caps=caps,
        stack=stack or SimulatedStack(caps.speed_max_mps, caps.angular_speed_max_radps),
        stamper=HeaderStamper(agv, version, clock),
        interface_name=interface_name,
        timing=Timing(state_interval_s=30.0, visualization_interval_s=1.0, tick_s=0.2),
        clock=clock,
        metrics=Metrics(),
    )
    recorder = Recorder()
    vehicle.attach(recorder)
    return vehicle, recorder


def make_caps(**changes: object) -> Capabilities:
    """Capabilities of a vehicle that knows map ``map``, with ``changes`` applied."""
    fields: dict[str, object] = {"map_ids": frozenset({MAP}), **changes}
    return Capabilities(**fields)  # type: ignore[arg-type]


def make_vehicle(
    x: float = 0.0, y: float = 0.0, theta: float = 0.0, *, last_node_id: str = "", **changes: object
) -> VehicleState:
    """An idle vehicle standing at (x, y, theta) on map ``map``."""
    state = VehicleState(
        pose=Pose(x, y, theta, MAP), last_node_id=last_node_id, maps=initial_maps({MAP})
    )
    return replace(state, **changes)  # type: ignore[arg-type]


def reposition(order: Order, index: int, **changes: object) -> Order:
    """``order`` with the nodePosition of node ``index`` changed (snake_case field names)."""
    node = order.nodes[index]
    if node.node_position is None:
        msg = f"node {node.node_id!r} has no nodePosition"
        raise ValueError(msg)
    position = node.node_position.model_copy(update=changes)
    nodes = list(order.nodes)
    nodes[index] = node.model_copy(update={"node_position": position})
    return order.model_copy(update={"nodes": nodes})


def make_stack(caps: Capabilities) -> SimulatedStack:
    return SimulatedStack(caps.speed_max_mps, caps.angular_speed_max_radps)


def action(
    action_type: str,
    action_id: str,
    blocking: BlockingType = BlockingType.NONE,
    **parameters: str | float,
) -> Action:
    """An action with ``parameters`` as actionParameters."""
    return Action(
        action_type=action_type,
        action_id=action_id,
        blocking_type=blocking,
        action_parameters=[ActionParameter(key=k, value=v) for k, v in parameters.items()] or None,
    )


def instant(*actions: Action, header_id: int = 0) -> InstantActions:
    """An instantActions message carrying ``actions``."""
    return InstantActions.model_validate({**HEADER, "header_id": header_id, "actions": actions})


def run(state: VehicleState, caps: Capabilities, seconds: float, dt: float = 0.1) -> VehicleState:
    """Advance ``state`` for ``seconds`` in ticks of ``dt`` on the simulated stack."""
    stack = make_stack(caps)
    for _ in range(round(seconds / dt)):
        state = advance(state, dt, caps=caps, stack=stack)
    return state


def run_until(
    state: VehicleState,
    caps: Capabilities,
    done: Callable[[VehicleState], bool],
    *,
    limit_s: float = 600.0,
    dt: float = 0.1,
) -> VehicleState:
    """Advance until ``done(state)`` holds; raises AssertionError after ``limit_s``."""
    stack = make_stack(caps)
    for _ in range(round(limit_s / dt)):
        if done(state):
            return state
        state = advance(state, dt, caps=caps, stack=stack)
    msg = f"condition not reached within {limit_s} s"
    raise AssertionError(msg)
