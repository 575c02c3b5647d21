"""Fleet traffic benchmark (issue 9 §8): K vehicles take random transports on the warehouse.

Real processes on a private Mosquitto: ``vda-master`` (traffic control on or off) and one
``vda-vehicle --count K`` on ``config/graphs/warehouse.json``, the simulation running
``--time-lapse`` times faster. Every vehicle drives transports without end: to a random pick
station (``pick``), then to a random drop station (``drop``), ordered through ``POST /orders``.

An observer that is not the master reads every vehicle's ``visualization`` over MQTT (published
at ``--sample-hz`` of simulated time) and reports:

- the minimum distance between two vehicles, and separation violations (a pair coming closer
  than the safety distance, counted once per approach);
- deadlocks: orders that took (or, at the end, have taken) over 5x their free-flow time;
- throughput: orders finished per simulated hour;
- stretch: an order's time divided by its free-flow time (the same order with no other vehicle:
  the route master control gives a vehicle alone, at top speed, with its turns and its action;
  see :mod:`vda_fleetsim.workload`), mean and p95;
- the master's CPU (percent of one core, over the run) and ``POST /orders`` latency p50/p99 of
  the orders it created (201); requests refused meanwhile (409: the vehicle runs an order of
  master control's own, e.g. it was sent to park) are counted apart and asked again next round.

The client hears that an order is done from the vehicle's ``state`` over MQTT, confirms it from
``GET /vehicles`` (the vehicle's ``activeOrderId`` moved on; polled every 50 ms as well) and then
reads that order once (``GET /orders/{id}``). The master is told the time lapse
(``--time-lapse``), so traffic control's waits and margins are simulated seconds.

Run: PYTHONPATH=. python benchmarks/traffic.py [--vehicles 5 10 20] [--sim-hours 1]
     [--time-lapse 10] [--modes on off]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import statistics
import sys
import tempfile
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from tests.integration.mqtt_helpers import client_for
from tests.mosquitto import run_mosquitto
from tests.system.stack import ServiceProcess, process_env
from vda5050.broker import BrokerAddress
from vda_fleetsim.cli import add_any_station_option
from vda_fleetsim.workload import DEADLOCK_FACTOR, Separation, Transports, percentile
from vda_master.config import MasterConfig
from vda_master.graph import load_graph

REPO = Path(__file__).resolve().parents[1]
GRAPH = REPO / "config" / "graphs" / "warehouse.json"
#: master control's default (routing with traffic control counts one-lane metres this much)
ONE_LANE_COST_FACTOR = MasterConfig.model_fields["one_lane_cost_factor"].default
TICKS = os.sysconf("SC_CLK_TCK")
#: An action state's status once the action has ended.
ENDED_ACTIONS = frozenset({"FINISHED", "FAILED"})
#: How long after a state showed an order done the client keeps asking every 2 ms whether
#: master control has taken it (it reads the same state from the broker).
LAG_S = 0.2


@dataclass
class Observer(Separation):
    """The separation observer, plus each vehicle's latest heading (for free-flow times) and
    the orders its states show done (nothing left to drive, every action ended): the client
    asks master control at once instead of at its next poll, as a plant's system that listens
    to its vehicles would. At time lapse 10 a 50 ms poll is half a simulated second."""

    headings: dict[str, float] = field(default_factory=dict)
    #: orderId -> when a state first showed it done (time.monotonic())
    done: dict[str, float] = field(default_factory=dict)
    ended: asyncio.Event = field(default_factory=asyncio.Event)

    def see_state(self, payload: dict[str, Any]) -> None:
        order_id = payload.get("orderId")
        if (
            order_id
            and order_id not in self.done
            and not payload.get("nodeStates")
            and not payload.get("edgeStates")
            and not payload.get("driving")
            and all(a.get("actionStatus") in ENDED_ACTIONS for a in payload.get("actionStates", ()))
        ):
            self.done[order_id] = time.monotonic()
            self.ended.set()


@dataclass
class Orders:
    """Order times (simulated seconds) against their free-flow times."""

    stretches: list[float] = field(default_factory=list)
    finished: int = 0
    deadlocked: int = 0
    post_ms: list[float] = field(default_factory=list)
    refused: int = 0


@asynccontextmanager
async def observing(address: BrokerAddress, interface: str) -> AsyncIterator[Observer]:
    observer = Observer()

    async def listen() -> None:
        async with client_for(address) as client:
            await client.subscribe(f"{interface}/v2/+/+/visualization")
            await client.subscribe(f"{interface}/v2/+/+/state")
            async for message in client.messages:
                payload = json.loads(message.payload)
                if str(message.topic).endswith("/state"):
                    observer.see_state(payload)
                    continue
                position = payload.get("agvPosition")
                if position:
                    serial = str(message.topic).split("/")[3]
                    observer.headings[serial] = position["theta"]
                    observer.see(serial, position["x"], position["y"])

    async with asyncio.TaskGroup() as group:
        task = group.create_task(listen(), name="bench.observer")
        try:
            yield observer
        finally:
            task.cancel()


def cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


async def order(
    leg: tuple[str, str, str | None],
    *,
    http: httpx.AsyncClient,
    api: str,
    transports: Transports,
    headings: dict[str, float],
    stats: Orders,
    running: dict[str, tuple[str, float, float]],
) -> None:
    """``POST /orders`` for one vehicle's next leg (serial, action type, destination; None: any
    station of the action's type)."""
    serial, action, target = leg
    body = {
        "manufacturer": "vda-sim",
        "serialNumber": serial,
        **({"stationType": action} if target is None else {"destination": target}),
        "destinationActions": [
            {"actionType": action, "actionParameters": [{"key": "loadType", "value": "EPAL"}]}
        ],
    }
    started = time.perf_counter()
    answer = await http.post(f"{api}/orders", json=body)
    took_ms = (time.perf_counter() - started) * 1000
    if answer.status_code != 201:
        # e.g. 409: master control sent the vehicle to park (traffic); tried again next
        # round. Not in the latencies, which are those of planned orders.
        stats.refused += 1
        return
    stats.post_ms.append(took_ms)
    start = answer.json()["order"]["nodes"][0]["nodeId"]
    free = transports.leg_free_flow_s(start, action, target, headings.get(serial))
    running[serial] = (answer.json()["orderId"], time.monotonic(), free)


async def drive(
    http: httpx.AsyncClient,
    api: str,
    serials: list[str],
    transports: Transports,
    seen: Observer,
    *,
    lapse: float,
    wall_s: float,
) -> Orders:
    """Transports without end for ``wall_s`` seconds; collects order statistics."""
    stats = Orders()
    running: dict[str, tuple[str, float, float]] = {}  # serial -> (orderId, start, free-flow)
    deadline = time.monotonic() + wall_s
    while time.monotonic() < deadline:
        seen.ended.clear()
        # A vehicle's order ended once it is no longer the vehicle's active order; only then
        # is the order itself read. (Listing every order 20 times a second was the heaviest
        # request the master answered, and its parsing loaded this process as well.)
        active = {
            v["serialNumber"]: v["activeOrderId"]
            for v in (await http.get(f"{api}/vehicles")).json()
        }
        now = time.monotonic()
        lagging = False  # a state showed the order done, master control has not taken it yet
        for serial, (order_id, started, free) in list(running.items()):
            if active.get(serial) == order_id:
                # asked again in 2 ms, for at most LAG_S after the state
                lagging = lagging or now - seen.done.get(order_id, -math.inf) < LAG_S
                continue
            state = (await http.get(f"{api}/orders/{order_id}")).json()["status"]
            if state == "FINISHED":
                stats.stretches.append((now - started) * lapse / free)
                stats.finished += 1
                stats.deadlocked += (now - started) * lapse > DEADLOCK_FACTOR * free
                del running[serial]
                transports.finished(serial)
            elif state in {"FAILED", "REJECTED", "CANCELLED"}:
                print(f"  order {order_id} of {serial} ended {state}", file=sys.stderr)
                del running[serial]
        for serial in [s for s in serials if s not in running]:
            # one after another: the latencies are those of one request, not of a queue
            await order(
                (serial, *transports.next_leg(serial)),
                http=http,
                api=api,
                transports=transports,
                headings=seen.headings,
                stats=stats,
                running=running,
            )
        if lagging:
            await asyncio.sleep(0.002)
        else:
            with suppress(TimeoutError):
                await asyncio.wait_for(seen.ended.wait(), 0.05)
    now = time.monotonic()
    stats.deadlocked += sum(
        1
        for _, started, free in running.values()
        if (now - started) * lapse > DEADLOCK_FACTOR * free
    )
    return stats


async def run(
    count: int,
    *,
    traffic: bool,
    sim_hours: float,
    lapse: float,
    hz: float,
    keep_logs: Path | None = None,
    master_args: tuple[str, ...] = (),
    any_station: frozenset[str] = frozenset(),
) -> dict[str, float]:
    interface = f"bench{count}{'on' if traffic else 'off'}"
    with tempfile.TemporaryDirectory() as folder, run_mosquitto(Path(folder) / "mosquitto") as mqtt:
        logs = Path(folder) if keep_logs is None else keep_logs / interface
        logs.mkdir(parents=True, exist_ok=True)
        api_port = 18_000 + count + (500 if traffic else 0)
        env = process_env()
        master = ServiceProcess(
            "master",
            ["vda_master", "--broker-url", mqtt.address.url, "--interface-name", interface,
             "--graph", str(GRAPH), "--api-port", str(api_port),
             "--log-level", "WARNING" if keep_logs is None else "INFO",
             "--data-dir", str(Path(folder) / "master-data"),
             # Traffic control's durations (max_wait_s and the rest) in simulated time.
             "--time-lapse", str(lapse),
             "--traffic-control" if traffic else "--no-traffic-control", *master_args],
            logs / "master.log", env,
        ).start()  # fmt: skip
        vehicles = ServiceProcess(
            "vehicles",
            ["vda_vehicle", "--broker-url", mqtt.address.url, "--interface-name", interface,
             "--graph", str(GRAPH), "--start-node", "P1", "--count", str(count),
             "--serial-number", "robot", "--time-lapse", str(lapse), "--tick-hz", "100",
             "--visualization-interval-s", str(1 / (hz * lapse)), "--log-level", "WARNING",
             # energy is not part of the transports: no battery drains, no vehicle is sent
             # to charge (docs/master.md, Charging)
             "--battery-drain-pct-per-m", "0"],
            logs / "vehicles.log", env,
        ).start()  # fmt: skip
        api = f"http://127.0.0.1:{api_port}"
        serials = [f"robot-{i}" for i in range(1, count + 1)]
        try:
            async with (
                httpx.AsyncClient(timeout=10) as http,
                observing(mqtt.address, interface) as seen,
            ):
                async with asyncio.timeout(60):
                    while True:
                        try:
                            views = (await http.get(f"{api}/vehicles")).json()
                            if sum(v["available"] for v in views) == count:
                                break
                        except httpx.TransportError:
                            pass
                        await asyncio.sleep(0.2)
                if master.process is None:
                    msg = "the master did not start"
                    raise RuntimeError(msg)
                cpu_before, wall_before = cpu_s(master.process.pid), time.monotonic()
                wall_s = sim_hours * 3600 / lapse
                factor = ONE_LANE_COST_FACTOR if traffic else 1.0
                transports = Transports(
                    load_graph(GRAPH), seed=count, one_lane_factor=factor, any_station=any_station
                )
                stats = await drive(
                    http, api, serials, transports, seen, lapse=lapse, wall_s=wall_s
                )
                cpu = (cpu_s(master.process.pid) - cpu_before) / (time.monotonic() - wall_before)
                if keep_logs is not None:  # what the fleet looked like at the end
                    for name, path in (("traffic", "/traffic"), ("vehicles", "/vehicles")):
                        answer = await http.get(f"{api}{path}")
                        (logs / f"{name}.json").write_text(answer.text)
        finally:
            await vehicles.stop()
            await master.stop()
    stretches = sorted(stats.stretches) or [math.nan]
    return {
        "min_m": seen.minimum_m,
        "violations": seen.violations,
        "deadlocks": stats.deadlocked,
        "orders_per_h": stats.finished / sim_hours,
        "stretch_mean": statistics.fmean(stretches),
        "stretch_p95": percentile(stats.stretches, 0.95),
        "master_cpu_pct": cpu * 100,
        "post_p50_ms": statistics.median(stats.post_ms),
        "post_p99_ms": sorted(stats.post_ms)[int(0.99 * (len(stats.post_ms) - 1))],
        "refused": stats.refused,
        "samples": seen.samples,
    }


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("--vehicles", type=int, nargs="+", default=[5, 10, 20])
    cli.add_argument("--modes", nargs="+", choices=["on", "off"], default=["off", "on"])
    cli.add_argument("--sim-hours", type=float, default=1.0)
    cli.add_argument("--time-lapse", type=float, default=10.0)
    cli.add_argument("--sample-hz", type=float, default=10.0, help="per simulated second")
    cli.add_argument("--keep-logs", type=Path, help="keep the services' logs (master at INFO) here")
    cli.add_argument(
        "--master-arg", action="append", default=[], help="one more vda-master flag (repeatable)"
    )
    add_any_station_option(cli)
    args = cli.parse_args()
    header = (
        f"{'K':>3} {'traffic':>7} {'min m':>6} {'viol':>5} {'dead':>5} {'orders/h':>9} "
        f"{'stretch':>8} {'p95':>6} {'cpu %':>6} {'POST p50/p99 ms':>16} {'refused':>7}"
    )
    print(
        f"{args.sim_hours} simulated hour(s) per run, time lapse {args.time_lapse}, "
        f"any station of type: {args.any_station or 'none'}"
    )
    print(header)
    for count in args.vehicles:
        for mode in args.modes:
            r = asyncio.run(
                run(
                    count,
                    traffic=mode == "on",
                    sim_hours=args.sim_hours,
                    lapse=args.time_lapse,
                    hz=args.sample_hz,
                    keep_logs=args.keep_logs,
                    master_args=tuple(args.master_arg),
                    any_station=frozenset(args.any_station),
                )
            )
            print(
                f"{count:>3} {mode:>7} {r['min_m']:>6.2f} {r['violations']:>5} "
                f"{r['deadlocks']:>5} {r['orders_per_h']:>9.0f} {r['stretch_mean']:>8.2f} "
                f"{r['stretch_p95']:>6.2f} {r['master_cpu_pct']:>6.1f} "
                f"{r['post_p50_ms']:>7.1f}/{r['post_p99_ms']:<8.1f} {r['refused']:>7}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
