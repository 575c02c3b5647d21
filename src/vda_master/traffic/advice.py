"""What the shell should do about traffic now, derived from the state (issue 9 §3).

- deadlocks: groups of waiting vehicles that wait for each other, each with a proposal
  (:func:`vda_master.traffic.waits.propose_resolution`);
- over-long waits: a vehicle that has waited ``max_wait_s`` gets a detour avoiding what the
  vehicles it waits for hold, if the detour's extra driving takes less time than it has waited;
- idle vehicles in the way: idle vehicles that a waiting vehicle waits for (or, after
  ``assign``, that stand on a vehicle's route) are sent to a free parking node;
- a new route not straight into a cycle (:func:`facing`, :func:`route_not_facing`): a route
  whose first step needs what a vehicle holds that waits for the planning vehicle, or is about
  to, is looked for again around every such vehicle.

A vehicle for which the shell carried out a proposal less than ``max_wait_s`` ago is left out,
so that one situation is not resolved twice while the first resolution is still under way; a
vehicle detoured for deadlocks too often lately gets no further deadlock detour (a livelock
guard, :func:`vda_master.traffic.state.detoured_too_often`). Finding the deadlocks is linear
in the waiting vehicles and their waits; each group costs a detour and a back-off search per
member, each over-long wait a detour search, each idle vehicle in the way one parking search
(shared by all waiting for it; a :class:`~vda_master.traffic.waits.SearchBudget` bounds how many
one request or look makes).
"""

from __future__ import annotations

from collections.abc import Container, Iterable
from dataclasses import dataclass
from functools import partial

from vda5050.topics import AgvId
from vda_master.routing import Route
from vda_master.traffic.conflicts import ConflictMap, Resource
from vda_master.traffic.gate import next_step, route_resources
from vda_master.traffic.paths import route_avoiding
from vda_master.traffic.snapshot import Advice
from vda_master.traffic.state import (
    TrafficState,
    VehicleTraffic,
    detoured_too_often,
    resolving,
    stuck_of,
    waiters_of,
)
from vda_master.traffic.waits import (
    BackOff,
    Deadlock,
    MoveToParking,
    ParkingSearch,
    Replan,
    SearchBudget,
    Stuck,
    Wait,
    find_deadlocks,
    first_step,
    propose_detour,
    propose_parking,
    propose_resolution,
    waiting_for_group,
)


def advise(state: TrafficState, now: float, budget: SearchBudget | None = None) -> Advice:
    """Deadlocks with resolutions, over-long waits to re-plan, idle vehicles to move away
    (``budget``: how many idle vehicles' parking places may be looked for)."""
    found = deadlocks(state, now)
    in_deadlock = {agv for deadlock in found for agv in deadlock.vehicles}
    moves = idle_blockers(state, now, budget)
    return Advice(found, overdue(state, now, skip=in_deadlock), moves)


def deadlocks(state: TrafficState, now: float) -> tuple[Deadlock, ...]:
    """Groups of waiting vehicles that wait for each other, each with a proposal."""
    found = []

    def wait_of(agv: AgvId) -> Wait | None:
        return state.vehicle(agv).wait

    for group in find_deadlocks(state.waiting, wait_of):
        if any(resolving(state, agv, now) for agv in group):
            continue
        members = [_stuck(state, agv) for agv in group]
        stalled = waiting_for_group(group, partial(waiters_of, state))
        worn = [agv for agv in group if detoured_too_often(state, agv, now)]
        reason = "deadlock"
        if worn:
            reason += f" (no further detour for {', '.join(map(str, worn))}: detoured too often)"
        proposal = propose_resolution(
            state.roads, state.table, members, reason, stalled=stalled, no_detour=worn
        )
        found.append(Deadlock(group, proposal))
    return tuple(found)


def overdue(
    state: TrafficState, now: float, skip: Iterable[AgvId] = ()
) -> tuple[Replan | BackOff, ...]:
    """Detours for vehicles that have waited ``max_wait_s`` or longer."""
    found: list[Replan | BackOff] = []
    for agv in sorted(state.waiting.difference(skip), key=str):
        wait = state.vehicle(agv).wait
        if wait is None or resolving(state, agv, now):
            continue
        if now - wait.since < state.settings.max_wait_s:
            continue
        detour = propose_detour(state.roads, state.table, _stuck(state, agv), "max_wait")
        if detour is not None and _worth_it(state, agv, detour, now - wait.since):
            found.append(detour)
    return tuple(found)


def _worth_it(state: TrafficState, agv: AgvId, detour: Replan, waited_s: float) -> bool:
    """A detour is taken when its extra driving takes less time than the vehicle has waited so
    far (the wait expected to last about as long again): in a queue behind busy vehicles, a
    long way round costs the fleet more than it saves."""
    speed = state.vehicle(agv).speed or state.settings.speed
    return detour.extra_m / speed.speed_mps <= waited_s


def idle_blockers(
    state: TrafficState, now: float, budget: SearchBudget | None = None
) -> tuple[MoveToParking, ...]:
    """Idle vehicles that waiting vehicles wait for, each sent towards parking."""
    found: dict[AgvId, MoveToParking] = {}
    # one search per idle vehicle, shared by every vehicle waiting for it
    search = ParkingSearch(state.roads, state.table, budget)
    for agv in sorted(state.waiting, key=str):
        vehicle = state.vehicle(agv)
        if vehicle.wait is not None:
            candidates = vehicle.wait.blockers.difference(found)
            taken = {move.node_id for move in found.values()}
            for move in _move_idle(state, vehicle, candidates, now, taken=taken, search=search):
                found[move.agv] = move
    return tuple(found.values())


def in_the_way(
    state: TrafficState, agv: AgvId, now: float, budget: SearchBudget | None = None
) -> tuple[MoveToParking, ...]:
    """Idle vehicles standing on (or too close to) what is left of ``agv``'s route."""
    vehicle = state.vehicle(agv)
    if vehicle.route is None:
        return ()
    remaining = route_resources(vehicle.route, vehicle.progress, len(vehicle.route.edge_ids))
    blockers = state.table.blockers(agv, remaining)
    search = ParkingSearch(state.roads, state.table, budget)
    return _move_idle(state, vehicle, blockers, now, taken=(), search=search)


def facing(state: TrafficState, agv: AgvId, route: Route) -> frozenset[AgvId]:
    """The vehicles that wait for ``agv`` or are about to, when ``route``'s first step (up to
    its first waiting node) needs something one of them holds; else nothing. Waiting for
    ``agv`` or about to: vehicles whose next step (beyond their base) needs what ``agv`` holds,
    and every vehicle waiting for ``agv`` or for one of those, directly or through other waiting
    vehicles. ``agv`` starting that way would only close a cycle with them: a vehicle that has
    just picked in an aisle, sent back out the way another vehicle is coming in to reach the
    place it stands on (the deadlock detours' rule, applied to new routes). O(first step x
    conflict-set size); only when that step is taken, O(fleet x step) more."""
    blockers = state.table.blockers(agv, first_step(state.conflicts, route))
    if not blockers:
        return frozenset()
    near = state.conflicts.closure(state.table.held_by(agv))  # conflicts are symmetric
    coming = [
        other
        for other, vehicle in state.vehicles.items()
        if other != agv and _next_needs(state.conflicts, vehicle, near)
    ]
    expecting = waiting_for_group((agv, *coming), partial(waiters_of, state))
    expecting = expecting.union(coming)
    return expecting if not blockers.isdisjoint(expecting) else frozenset()


def route_not_facing(
    state: TrafficState, start: str, destination: str, vehicles: frozenset[AgvId]
) -> Route | None:
    """A route from ``start`` that avoids what ``vehicles`` (:func:`facing`) hold, conflicts
    included; None if there is none."""
    held = frozenset().union(*(state.table.held_by(other) for other in vehicles))
    route = route_avoiding(state.roads, start, destination, state.conflicts.closure(held))
    return route if route is not None and route.edge_ids else None


def _next_needs(conflicts: ConflictMap, vehicle: VehicleTraffic, near: frozenset[Resource]) -> bool:
    """Whether ``vehicle``'s next step (beyond the end of its base) needs one of ``near``."""
    route = vehicle.route
    if route is None or vehicle.granted_end >= len(route.edge_ids):
        return False
    _, step = next_step(conflicts, route, vehicle.granted_end)
    return not near.isdisjoint(step)


def _stuck(state: TrafficState, agv: AgvId) -> Stuck:
    stuck = stuck_of(state, state.vehicle(agv))
    if stuck is None:  # the waiting set only holds vehicles with a route and a wait
        msg = f"vehicle {agv} is in the waiting set without a wait"
        raise ValueError(msg)
    return stuck


def _move_idle(
    state: TrafficState,
    vehicle: VehicleTraffic,
    candidates: Iterable[AgvId],
    now: float,
    *,
    taken: Iterable[str],
    search: ParkingSearch,
) -> tuple[MoveToParking, ...]:
    """Parking moves for the idle ones among ``candidates``, out of ``vehicle``'s way; no two
    to the same node, none to another vehicle's destination or to a node in ``taken``."""
    route = vehicle.route
    if route is None:
        return ()
    idle = [
        (agv, other.node_id)
        for agv in sorted(candidates, key=str)
        if (other := state.vehicle(agv)).route is None
        and other.node_id is not None
        and not resolving(state, agv, now)
    ]
    if not idle:  # most waits are behind vehicles that drive: no way to work out
        return ()
    remaining = route_resources(route, vehicle.progress, len(route.edge_ids))
    way = state.conflicts.closure(remaining)
    chosen = set(taken)
    destinations = _Either(state.destinations, chosen)
    found = []
    for agv, node_id in idle:
        move = propose_parking(
            state.roads,
            state.table,
            agv,
            node_id,
            way=way,
            taken=destinations,
            reason=f"in the way of {vehicle.agv}",
            search=search,
        )
        if move is not None:
            found.append(move)
            chosen.add(move.node_id)
    return tuple(found)


@dataclass(frozen=True, slots=True)
class _Either:
    """Nodes in either container (other vehicles' destinations, or chosen just now)."""

    first: Container[str]
    second: Container[str]

    def __contains__(self, node_id: object) -> bool:
        return node_id in self.first or node_id in self.second
