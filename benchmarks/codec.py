"""Codec benchmark: median µs per message to decode+validate and to encode each message type.

The reference is a ~1.5 KB state message (issue 2 target: decode+validate <= 30 µs).
Run: python benchmarks/codec.py [--rounds N]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

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
)
from vda5050.testing import HEADER, make_order, make_state
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
    address = TopicAddress("uagv", 2, AgvId("acme", "robot_0"), Topic.STATE)
    print(f"{'message':<16}{'bytes':>7}{'decode+validate µs':>21}{'encode µs':>12}")
    for topic, message in samples().items():
        raw = encode(message)
        result = decode(topic, raw, address=address)
        if isinstance(result, DecodeFailure):
            raise SystemExit(f"{topic.value} sample does not decode: {result.summary()}")
        decode_us = median_us(lambda t=topic, r=raw: decode(t, r, address=address), args.rounds)
        encode_us = median_us(lambda m=message: encode(m), args.rounds)
        print(f"{topic.value:<16}{len(raw):>7}{decode_us:>21.1f}{encode_us:>12.1f}")


if __name__ == "__main__":
    main()
