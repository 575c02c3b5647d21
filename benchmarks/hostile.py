"""How fast each service gets rid of hostile input, in-process (issue 14).

Feeds the hostile mixes of ``tests/system/hostile.py`` straight into the master's ``ingest`` and
the vehicle runtime's handlers (no broker) and prints messages handled per second, plus the time
to refuse the worst single messages: a 10,000-action instantActions and a 900 KB orderId.

Run: PYTHONPATH=. python benchmarks/hostile.py [--messages 10000]
"""

from __future__ import annotations

import argparse
import time

import structlog

from tests.system.hostile import at_master, at_vehicle
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.testing import make_action, make_instant_actions, make_order
from vda_master.config import MasterConfig
from vda_master.service import MasterService
from vda_master.testing import RecordingPublisher, demo_graph
from vda_vehicle.testing import make_runtime


def master_rate(count: int) -> float:
    service = MasterService(MasterConfig(), demo_graph(), RecordingPublisher(), FakeClock())
    messages = list(at_master("uagv/v2/acme", "robot_0", count))
    started = time.perf_counter()
    for topic, payload in messages:
        service.ingest(topic, payload)
    return count / (time.perf_counter() - started)


def vehicle_rate(count: int) -> float:
    vehicle, _ = make_runtime(FakeClock())
    messages = list(at_vehicle("uagv/v2/acme/robot_0", count))
    started = time.perf_counter()
    for topic, payload in messages:
        if topic.endswith("/order"):
            vehicle.handle_order(topic, payload)
        else:
            vehicle.handle_instant_actions(topic, payload)
    return count / (time.perf_counter() - started)


def worst_single_messages_ms() -> dict[str, float]:
    vehicle, _ = make_runtime(FakeClock())
    many = make_instant_actions(*(make_action("stateRequest", f"q{n}") for n in range(10_000)))
    long_id = make_order(["a"], order_id="o" * 900_000)
    found = {}
    for name, topic, payload in (
        ("instantActions, 10,000 actions", "instantActions", encode(many)),
        ("order, 900 KB orderId", "order", encode(long_id)),
    ):
        started = time.perf_counter()
        if topic == "order":
            vehicle.handle_order("uagv/v2/acme/robot_0/order", payload)
        else:
            vehicle.handle_instant_actions("uagv/v2/acme/robot_0/instantActions", payload)
        found[f"{name} ({len(payload) // 1024} KiB)"] = (time.perf_counter() - started) * 1000
    return found


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("--messages", type=int, default=10_000)
    args = cli.parse_args()
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(50))
    print(f"master  hostile mix: {master_rate(args.messages):>8.0f} messages/s")
    print(f"vehicle hostile mix: {vehicle_rate(args.messages):>8.0f} messages/s")
    for name, ms in worst_single_messages_ms().items():
        print(f"vehicle refuses {name}: {ms:.1f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
