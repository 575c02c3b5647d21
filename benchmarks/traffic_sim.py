"""Traffic control in a deterministic co-simulation (issue 9): the real master service and the
real simulated vehicles in one process on one fake clock, messages passed with a fixed latency.

``benchmarks/traffic.py`` measures the real stack over MQTT in real time; this one runs the same
transports (``benchmarks/transports.py``) without real time and without a broker: a simulated
hour of ten vehicles takes about half a minute, every run is reproducible from its seed, and a
change to traffic control or to the graph can be judged on several seeds before the real
benchmark confirms it. Per run: orders per simulated hour, the mean free-flow time of the
finished orders (the yardstick, which a change of layout or route cost can move), stretch (order
time / free-flow time) mean and p95, deadlocks (orders over 5x their free-flow time, finished or
not), the minimum distance between two vehicles, separation violations, deadlocks resolved by
master control, idle vehicles it moved out of another's way, and how the vehicles with an order
spent their time. ``--dump`` adds the fleet
at the end, what the waits were for (the kind of resource and what the vehicle waited on did)
and where (the kind of node the waiting vehicle stood on, the nodes most waited on), and each
order over 5x its free-flow time with the places it waited longest and whom it waited for
there, the free-flow time of the route it was first given (a planned way round shows above its
own free-flow time), the re-plans and back-offs that changed its route, and the resolved
deadlocks it was a member of (when, and how many vehicles); and the finished orders by stretch
band, each with the share of them that were members of a resolved deadlock.

Run: PYTHONPATH=. python benchmarks/traffic_sim.py [--vehicles 10 20] [--sim-hours 0.5]
     [--seeds 1 2 3 | --seeds 1-24] [--jobs 2] [--latency-ms 20] [--client-delay-ms 0]
     [--graph FILE] [--off] [--master-setting key=value]

``--client-delay-ms`` is how long (simulated) a vehicle whose order ended waits for its next
one; 0, the default, asks at once, in the step the order ended. The real benchmark's client
takes a poll round and an HTTP request, 0.1-0.5 s of simulated time at time lapse 10, in which
master control may already send the idle vehicle out of another's way; the ``parked`` column
counts those moves.

``--jobs N`` runs N simulations at once in worker processes (one per core; every run is
deterministic and independent, so the figures are those of a single process, printed in seed
order). A change to traffic control needs many seeds before its tail can be told from another
set of seeds' (docs/traffic.md, *Three ways to predict better*: about 18 seeds on each side for
a tail halved).
"""

from __future__ import annotations

import argparse
import contextlib
import heapq
import io
import itertools
import math
import statistics
import sys
from collections import defaultdict
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import structlog
import yaml

from benchmarks.transports import (
    DEADLOCK_FACTOR,
    Separation,
    Transports,
    add_any_station_option,
    percentile,
)
from vda5050.clock import FakeClock
from vda5050.graph_file import GraphFile
from vda5050.models.state import ActionStatus
from vda5050.topics import AgvId, Topic
from vda_master.capabilities import ActionSpec
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderStatus
from vda_master.graph import load_graph
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.stops import Stop
from vda_master.traffic import MoveToParking, Proposal
from vda_vehicle.config import VehicleSettings
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.service import VehicleService

REPO = Path(__file__).resolve().parents[1]
WAREHOUSE = REPO / "config" / "graphs" / "warehouse.json"
MANUFACTURER = "vda-sim"
STEP_S = 0.05
ENDED = {OrderStatus.FAILED, OrderStatus.REJECTED, OrderStatus.CANCELLED}
BUSY = {ActionStatus.INITIALIZING, ActionStatus.RUNNING}


@dataclass(order=True)
class _Delivery:
    at: float
    seq: int
    deliver: Callable[[], None] = field(compare=False)


class Wire:
    """Messages in flight, each delivered ``latency_s`` after it was sent, in send order."""

    def __init__(self, latency_s: float) -> None:
        self.latency_s = latency_s
        self._queue: list[_Delivery] = []
        self._seq = itertools.count()
        self._now = 0.0

    def send(self, deliver: Callable[[], None]) -> None:
        at = self._now + self.latency_s
        heapq.heappush(self._queue, _Delivery(at, next(self._seq), deliver))

    def deliver_due(self, now: float) -> None:
        self._now = now
        while self._queue and self._queue[0].at <= now:
            heapq.heappop(self._queue).deliver()


@dataclass
class Running:
    order_id: str
    started: float
    free_flow_s: float
    route: str = ""
    #: seconds spent driving and in actions (a detour shows as driving well above free flow)
    driving_s: float = 0.0
    action_s: float = 0.0
    #: seconds waited at each node, by what was in the way (with --dump)
    waits: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))
    #: free-flow seconds of the route master control first gave it (above ``free_flow_s``:
    #: a detour planned around the others' passages)
    planned_s: float = 0.0
    #: traffic control's resolutions that changed this order's route (with --dump)
    resolutions: list[str] = field(default_factory=list)
    #: the resolved deadlocks this vehicle was a member of during the order (with --dump)
    deadlocks: list[str] = field(default_factory=list)


@dataclass
class Results:
    finished: int = 0
    stretches: list[float] = field(default_factory=list)
    #: free-flow seconds of the finished orders: the yardstick of stretch and deadlocks, which a
    #: change of layout or route cost moves too (compare it before comparing those)
    free_flows: list[float] = field(default_factory=list)
    deadlocks: int = 0
    #: orders master control refused (the vehicle not yet available again: retried next step)
    refused: int = 0
    failed: int = 0
    #: idle vehicles master control sent out of another's way (towards parking)
    parking_moves: int = 0
    #: vehicle-seconds by what a vehicle was doing
    time: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))
    #: seconds waited, by "resource kind: what the blocker did" (with --dump)
    waits: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))
    #: seconds waited, by the node the waiting vehicle stood on (with --dump)
    wait_nodes: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))
    #: the orders over the deadlock factor: what they were and what they waited for (--dump)
    slow: list[str] = field(default_factory=list)
    #: finished orders by stretch band: [orders, of them members of a resolved deadlock] (--dump)
    bands: defaultdict[str, list[int]] = field(default_factory=lambda: defaultdict(lambda: [0, 0]))


class Simulation:
    """One run: ``count`` vehicles, a master, the wire between them, the transports."""

    def __init__(
        self,
        graph_path: Path,
        count: int,
        *,
        seed: int,
        latency_s: float,
        settings: dict[str, Any],
        any_station: frozenset[str] = frozenset(),
        client_delay_s: float = 0.0,
        two_stops: bool = False,
    ) -> None:
        self.clock = FakeClock()
        #: each transport (a pick, then a drop) is one order with two stops, not two orders
        self.two_stops = two_stops
        #: how long after a vehicle's order ended its next one is asked for (the real client's
        #: reaction time, in simulated seconds); until then the vehicle stands idle
        self.client_delay_s = client_delay_s
        self.ready_at: dict[str, float] = {}
        self.wire = Wire(latency_s)
        graph = self.graph = load_graph(graph_path)
        config = MasterConfig.model_validate(
            {"graph": str(graph_path), "confirm_timeout_s": 2.0, "tick_s": STEP_S, **settings}
        )
        self.vehicles = VehicleService(
            VehicleSettings.model_validate(
                {"graph": str(graph_path), "start_node": "P1", "count": count,
                 "manufacturer": MANUFACTURER, "serial_number": "robot", "tick_hz": 1 / STEP_S,
                 "visualization_interval_s": 0, "state_interval_s": 30.0,
                 # energy is not part of issue 9's transports: batteries do not drain, so
                 # master control's energy management sends no vehicle to charge
                 "battery_drain_pct_per_m": 0.0}
            ),
            GraphFile.model_validate_json(graph_path.read_bytes()),
            clock=self.clock,
        )  # fmt: skip
        self.runtimes = {r.agv.serial_number: r for r in self.vehicles.runtimes}
        self.master = MasterService(
            config, graph, _ToVehicles(self.wire, self.runtimes), self.clock
        )
        for runtime in self.runtimes.values():
            runtime.attach(self._to_master)
            runtime.on_connected()
        factor = config.one_lane_cost_factor if config.traffic_control else 1.0
        self.transports = Transports(
            graph, seed=seed, one_lane_factor=factor, any_station=any_station
        )
        self.separation = Separation()
        self.running: dict[str, Running] = {}
        self.results = Results()
        self.profile_waits = False
        record = self.master.coordinator.record

        def noting(proposal: Proposal, now: float, vehicles: tuple[AgvId, ...]) -> None:
            record(proposal, now, vehicles)
            if isinstance(proposal, MoveToParking):
                self.results.parking_moves += 1
            for member in vehicles:
                if (joined := self.running.get(member.serial_number)) is not None:
                    joined.deadlocks.append(f"{now - joined.started:.0f} s ({len(vehicles)})")
            running = self.running.get(proposal.agv.serial_number)
            if running is not None and not isinstance(proposal, MoveToParking):
                running.resolutions.append(
                    f"{type(proposal).__name__} at {now - running.started:.0f} s"
                    f" {proposal.extra_m:+.0f} m ({proposal.reason.split(' ')[0]})"
                )

        setattr(self.master.coordinator, "record", noting)  # noqa: B010 - a probe, not a patch

    def _to_master(self, topic: str, _kind: Topic, payload: bytes | Callable[[], bytes]) -> None:
        body = payload() if callable(payload) else payload
        self.wire.send(lambda: self.master.ingest(topic, body))

    def run(
        self, seconds: float, events: tuple[tuple[float, Callable[[], None]], ...] = ()
    ) -> None:
        """Simulate ``seconds``; each of ``events`` (simulated second, call) is called once
        that time has passed (a test changes the floor mid-run)."""
        now = 0.0
        due = sorted(events, key=lambda event: event[0])
        while now < seconds:
            now += STEP_S
            while due and due[0][0] <= now:
                due.pop(0)[1]()
            self.clock.advance(STEP_S)
            self.wire.deliver_due(now)
            for runtime in self.runtimes.values():
                runtime.tick(STEP_S, now)
            self.master.tick()
            for serial, runtime in self.runtimes.items():
                self.separation.see(serial, runtime.state.pose.x, runtime.state.pose.y)
                self._account(serial, runtime)
            self._collect(now)
            if now >= 2.0:  # the vehicles have reported
                self._dispatch(now)
        for serial, running in self.running.items():
            if now - running.started > DEADLOCK_FACTOR * running.free_flow_s:
                self.results.deadlocks += 1
                self._note_slow(serial, running, now - running.started)

    def _note_slow(self, serial: str, running: Running, took: float) -> None:
        if self.profile_waits:
            waits = ", ".join(f"{k} {v:.0f} s" for k, v in _largest(running.waits)[:4])
            self.results.slow.append(
                f"{serial} {running.route}: {took:.0f} s, free flow {running.free_flow_s:.0f} s;"
                f" drove {running.driving_s:.0f} s, actions {running.action_s:.0f} s,"
                f" waited {sum(running.waits.values()):.0f} s, most {waits};"
                f" planned {running.planned_s:.0f} s, then {', '.join(running.resolutions) or '-'};"
                f" in deadlocks at {', '.join(running.deadlocks) or '-'}"
            )

    def _collect(self, now: float) -> None:
        for serial, running in list(self.running.items()):
            status = self.master.tracks[running.order_id].status
            if status is OrderStatus.FINISHED:
                took = now - running.started
                self.results.finished += 1
                self.results.stretches.append(took / running.free_flow_s)
                self.results.free_flows.append(running.free_flow_s)
                band = self.results.bands[_band(took / running.free_flow_s)]
                band[0] += 1
                band[1] += bool(running.deadlocks)
                if took > DEADLOCK_FACTOR * running.free_flow_s:
                    self.results.deadlocks += 1
                    self._note_slow(serial, running, took)
                self.transports.finished(serial)
                self._ended(serial, now)
            elif status in ENDED:
                self.results.failed += 1
                self._ended(serial, now)

    def _ended(self, serial: str, now: float) -> None:
        del self.running[serial]
        self.ready_at[serial] = now + self.client_delay_s

    def _dispatch(self, now: float) -> None:
        for serial in [s for s in self.runtimes if s not in self.running]:
            if self.ready_at.get(serial, 0.0) > now:
                continue
            action, destination = self.transports.next_leg(serial)
            spec = ActionSpec(action, None, {"loadType": "EPAL"})
            target = (
                Target(station_type=action)
                if destination is None
                else Target(destination=destination)
            )
            onward: tuple[Stop, ...] = ()
            if self.two_stops and action == "pick" and destination is not None:
                self.transports.finished(serial)  # the drop follows in the same order
                drop, drop_at = self.transports.next_leg(serial)
                drop_spec = ActionSpec(drop, None, {"loadType": "EPAL"})
                onward = (Stop(drop_at, None, (drop_spec,)),)
            request = OrderRequest(target, AgvId(MANUFACTURER, serial), (spec,), onward=onward)
            try:
                track = self.master.create_order(request)
            except RequestError:
                self.results.refused += 1
                if onward:
                    self.transports.finished(serial)  # a pick first again
                continue
            start = track.plan.nodes[0].node_id
            theta = self.runtimes[serial].state.pose.theta
            free = self.transports.leg_free_flow_s(start, action, destination, theta)
            for stop in onward:  # from the pick station, heading unknown
                free += self.transports.free_flow_s(
                    track.plan.destination, stop.destination or "", None
                )
            running = Running(track.order_id, now, free, f"{start}->{track.plan.destination}")
            if track.plan.route is not None:
                running.planned_s = self.transports.route_free_flow_s(track.plan.route, theta)
            self.running[serial] = running

    def _account(self, serial: str, runtime: VehicleRuntime) -> None:
        """What ``serial`` spends this step on; with ``profile_waits``, what its wait is for."""
        state = runtime.state
        wait = self.master.coordinator.controller.vehicle(AgvId(MANUFACTURER, serial)).wait
        if serial not in self.running:
            doing = "no order"
        elif state.driving:
            doing = "driving"
            self.running[serial].driving_s += STEP_S
        elif any(a.status in BUSY for a in state.actions):
            doing = "action"
            self.running[serial].action_s += STEP_S
        elif wait is not None:
            doing = "waits in traffic"
            if self.profile_waits:
                blockers = "+".join(sorted({self._doing(b.serial_number) for b in wait.blockers}))
                self.results.waits[f"{wait.resource.kind.value} {blockers}"] += STEP_S
                self.results.wait_nodes[wait.node_id] += STEP_S
                who = "+".join(sorted(b.serial_number for b in wait.blockers))
                self.running[serial].waits[f"{wait.node_id}<{who}({blockers})"] += STEP_S
        else:
            doing = "stopped, no wait"
        self.results.time[doing] += STEP_S

    def _doing(self, serial: str) -> str:
        state = self.runtimes[serial].state
        if self.master.coordinator.controller.vehicle(AgvId(MANUFACTURER, serial)).wait:
            return "waiting"
        if state.driving:
            return "driving"
        return "action" if any(a.status in BUSY for a in state.actions) else "standing"

    def report(self, count: int, hours: float) -> dict[str, Any]:
        snapshot = self.master.coordinator.snapshot(self.clock.monotonic()).as_json()
        results = self.results
        return {
            "orders_per_h": results.finished / hours,
            "stretch_mean": statistics.fmean(results.stretches or [math.nan]),
            "stretch_p95": percentile(results.stretches, 0.95),
            "free_flow_s": statistics.fmean(results.free_flows or [math.nan]),
            "deadlocks": results.deadlocks,
            "failed": results.failed,
            "min_m": self.separation.minimum_m,
            "violations": self.separation.violations,
            "resolved": snapshot.get("deadlocksResolved", 0),
            "parking_moves": results.parking_moves,
            "time": {k: v / (hours * 3600 * count) for k, v in _largest(results.time)},
        }

    def dump(self) -> None:
        """The fleet at the end, and the biggest causes of waiting."""
        for serial, runtime in self.runtimes.items():
            order_id = self.master.active.get(AgvId(MANUFACTURER, serial))
            track = self.master.tracks.get(order_id) if order_id else None
            route = [n.node_id for n in track.plan.nodes] if track else []
            print(f"  {serial:>9} at {runtime.state.last_node_id:>5} route {route}")
        for key, seconds in _largest(self.results.waits)[:12]:
            print(f"  waited {seconds:8.0f} s at {key}")
        print(f"  waited where: {self._wait_places()}")
        bands = self.results.bands
        print("  stretch bands (finished orders; of them in a resolved deadlock): " + ", ".join(
            f"{name} {bands[name][0]} ({bands[name][1] / bands[name][0]:.0%})"
            for name in BANDS if bands[name][0]
        ))  # fmt: skip
        for line in self.results.slow:
            print(f"  slow: {line}")

    def _wait_places(self) -> str:
        """Shares of the waiting by the kind of node the vehicle stood on (a station of a type,
        else a node on a one-way way: the ring's lanes, the bays, the passing places, else a node
        only one-lane edges touch: inside an aisle or a spur), and the nodes most waited on."""
        lanes = self.master.coordinator.controller.state.conflicts.lane_nodes
        nodes = self.results.wait_nodes
        total = sum(nodes.values()) or 1.0
        kinds: defaultdict[str, float] = defaultdict(float)
        for node_id, seconds in nodes.items():
            station = self.graph.nodes[node_id].station_type
            kinds[station or ("one-way" if node_id in lanes else "one-lane")] += seconds
        shares = ", ".join(f"{k} {v / total:.0%}" for k, v in _largest(kinds))
        most = ", ".join(f"{k} {v:.0f} s" for k, v in _largest(nodes)[:6])
        return f"{shares}; most on {most}"


#: Stretch bands of ``--dump``, from their lower bound: where the tail over 5x builds up.
BANDS = {"<2x": 0.0, "2-3x": 2.0, "3-4x": 3.0, "4-5x": 4.0, ">=5x": DEADLOCK_FACTOR}


def _band(stretch: float) -> str:
    return next(name for name, low in reversed(BANDS.items()) if stretch >= low)


def _largest(seconds: dict[str, float]) -> list[tuple[str, float]]:
    return sorted(seconds.items(), key=lambda item: -item[1])


class _ToVehicles:
    """The master's publisher: orders and instant actions go over the wire to the vehicle."""

    def __init__(self, wire: Wire, runtimes: dict[str, VehicleRuntime]) -> None:
        self._wire = wire
        self._runtimes = runtimes

    def publish(self, topic: str, kind: Topic, payload: bytes | Callable[[], bytes]) -> None:
        body = payload() if callable(payload) else payload
        runtime = self._runtimes[topic.split("/")[3]]
        if kind is Topic.ORDER:
            self._wire.send(lambda: runtime.handle_order(topic, body))
        elif kind is Topic.INSTANT_ACTIONS:
            self._wire.send(lambda: runtime.handle_instant_actions(topic, body))


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    cli.add_argument("--vehicles", type=int, nargs="+", default=[10])
    cli.add_argument("--sim-hours", type=float, default=0.5)
    cli.add_argument(
        "--seeds", type=seed_list, nargs="+", default=[[1, 2, 3]], help="seeds or ranges (1-24)"
    )
    cli.add_argument("--jobs", type=int, default=1, help="simulations run at once (processes)")
    cli.add_argument("--latency-ms", type=float, default=20.0)
    cli.add_argument(
        "--client-delay-ms",
        type=float,
        default=0.0,
        help="simulated ms from an order's end until the next one is asked for",
    )
    cli.add_argument("--graph", type=Path, default=WAREHOUSE)
    cli.add_argument("--off", action="store_true", help="traffic control off")
    cli.add_argument("--master-setting", action="append", default=[], help="key=value (YAML)")
    cli.add_argument("--dump", action="store_true", help="the fleet and the waits after each run")
    cli.add_argument(
        "--two-stops",
        action="store_true",
        help="each transport is one order with two stops (pick, then drop); orders/h then "
        "counts transports, and free flow and stretch are the whole transport's",
    )
    add_any_station_option(cli)
    args = cli.parse_args()
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(40))
    settings: dict[str, Any] = {"traffic_control": not args.off}
    for item in args.master_setting:
        key, _, value = item.partition("=")
        settings[key] = yaml.safe_load(value)
    print(f"{args.sim_hours} h per run, latency {args.latency_ms} ms, client delay "
          f"{args.client_delay_ms} ms, settings {settings}, "
          f"any station of type: {args.any_station or 'none'}, "
          f"{'an order of two stops' if args.two_stops else 'an order'} per transport leg"
          f"{'s' if args.two_stops else ''}")  # fmt: skip
    print(f"{'K':>3} {'seed':>4} {'orders/h':>9} {'ff s':>5} {'stretch':>8} {'p95':>6} "
          f"{'dead':>5} {'failed':>6} {'min m':>6} {'viol':>5} {'resolved':>8} {'parked':>6}"
          "  time")  # fmt: skip
    seeds = [seed for group in args.seeds for seed in group]
    runs = [
        SimRun(args.graph, count, seed, args.latency_ms / 1000, args.sim_hours, settings,
             frozenset(args.any_station), dump=args.dump,
             client_delay_s=args.client_delay_ms / 1000, two_stops=args.two_stops)
        for count in args.vehicles
        for seed in seeds
    ]  # fmt: skip
    reports: list[dict[str, Any]] = []
    for run, (r, dumped) in zip(runs, results_of(runs, args.jobs), strict=True):
        shares = ", ".join(f"{k} {v:.0%}" for k, v in r["time"].items())
        print(
            f"{run.count:>3} {run.seed:>4} {r['orders_per_h']:>9.0f} {r['free_flow_s']:>5.1f} "
            f"{r['stretch_mean']:>8.2f} "
            f"{r['stretch_p95']:>6.2f} {r['deadlocks']:>5} {r['failed']:>6} "
            f"{r['min_m']:>6.2f} {r['violations']:>5} {r['resolved']:>8} "
            f"{r['parking_moves']:>6}  {shares}",
            flush=True,
        )
        print(dumped, end="", flush=True)
        reports.append(r)
        if len(reports) == len(seeds):  # this K's last seed
            if len(reports) > 1:
                print(seeds_summary(run.count, reports, args.sim_hours), flush=True)
            reports = []
    return 0


def seed_list(text: str) -> list[int]:
    """A seed (``7``) or an inclusive range of seeds (``1-24``)."""
    first, dash, last = text.partition("-")
    try:
        low = int(first)
        high = int(last) if dash else low
    except ValueError:
        msg = f"{text!r}: a seed is a whole number, a range is like 1-24"
        raise argparse.ArgumentTypeError(msg) from None
    if high < low:
        msg = f"{text!r}: the range ends before it starts"
        raise argparse.ArgumentTypeError(msg)
    return list(range(low, high + 1))


@dataclass(frozen=True)
class SimRun:
    """One simulation to run: K vehicles, one seed."""

    graph: Path
    count: int
    seed: int
    latency_s: float
    sim_hours: float
    settings: dict[str, Any]
    any_station: frozenset[str]
    dump: bool = False
    client_delay_s: float = 0.0
    two_stops: bool = False


def simulate(run: SimRun) -> tuple[dict[str, Any], str]:
    """Run one simulation: its report, and what ``--dump`` prints about it ("" without)."""
    sim = Simulation(
        run.graph,
        run.count,
        seed=run.seed,
        latency_s=run.latency_s,
        settings=run.settings,
        any_station=run.any_station,
        client_delay_s=run.client_delay_s,
        two_stops=run.two_stops,
    )
    sim.profile_waits = run.dump
    sim.run(run.sim_hours * 3600)
    dumped = io.StringIO()
    if run.dump:
        with contextlib.redirect_stdout(dumped):
            sim.dump()
    return sim.report(run.count, run.sim_hours), dumped.getvalue()


def results_of(runs: list[SimRun], jobs: int) -> Iterator[tuple[dict[str, Any], str]]:
    """The runs' results in their order, ``jobs`` simulated at once (forked workers, which
    inherit this process's modules as they are)."""
    if jobs <= 1 or len(runs) <= 1:
        yield from map(simulate, runs)
        return
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        yield from pool.map(simulate, runs)


def seeds_summary(count: int, reports: list[dict[str, Any]], sim_hours: float) -> str:
    """One line over the seeds of one K: the orders over 5x summed (and per simulated hour),
    throughput and stretch averaged. A change to traffic control is judged on this line, over
    enough seeds: the same code gave 57, 75 and 56 over 5x on three sets of eight seeds at
    K = 20 (docs/traffic.md)."""
    slow = sum(r["deadlocks"] for r in reports)
    hours = sim_hours * len(reports)
    return (
        f"{count:>3}  all: {len(reports)} seeds, {slow} orders over {DEADLOCK_FACTOR:g}x "
        f"({slow / hours:.1f} per simulated hour, per seed "
        f"{'/'.join(str(r['deadlocks']) for r in reports)}), "
        f"{statistics.mean(r['orders_per_h'] for r in reports):.0f} orders/h, "
        f"stretch {statistics.mean(r['stretch_mean'] for r in reports):.2f}, "
        f"{sum(r['parking_moves'] for r in reports)} moves out of the way"
    )


if __name__ == "__main__":
    sys.exit(main())
