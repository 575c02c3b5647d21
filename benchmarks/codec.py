"""Codec benchmark: median µs per message to decode+validate and to encode each message type.

The reference is a ~1.5 KB state message (issue 2 target: decode+validate <= 30 µs), in its 2.x
and its 3.0 form (issue 13: 3.0 must not slow 2.x down).
Run: python benchmarks/codec.py [--rounds N]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from functools import partial

from vda5050.codec import DecodeFailure, decode, encode
from vda5050.models import (
    Action,
    ActionState,
    ActionStatus,
    AgvPosition,
    BlockingType,
    Connection,
    ConnectionState,
    EdgeState,
    InstantActions,
    Load,
    NodeState,
    Velocity,
    Visualization,
    WireModel,
    v3,
)
from vda5050.testing import (
    HEADER,
    make_connection_v3,
    make_instant_action_v3,
    make_instant_actions_v3,
    make_order,
    make_order_v3,
    make_responses_v3,
    make_state,
    make_state_v3,
    make_visualization_v3,
    make_zone_set_v3,
)
from vda5050.topics import AgvId, Topic, TopicAddress


def reference_state() -> WireModel:
    """A state of an AGV in the middle of an order, about 1.5 KB encoded."""
    return make_state(
        order_id="order-0815",
        order_update_id=3,
        last_node_id="n4",
        last_node_sequence_id=8,
        driving=True,
        paused=False,
        new_base_request=False,
        distance_since_last_node=1.25,
        node_states=[
            NodeState(node_id=f"n{i}", sequence_id=2 * i, released=i < 7) for i in range(5, 9)
        ],
        edge_states=[
            EdgeState(edge_id=f"e{i}", sequence_id=2 * i - 1, released=i < 7) for i in range(5, 9)
        ],
        agv_position=AgvPosition(
            x=12.5,
            y=-3.25,
            theta=1.5707,
            map_id="warehouse",
            position_initialized=True,
            localization_score=0.98,
        ),
        velocity=Velocity(vx=1.2, vy=0.0, omega=0.05),
        loads=[Load(load_id="pallet-17", load_type="EPAL", load_position="front", weight=320.0)],
        action_states=[
            ActionState(action_id=f"action-{i:04d}", action_type=kind, action_status=status)
            for i, (kind, status) in enumerate(
                [
                    ("pick", ActionStatus.FINISHED),
                    ("drop", ActionStatus.WAITING),
                    ("startCharging", ActionStatus.WAITING),
                    ("detectObject", ActionStatus.RUNNING),
                    ("finePositioning", ActionStatus.WAITING),
                ]
            )
        ],
    )


def reference_state_v3() -> WireModel:
    """The reference state in its 3.0 form (the same content, 3.0 names)."""
    return make_state_v3(
        order_id="order-0815",
        order_update_id=3,
        last_node_id="n4",
        last_node_sequence_id=8,
        driving=True,
        paused=False,
        new_base_request=False,
        distance_since_last_node=1.25,
        node_states=[
            v3.NodeState(node_id=f"n{i}", sequence_id=2 * i, released=i < 7) for i in range(5, 9)
        ],
        edge_states=[
            v3.EdgeState(edge_id=f"e{i}", sequence_id=2 * i - 1, released=i < 7)
            for i in range(5, 9)
        ],
        mobile_robot_position=v3.MobileRobotPosition(
            x=12.5,
            y=-3.25,
            theta=1.5707,
            map_id="warehouse",
            localized=True,
            localization_score=0.98,
        ),
        velocity=Velocity(vx=1.2, vy=0.0, omega=0.05),
        loads=[v3.Load(load_id="pallet-17", load_type="EPAL", load_position="front", weight=320.0)],
        action_states=[
            v3.ActionState(action_id=f"action-{i:04d}", action_type=kind, action_status=status)
            for i, (kind, status) in enumerate(
                [
                    ("pick", v3.ActionStatus.FINISHED),
                    ("drop", v3.ActionStatus.WAITING),
                    ("startCharging", v3.ActionStatus.WAITING),
                    ("detectObject", v3.ActionStatus.RUNNING),
                    ("finePositioning", v3.ActionStatus.WAITING),
                ]
            )
        ],
    )


def samples_v3() -> dict[Topic, WireModel]:
    return {
        Topic.STATE: reference_state_v3(),
        Topic.ORDER: make_order_v3([f"n{i}" for i in range(10)], released=6),
        Topic.INSTANT_ACTIONS: make_instant_actions_v3(
            make_instant_action_v3("startPause", "ia-1")
        ),
        Topic.CONNECTION: make_connection_v3(),
        Topic.VISUALIZATION: make_visualization_v3(
            3,
            mobile_robot_position=v3.MobileRobotPosition(
                x=1.0, y=2.0, theta=0.5, map_id="m", localized=True
            ),
        ),
        Topic.ZONE_SET: make_zone_set_v3(),
        Topic.RESPONSES: make_responses_v3(("req-1", v3.GrantType.GRANTED)),
    }


def samples() -> dict[Topic, WireModel]:
    header = {**HEADER}
    return {
        Topic.STATE: reference_state(),
        Topic.ORDER: make_order([f"n{i}" for i in range(10)], released=6),
        Topic.INSTANT_ACTIONS: InstantActions.model_validate(
            {
                **header,
                "actions": [
                    Action(
                        action_type="startPause", action_id="ia-1", blocking_type=BlockingType.HARD
                    )
                ],
            }
        ),
        Topic.CONNECTION: Connection.model_validate(
            {**header, "connection_state": ConnectionState.ONLINE}
        ),
        Topic.VISUALIZATION: Visualization.model_validate(
            {
                **header,
                "agv_position": AgvPosition(
                    x=1.0, y=2.0, theta=0.5, map_id="m", position_initialized=True
                ),
            }
        ),
    }


def median_us(action: Callable[[], object], rounds: int) -> float:
    batch = 200
    timings = []
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(batch):
            action()
        timings.append((time.perf_counter() - start) / batch * 1e6)
    return statistics.median(timings)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=50)
    args = parser.parse_args()
    for major, interface, messages in ((2, "uagv", samples()), (3, "vda5050", samples_v3())):
        address = TopicAddress(interface, major, AgvId("acme", "robot_0"), Topic.STATE)
        print(f"{f'message (v{major})':<16}{'bytes':>7}{'decode+validate µs':>21}{'encode µs':>12}")
        for topic, message in messages.items():
            raw = encode(message)
            result = decode(topic, raw, address=address)
            if isinstance(result, DecodeFailure):
                raise SystemExit(f"{topic.value} sample does not decode: {result.summary()}")
            decode_us = median_us(partial(decode, topic, raw, address=address), args.rounds)
            encode_us = median_us(partial(encode, message), args.rounds)
            print(f"{topic.value:<16}{len(raw):>7}{decode_us:>21.1f}{encode_us:>12.1f}")


if __name__ == "__main__":
    main()
