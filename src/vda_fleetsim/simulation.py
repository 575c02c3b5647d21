"""A fleet on a fake clock: the real master service and the real simulated vehicles in one
process, messages passed with a fixed latency (docs/fleetsim.md).

Master control and the vehicles are the very objects ``vda-master`` and ``vda-vehicle`` run; only
MQTT is replaced by a queue that delivers every message ``latency_s`` after it was sent, in send
order, and time by a :class:`~vda5050.clock.FakeClock` advanced in steps of :data:`STEP_S`. So a
simulated hour of twenty vehicles takes a minute or two instead of an hour, and every run is
reproducible from its seed. Each vehicle takes transports (:mod:`vda_fleetsim.workload`) without
end: as soon as one order has ended (after ``client_delay_s``, a client's reaction time) it is
sent the next, as a plant's system would through ``POST /orders``.

Per run (:meth:`Simulation.report`): orders per simulated hour, the mean free-flow time of the
finished orders (the yardstick, which a change of layout or route cost moves), stretch (order time
over free-flow time) mean and p95, orders over :data:`~vda_fleetsim.workload.DEADLOCK_FACTOR`
times their free-flow time (finished or not), the closest approach of two vehicles and the
separation violations, deadlocks master control resolved, idle vehicles it moved out of another's
way, and how the vehicles spent their time. With ``profile_waits`` also what the waits were for
and where, and each slow order's story (:meth:`Simulation.dump`).
"""

from __future__ import annotations

import heapq
import itertools
import math
import statistics
from collections import defaultdict
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from vda5050.clock import FakeClock
from vda5050.graph_file import GraphFile
from vda5050.models.state import ActionStatus
from vda5050.topics import AgvId, Topic
from vda_fleetsim.workload import DEADLOCK_FACTOR, Pace, Separation, Transports, percentile
from vda_master.capabilities import ActionSpec
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderStatus
from vda_master.eta import FinishEstimates
from vda_master.graph import Graph, load_graph
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.stops import Stop
from vda_master.traffic import MoveToParking, Proposal
from vda_vehicle.action_catalog import default_catalog, for_version, with_durations
from vda_vehicle.config import VehicleSettings
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.service import VehicleService

MANUFACTURER: Final = "vda-sim"
#: Simulated seconds per step: the vehicles' tick and master control's.
STEP_S: Final = 0.05
ENDED: Final = {OrderStatus.FAILED, OrderStatus.REJECTED, OrderStatus.CANCELLED}
BUSY: Final = {ActionStatus.INITIALIZING, ActionStatus.RUNNING}
#: Simulated seconds after which every vehicle has reported (connection, factsheet, state):
#: the first transports go out then.
REPORTED_AFTER_S: Final = 2.0
#: What the simulated vehicles are set to unless the caller says otherwise: no visualization,
#: a state every 30 s besides those events send, and batteries that do not drain (energy is not
#: part of the transports: master control's energy management sends no vehicle to charge).
VEHICLE_DEFAULTS: Final[Mapping[str, object]] = {
    "visualization_interval_s": 0,
    "state_interval_s": 30.0,
    "battery_drain_pct_per_m": 0.0,
}


def first_parking_node(graph: Graph) -> str:
    """Where the fleet starts by default: the graph file's first ``parking`` node (the vehicles
    stand on it and the nodes after it, in file order), else its first node."""
    parking = graph.station_nodes("parking")
    return parking[0] if parking else next(iter(graph.nodes))


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
    #: seconds waited at each node, by what was in the way (with profile_waits)
    waits: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))
    #: free-flow seconds of the route master control first gave it (above ``free_flow_s``:
    #: a detour planned around the others' passages)
    planned_s: float = 0.0
    #: traffic control's resolutions that changed this order's route (with profile_waits)
    resolutions: list[str] = field(default_factory=list)
    #: the resolved deadlocks this vehicle was a member of during the order (with profile_waits)
    deadlocks: list[str] = field(default_factory=list)
    #: master control's expectedFinishAt (simulated s) at creation, the same with nothing
    #: learned, and once half the time it expected has passed (docs/master.md *Expected finish*)
    eta: float | None = None
    eta_unlearned: float | None = None
    eta_halfway: float | None = None


@dataclass
class Results:
    finished: int = 0
    #: seconds from each finished order's creation to its end
    durations: list[float] = field(default_factory=list)
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
    #: seconds waited, by "resource kind: what the blocker did" (with profile_waits)
    waits: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))
    #: seconds waited, by the node the waiting vehicle stood on (with profile_waits)
    wait_nodes: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))
    #: the orders over the deadlock factor: what they were and what they waited for (profile_waits)
    slow: list[str] = field(default_factory=list)
    #: finished orders by stretch band: [orders, of them in a resolved deadlock] (profile_waits)
    bands: defaultdict[str, list[int]] = field(default_factory=lambda: defaultdict(lambda: [0, 0]))
    #: per finished order, how much later than expectedFinishAt it finished, over its duration:
    #: as expected at creation, the same with nothing learned, and halfway
    eta_errors: dict[str, list[float]] = field(
        default_factory=lambda: {"created": [], "unlearned": [], "halfway": []}
    )


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
        vehicle_settings: Mapping[str, object] | None = None,
        start_node: str | None = None,
        safety_m: float | None = None,
    ) -> None:
        """``settings``: master control's configuration keys (``traffic_control`` and the like);
        ``vehicle_settings``: the simulated vehicles' (``speed_max_mps``, ``length_m``, ...; the
        fleet's identity, count, tick and graph are the simulation's); ``start_node``: where
        the first vehicle stands, the others on the graph file's next nodes (default
        :func:`first_parking_node`); ``safety_m``: the distance below which two vehicles count
        as a separation violation (default master control's safety distance once it is known)."""
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
        vehicle = VehicleSettings.model_validate(
            {**VEHICLE_DEFAULTS, **(vehicle_settings or {}), "graph": str(graph_path),
             "start_node": start_node or first_parking_node(graph), "count": count,
             "manufacturer": MANUFACTURER, "serial_number": "robot", "tick_hz": 1 / STEP_S}
        )  # fmt: skip
        self.vehicles = VehicleService(
            vehicle, GraphFile.model_validate_json(graph_path.read_bytes()), clock=self.clock
        )
        self.runtimes = {r.agv.serial_number: r for r in self.vehicles.runtimes}
        self.master = MasterService(config, graph, ToVehicles(self.wire, self.runtimes), self.clock)
        for runtime in self.runtimes.values():
            runtime.attach(self._to_master)
            runtime.on_connected()
        factor = config.one_lane_cost_factor if config.traffic_control else 1.0
        self.transports = Transports(
            graph, seed=seed, one_lane_factor=factor, any_station=any_station, pace=pace_of(vehicle)
        )
        self.separation = Separation() if safety_m is None else Separation(safety_m)
        self._safety_known = safety_m is not None
        self.running: dict[str, Running] = {}
        self.results = Results()
        self.profile_waits = False

        def noting(proposal: Proposal, now: float, vehicles: tuple[AgvId, ...]) -> None:
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

        self.master.coordinator.on_record = noting

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
            if now >= REPORTED_AFTER_S:
                if not self._safety_known:  # from their factsheets, as master control sees it
                    self.separation.safety_m = self.master.coordinator.safety_distance_m
                    self._safety_known = True
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
            if running.eta_halfway is None and status not in {*ENDED, OrderStatus.FINISHED}:
                self._expect(running, now)
            if status is OrderStatus.FINISHED:
                took = now - running.started
                self.results.finished += 1
                self.results.durations.append(took)
                self.results.stretches.append(took / running.free_flow_s)
                self.results.free_flows.append(running.free_flow_s)
                band = self.results.bands[_band(took / running.free_flow_s)]
                band[0] += 1
                band[1] += bool(running.deadlocks)
                self._eta_errors(running, now, took)
                if took > DEADLOCK_FACTOR * running.free_flow_s:
                    self.results.deadlocks += 1
                    self._note_slow(serial, running, took)
                self.transports.finished(serial)
                self._ended(serial, now)
            elif status in ENDED:
                self.results.failed += 1
                self._ended(serial, now)

    def _eta_errors(self, running: Running, now: float, took: float) -> None:
        errors = self.results.eta_errors
        for key, expected in (
            ("created", running.eta),
            ("unlearned", running.eta_unlearned),
            ("halfway", running.eta_halfway),
        ):
            if expected is not None:
                errors[key].append((now - expected) / took)

    def _expect(self, running: Running, now: float) -> None:
        """expectedFinishAt as master control gives it: at creation (also with nothing learned)
        and once half the time it expected then has passed."""
        eta = running.eta
        first = eta is None
        due = eta is not None and now - running.started >= (eta - running.started) / 2
        if not first and not (due and running.eta_halfway is None):
            return
        track = self.master.tracks[running.order_id]
        if first:
            running.eta = self.master.expected_finish_s(track)
            running.eta_unlearned = self.master.expected_finish_s(track, FinishEstimates())
        else:
            running.eta_halfway = self.master.expected_finish_s(track)

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
            self._expect(running, now)

    def _account(self, serial: str, runtime: VehicleRuntime) -> None:
        """What ``serial`` spends this step on; with ``profile_waits``, what its wait is for."""
        state = runtime.state
        wait = self.master.coordinator.controller.vehicle(AgvId(MANUFACTURER, serial)).wait
        if serial not in self.running:  # between transports, or at a charger
            doing = "charging" if state.charging else "no order"
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
            "order_s_mean": statistics.fmean(results.durations or [math.nan]),
            "order_s_p95": percentile(results.durations, 0.95),
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
            # with profile_waits: vehicle-seconds waited in traffic per node stood on
            "waited_at": dict(results.wait_nodes),
            # expectedFinishAt: finished later than expected by, over the order's duration
            "eta": {key: _error_figures(values) for key, values in results.eta_errors.items()},
        }

    def dump(self) -> str:
        """The fleet at the end, the biggest causes of waiting, the stretch bands and the slow
        orders' stories (with ``profile_waits``), as lines of text."""
        lines = []
        for serial, runtime in self.runtimes.items():
            order_id = self.master.active.get(AgvId(MANUFACTURER, serial))
            track = self.master.tracks.get(order_id) if order_id else None
            route = [n.node_id for n in track.plan.nodes] if track else []
            lines.append(f"  {serial:>9} at {runtime.state.last_node_id:>5} route {route}")
        lines += [f"  waited {s:8.0f} s at {key}" for key, s in _largest(self.results.waits)[:12]]
        lines.append(f"  waited where: {self._wait_places()}")
        bands = self.results.bands
        shares = ", ".join(
            f"{name} {bands[name][0]} ({bands[name][1] / bands[name][0]:.0%})"
            for name in BANDS
            if bands[name][0]
        )
        lines.append(f"  stretch bands (finished orders; of them in a resolved deadlock): {shares}")
        lines += [f"  slow: {line}" for line in self.results.slow]
        return "".join(f"{line}\n" for line in lines)

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


#: Stretch bands of :meth:`Simulation.dump`, from their lower bound: where the tail over 5x
#: builds up.
BANDS = {"<2x": 0.0, "2-3x": 2.0, "3-4x": 3.0, "4-5x": 4.0, ">=5x": DEADLOCK_FACTOR}


def _band(stretch: float) -> str:
    return next(name for name, low in reversed(BANDS.items()) if stretch >= low)


def _largest(seconds: Mapping[str, float]) -> list[tuple[str, float]]:
    return sorted(seconds.items(), key=lambda item: -item[1])


class ToVehicles:
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


def pace_of(vehicle: VehicleSettings) -> Pace:
    """The free-flow pace of ``vehicle``: its top speed and turning speed, and the time its pick
    (as long as its drop by default) takes."""
    catalog = with_durations(
        for_version(default_catalog(), vehicle.vda_version), vehicle.action_durations_s
    )
    pick = catalog["pick"]
    return Pace(vehicle.speed_max_mps, vehicle.angular_speed_max_radps, pick.init_s + pick.run_s)


def _error_figures(errors: list[float]) -> dict[str, float]:
    """Median and 90th percentile of the size of ``errors``, and their mean (the bias: above 0,
    orders finish later than expected)."""
    sizes = [abs(e) for e in errors]
    return {
        "p50": percentile(sizes, 0.5),
        "p90": percentile(sizes, 0.9),
        "bias": statistics.fmean(errors) if errors else math.nan,
    }
