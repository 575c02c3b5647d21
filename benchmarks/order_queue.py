"""What queued orders cost master control (docs/master.md, *Queued orders*).

On ``config/graphs/warehouse.json`` with N simulated vehicles (``vda_vehicle``'s own runtimes on
the graph's first N nodes, VDA 2.0.0), all of them busy with an order each, a WMS posts a wave of
M orders without a vehicle and with ``queue: true``; then the vehicles finish their orders one
after the other, and each finishing state serves the queue. The service is driven directly (no
broker, no HTTP, no store: the master's own work), on a fake clock; figures are process CPU.

Printed: CPU per queued ``place_order`` (all vehicles busy: every one is refused, then kept);
CPU of one pass over the whole queue while no vehicle is free (what the once-a-second pass
costs); CPU per running order driven to its end (every state of it) when its last state sends
the next queued order, against the same with nothing queued (the same fleet again without the
wave).

With ``--traffic`` the first two figures hold; fewer orders end (the drive here does not wait
where another vehicle holds the way, so an order whose base traffic control holds back does not
finish), which the report says.

Run:
    PYTHONPATH=. .venv/bin/python benchmarks/order_queue.py                    # N = 40, M = 1000
    PYTHONPATH=. .venv/bin/python benchmarks/order_queue.py --vehicles 80 --orders 5000 --traffic
"""

from __future__ import annotations

import argparse
import random
import statistics
import time
from pathlib import Path

import structlog

from benchmarks.post_orders import DroppingPublisher
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import ActionStatus
from vda5050.topics import Topic, build_topic
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderStatus
from vda_master.graph import load_graph
from vda_master.planner import Target
from vda_master.requests import OrderRequest
from vda_master.service import MasterService
from vda_master.testing import plan_state
from vda_vehicle.config import VehicleSettings
from vda_vehicle.config import load_graph as load_vehicle_graph
from vda_vehicle.service import VehicleService

GRAPH = Path(__file__).resolve().parents[1] / "config" / "graphs" / "warehouse.json"
INTERFACE = "queue"


def fleet_messages(vehicles: int) -> list[tuple[str, bytes]]:
    """ONLINE, factsheet and first state of each simulated vehicle."""
    settings = VehicleSettings.model_validate(
        {
            "interface_name": INTERFACE,
            "graph": GRAPH,
            "count": vehicles,
            "serial_number": "q",
            "manufacturer": "bench",
            "vda_version": "2.0.0",
        }
    )
    fleet = VehicleService(settings, load_vehicle_graph(GRAPH))
    sent: list[tuple[str, bytes]] = []
    for runtime in fleet.runtimes:
        runtime.attach(
            lambda topic, _kind, body: sent.append((topic, body() if callable(body) else body))
        )
        runtime.on_connected()
    return sent


def busy_service(vehicles: int, *, traffic: bool, seed: int) -> tuple[MasterService, list[str]]:
    """A master whose every vehicle runs an order; the graph's node ids."""
    config = MasterConfig.model_validate(
        {"interface_name": INTERFACE, "traffic_control": traffic, "charge_below_pct": 0}
    )
    graph = load_graph(GRAPH)
    service = MasterService(config, graph, DroppingPublisher(), FakeClock())
    for topic, payload in fleet_messages(vehicles):
        service.ingest(topic, payload)
    nodes = sorted(graph.nodes)
    rng = random.Random(seed)
    for vehicle in list(service.fleet):
        if vehicle.agv in service.active:
            continue  # traffic control moved it out of another's way: busy already
        standing = vehicle.state.last_node_id if vehicle.state else ""
        goal = rng.choice([n for n in nodes if n != standing])
        service.create_order(OrderRequest(Target(destination=goal), vehicle.agv))
    return service, nodes


def finish(service: MasterService, order_id: str) -> None:
    """The vehicle drives its order node by node (the base grows as it goes) to its end."""
    plan = service.tracks[order_id].plan
    header = {"manufacturer": plan.agv.manufacturer, "serial_number": plan.agv.serial_number}
    topic = build_topic(INTERFACE, 2, plan.agv, Topic.STATE)
    for passed in range(plan.last_index + 1):
        track = service.tracks[order_id]
        done = passed == plan.last_index
        state = plan_state(
            plan,
            update_id=track.update_id,
            passed=passed,
            released_end=track.released_end,
            actions=dict.fromkeys(plan.action_ids(), ActionStatus.FINISHED) if done else None,
        )
        service.ingest(topic, encode(state.model_copy(update=header)))


def finishing_cpu_us(service: MasterService) -> list[float]:
    """Each vehicle's running order driven to its end in turn: CPU per order (every state of
    it, the last one serving the queue)."""
    spent = []
    for order_id in list(service.active.values()):
        start = time.process_time()
        finish(service, order_id)
        spent.append((time.process_time() - start) * 1e6)
    return spent


def run(args: argparse.Namespace) -> None:
    service, nodes = busy_service(args.vehicles, traffic=args.traffic, seed=args.seed)
    rng = random.Random(args.seed + 1)
    wave = [
        OrderRequest(Target(destination=rng.choice(nodes)), queue=True) for _ in range(args.orders)
    ]
    start = time.process_time()
    for request in wave:
        service.place_order(request)
    place_us = (time.process_time() - start) * 1e6 / len(wave)
    if len(service.queue) != len(wave):
        msg = f"{len(wave) - len(service.queue)} orders of the wave did not wait"
        raise RuntimeError(msg)
    start = time.process_time()
    service.serve_queue(service.clock.monotonic())
    pass_us = (time.process_time() - start) * 1e6
    served_us = finishing_cpu_us(service)
    served = args.orders - len(service.queue)
    baseline, _ = busy_service(args.vehicles, traffic=args.traffic, seed=args.seed)
    plain_us = finishing_cpu_us(baseline)
    ended = sum(1 for t in service.tracks.values() if t.status is OrderStatus.FINISHED)
    report = [
        (
            f"N = {args.vehicles} vehicles, M = {args.orders} queued orders, traffic control "
            f"{'on' if args.traffic else 'off'}"
        ),
        f"  place_order (queued):                        {place_us:8.0f} µs per order",
        f"  a pass over the queue, nobody free:          {pass_us:8.0f} µs",
        (
            f"  an order driven to its end, the next sent:   {statistics.median(served_us):8.0f} "
            f"µs median, {max(served_us):.0f} max ({served} sent from the queue, {ended} orders "
            "ended)"
        ),
        (
            f"  an order driven to its end, nothing queued: {statistics.median(plain_us):8.0f} µs "
            "median"
        ),
    ]
    print("\n".join(report))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=40)
    parser.add_argument("--orders", type=int, default=1000)
    parser.add_argument("--traffic", action="store_true", help="traffic control on")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(30))
    run(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
