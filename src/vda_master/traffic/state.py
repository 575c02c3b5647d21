"""The traffic controller's immutable state and its transitions (pure functions over it).

:class:`TrafficState` holds the reservation table, the planned passages, one
:class:`VehicleTraffic` per vehicle and two indexes kept in step with the vehicles' waits. The
functions here are the building blocks of :class:`vda_master.traffic.controller.TrafficController`;
each returns a new state and touches O(route) entries.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from vda5050.topics import AgvId
from vda_master.routing import Route
from vda_master.traffic.conflicts import ConflictMap, Resource, node
from vda_master.traffic.gate import Blocked, route_resources
from vda_master.traffic.passages import (
    Passage,
    PassageSettings,
    PassageTable,
    SpeedModel,
    estimate_timeline,
    passages_of,
    standing,
)
from vda_master.traffic.paths import RoadMap
from vda_master.traffic.pmap import PMap
from vda_master.traffic.reservations import Refused, ReservationTable
from vda_master.traffic.snapshot import Resolution
from vda_master.traffic.waits import Stuck, Wait


@dataclass(frozen=True, slots=True)
class TrafficSettings:
    """``max_wait_s``: a wait this long gets a re-plan proposal; ``dwell_s``: how long a planned
    destination must stay free after arrival; ``history``: resolutions kept for the snapshot;
    ``one_lane_factor``: what a metre of one-lane edge costs routing (:mod:`.paths`);
    ``detour_repeats`` within ``detour_repeat_window_s``: how many deadlock detours one vehicle
    gets before its deadlocks are resolved otherwise (:func:`detoured_too_often`)."""

    max_wait_s: float = 60.0
    one_lane_factor: float = 1.0
    speed: SpeedModel = field(default_factory=SpeedModel)
    passages: PassageSettings = field(default_factory=PassageSettings)
    dwell_s: float = 5.0
    history: int = 20
    #: A route round the others' passages is taken only if expected this much earlier.
    detour_margin_s: float = 0.0
    detour_repeats: int = 3
    detour_repeat_window_s: float = 60.0
    #: An order is *late* once it has taken this many times its free-flow estimate; while a late
    #: vehicle waits, its refused step is claimed (:mod:`.priority`).
    late_stretch: float = 2.0
    #: An order is *due* at its start plus this many times its free-flow estimate (issue 9 counts
    #: an order slower than 5x as a deadlock); the earlier due claim goes first.
    due_stretch: float = 5.0
    #: The fleet is simulated this many times faster than the clock the controller is given
    #: (the master's wall clock): an edge's ``maxSpeed`` (simulated m/s) counts this many times
    #: over. The durations above are on the controller's clock (:meth:`at_time_lapse`).
    time_lapse: float = 1.0

    def at_time_lapse(self, time_lapse: float) -> TrafficSettings:
        """These settings for a fleet simulated ``time_lapse`` times faster than real time:
        every duration (waits, margins, expected stays, the default node time) divided, the
        default speed multiplied, relative to the lapse they were given for. A time-lapsed
        simulation then meets the same traffic control as one in real time; speeds from the
        vehicles' factsheets are as the vehicles state them (ours: already time-lapsed)."""
        if time_lapse <= 0:
            msg = f"time_lapse must be positive, got {time_lapse}"
            raise ValueError(msg)
        k = time_lapse / self.time_lapse
        if k == 1:
            return self
        passages = self.passages
        return replace(
            self,
            max_wait_s=self.max_wait_s / k,
            speed=replace(
                self.speed,
                speed_mps=self.speed.speed_mps * k,
                node_time_s=self.speed.node_time_s / k,
            ),
            passages=replace(passages, buffer_s=passages.buffer_s / k, hold_s=passages.hold_s / k),
            dwell_s=self.dwell_s / k,
            detour_margin_s=self.detour_margin_s / k,
            detour_repeat_window_s=self.detour_repeat_window_s / k,
            time_lapse=time_lapse,
        )


@dataclass(frozen=True, slots=True)
class VehicleTraffic:
    """What the controller knows about one vehicle."""

    agv: AgvId
    node_id: str | None = None
    route: Route | None = None
    progress: int = 0
    granted_end: int = 0
    speed: SpeedModel | None = None
    #: The latest refusal of the gate, while the base does not reach the desired end.
    blocked: Blocked | None = None
    #: Set while the vehicle stands at the end of its base and the next step is refused.
    wait: Wait | None = None
    #: A position that could not be reserved: another vehicle held a conflicting resource.
    unplaced: Refused | None = None
    #: When the shell last carried out a proposal for this vehicle (cleared by assign/finish).
    resolving_since: float | None = None
    #: When the shell re-planned this vehicle to resolve a deadlock, within the repeat window.
    deadlock_detours: tuple[float, ...] = ()
    #: When its order started and what it takes alone on the floor (re-plans and back-offs keep
    #: them; cleared when the order ends): how late it is (:mod:`.priority`).
    order_since: float | None = None
    free_flow_s: float | None = None


@dataclass(frozen=True, slots=True)
class TrafficState:
    """Everything the controller knows; replaced, never changed."""

    roads: RoadMap
    conflicts: ConflictMap
    settings: TrafficSettings
    table: ReservationTable
    passages: PassageTable = field(default_factory=PassageTable)
    vehicles: PMap[AgvId, VehicleTraffic] = field(default_factory=PMap)
    waiting: frozenset[AgvId] = frozenset()
    #: Blocker → the waiting vehicles that wait for it.
    waiters: PMap[AgvId, frozenset[AgvId]] = field(default_factory=PMap)
    #: Node id → the routed vehicle heading there (destinations are not parking candidates).
    destinations: PMap[str, AgvId] = field(default_factory=PMap)
    resolved: int = 0
    history: tuple[Resolution, ...] = ()

    def vehicle(self, agv: AgvId) -> VehicleTraffic:
        """What is known about ``agv`` (an empty record if nothing)."""
        return self.vehicles.get(agv) or VehicleTraffic(agv)

    def speed_of(self, agv: AgvId) -> SpeedModel:
        """The vehicle's speed model (the settings' default if none was given)."""
        return self.vehicle(agv).speed or self.settings.speed


def store(state: TrafficState, vehicle: VehicleTraffic) -> TrafficState:
    """``vehicle``'s record replaced (its wait must go through :func:`set_wait`)."""
    return replace(state, vehicles=state.vehicles.set(vehicle.agv, vehicle))


def set_wait(state: TrafficState, agv: AgvId, wait: Wait | None) -> TrafficState:
    """Record that ``agv`` waits (``wait``) or not (None), keeping both indexes right."""
    old = state.vehicle(agv).wait
    old_blockers = old.blockers if old else frozenset()
    new_blockers = wait.blockers if wait else frozenset()
    waiters = state.waiters
    for blocker in old_blockers - new_blockers:
        remaining = (waiters.get(blocker) or frozenset()) - {agv}
        waiters = waiters.set(blocker, remaining) if remaining else waiters.remove(blocker)
    for blocker in new_blockers - old_blockers:
        waiters = waiters.set(blocker, (waiters.get(blocker) or frozenset()) | {agv})
    waiting = state.waiting | {agv} if wait else state.waiting - {agv}
    vehicle = replace(state.vehicle(agv), wait=wait)
    return store(replace(state, waiters=waiters, waiting=waiting), vehicle)


def set_destination(state: TrafficState, agv: AgvId, destination: str | None) -> TrafficState:
    """``agv`` heads for ``destination`` (None: nowhere) instead of its current route's end."""
    destinations = state.destinations
    route = state.vehicle(agv).route
    if route is not None and destinations.get(route.destination) == agv:
        destinations = destinations.remove(route.destination)
    if destination is not None:
        destinations = destinations.set(destination, agv)
    return replace(state, destinations=destinations)


def waiters_of(state: TrafficState, agv: AgvId) -> frozenset[AgvId]:
    """The vehicles waiting for ``agv`` directly (the reverse index of waits)."""
    return state.waiters.get(agv) or frozenset()


def woken(state: TrafficState, agv: AgvId, *, freed: bool) -> tuple[AgvId, ...]:
    """The vehicles waiting for ``agv``, if ``agv`` freed something: longest waiting first, so
    that they ask for the freed resources in the order they came (first come, first served)."""
    if not freed:
        return ()
    waiters = waiters_of(state, agv)
    return tuple(sorted(waiters, key=lambda waiter: (_waiting_since(state, waiter), str(waiter))))


def _waiting_since(state: TrafficState, agv: AgvId) -> float:
    wait = state.vehicle(agv).wait
    return wait.since if wait is not None else float("inf")


def advance(
    state: TrafficState, agv: AgvId, progress: int, now: float
) -> tuple[TrafficState, tuple[AgvId, ...]]:
    """``agv`` passed its route's nodes up to ``progress``: free everything behind it."""
    vehicle = state.vehicle(agv)
    route = vehicle.route
    if route is None or progress <= vehicle.progress:
        return state, ()
    progress = min(progress, len(route.edge_ids))
    end = max(vehicle.granted_end, progress)
    keep = route_resources(route, progress, end)
    table = state.table.release(agv, state.table.held_by(agv).difference(keep))
    claimed = table.claim(agv, keep)  # holds more only if the vehicle went beyond its grant
    if isinstance(claimed, Refused):
        vehicle, claimed = replace(vehicle, unplaced=claimed), table
    moved = replace(vehicle, progress=progress, granted_end=end, node_id=route.node_ids[progress])
    new = estimate(store(replace(state, table=claimed), moved), agv, now)
    return new, woken(new, agv, freed=table is not state.table)


def adopt(state: TrafficState, agv: AgvId, released_end: int) -> TrafficState:
    """Hold a base the shell released beyond the grant, as far as it is free."""
    vehicle = state.vehicle(agv)
    route, end = vehicle.route, vehicle.granted_end
    if route is None or released_end <= end:
        return state
    table = state.table
    unplaced = None
    while end < min(released_end, len(route.edge_ids)):
        claimed = table.claim(agv, route_resources(route, end, end + 1))
        if isinstance(claimed, Refused):
            unplaced = claimed
            break
        table, end = claimed, end + 1
    adopted = replace(vehicle, granted_end=end, unplaced=unplaced or vehicle.unplaced)
    return store(replace(state, table=table), adopted)


def stand(
    state: TrafficState, agv: AgvId, node_id: str, now: float, *, force: bool = False
) -> tuple[TrafficState, tuple[AgvId, ...]]:
    """An idle vehicle holds exactly the node it stands on (if that node is free for it)."""
    wanted = frozenset({node(node_id)})
    if state.table.held_by(agv) == wanted and state.vehicle(agv).node_id == node_id and not force:
        return state, ()
    return _place(state, agv, wanted, standing(node_id, now), node_id)


def occupy(
    state: TrafficState, agv: AgvId, resources: frozenset[Resource], now: float
) -> tuple[TrafficState, tuple[AgvId, ...]]:
    """A vehicle without a route that stands off the graph's nodes (moved by hand, stopped
    between two nodes) holds every resource it covers (``resources``: those closer than the
    safety distance to where it reports itself), as far as they are free; it stands on no node,
    so it is not sent to park."""
    if state.table.held_by(agv) == resources and state.vehicle(agv).node_id is None:
        return state, ()
    occupied = tuple(Passage(resource, now, math.inf) for resource in sorted(resources))
    return _place(state, agv, resources, occupied, None)


def _place(
    state: TrafficState,
    agv: AgvId,
    wanted: frozenset[Resource],
    passages: tuple[Passage, ...],
    node_id: str | None,
) -> tuple[TrafficState, tuple[AgvId, ...]]:
    """A vehicle without a route holds ``wanted`` (what of it is free; the refusal is kept as
    ``unplaced``) and is expected there from now on; returns who it freed something for."""
    held = state.table.held_by(agv)
    table = state.table.replace(agv, wanted)
    unplaced = None
    if isinstance(table, Refused):
        unplaced, table = table, _shrink(state.table, agv, held & wanted)
    placed = replace(state.vehicle(agv), node_id=node_id, unplaced=unplaced)
    new = store(
        replace(state, table=table, passages=state.passages.with_vehicle(agv, passages)), placed
    )
    return new, woken(new, agv, freed=bool(held - wanted))


def hold_start(state: TrafficState, agv: AgvId, route: Route, progress: int) -> TrafficState:
    """On a new route, ``agv`` holds the node it stands on (node ``progress``) and nothing else."""
    vehicle = state.vehicle(agv)
    table = state.table.replace(agv, route_resources(route, progress, progress))
    unplaced = None
    if isinstance(table, Refused):
        unplaced, table = table, _shrink(state.table, agv, frozenset())
    return store(replace(state, table=table), replace(vehicle, unplaced=unplaced))


def _shrink(table: ReservationTable, agv: AgvId, keep: frozenset[Resource]) -> ReservationTable:
    """``agv`` keeps only ``keep`` (a subset of its holdings: always allowed)."""
    return table.release(agv, table.held_by(agv).difference(keep))


def estimate(state: TrafficState, agv: AgvId, now: float) -> TrafficState:
    """Re-estimate ``agv``'s passages from where it is now."""
    vehicle = state.vehicle(agv)
    if vehicle.route is None:
        return state
    timeline = estimate_timeline(
        state.roads, vehicle.route, state.speed_of(agv), start_time=now, from_index=vehicle.progress
    )
    passages = passages_of(
        vehicle.route, timeline, state.settings.passages, from_index=vehicle.progress
    )
    return replace(state, passages=state.passages.with_vehicle(agv, passages))


def resolving(state: TrafficState, agv: AgvId, now: float) -> bool:
    """A proposal for ``agv`` is under way: carried out less than ``max_wait_s`` ago, and the
    vehicle has not come to wait again since (a vehicle waiting again after its proposal was
    carried out shows that it did not help: it may be resolved anew)."""
    vehicle = state.vehicle(agv)
    since = vehicle.resolving_since
    if since is None or now - since >= state.settings.max_wait_s:
        return False
    return vehicle.wait is None or vehicle.wait.since < since


def detoured_too_often(state: TrafficState, agv: AgvId, now: float) -> bool:
    """``agv`` was re-planned for deadlocks ``detour_repeats`` times within the repeat window.

    A detour that leads into a new deadlock, resolved by re-planning the same vehicle back, is a
    livelock: the vehicle turns every second and never arrives. Whatever its cause, a vehicle
    that keeps being detoured gets no further detour for a while; its next deadlock is resolved
    by backing off or by moving another member."""
    settings = state.settings
    recent = recent_detours(state.vehicle(agv), now, settings.detour_repeat_window_s)
    return len(recent) >= settings.detour_repeats


def recent_detours(vehicle: VehicleTraffic, now: float, window_s: float) -> tuple[float, ...]:
    """The times of ``vehicle``'s deadlock detours less than ``window_s`` before ``now``."""
    return tuple(t for t in vehicle.deadlock_detours if now - t < window_s)


def stuck_of(state: TrafficState, vehicle: VehicleTraffic) -> Stuck | None:
    """What resolution needs to know about a waiting vehicle (None if it does not wait)."""
    route, wait = vehicle.route, vehicle.wait
    if route is None or wait is None:
        return None
    remaining = route_resources(route, vehicle.progress, len(route.edge_ids))
    left = sum(state.roads.length[e] for e in route.edge_ids[vehicle.progress :])
    return Stuck(
        vehicle.agv,
        route.node_ids[vehicle.progress],
        route.destination,
        left,
        frozenset(remaining),
        wait.blockers,
    )
