"""Who waits for whom, deadlocks, and how to resolve them (issue 9 §3).

A vehicle *waits* when it has reached the end of its released base (its last traversed node is
the base's last node) and the release gate refuses the next step. It waits for every vehicle
holding a resource that conflicts with that step (all of them must move: the AND model), so the
who-waits-for-whom graph has an arc from the waiting vehicle to each of those holders.

A **deadlock** is a set of waiting vehicles that wait for each other in a cycle: none of them
moves, so none of their holdings is ever freed. :func:`find_deadlocks` reports each strongly
connected component of the graph with two or more vehicles (each contains a cycle).

**Resolutions are values** (:data:`Proposal`), for the master shell to carry out:

- :class:`Replan`: the vehicle drives to its destination on a route that avoids every resource
  conflicting with what the vehicles it waits for (and, in a deadlock, every other member of
  it) hold: an order update from where it waits. In a deadlock, the route must not start
  towards a vehicle that itself waits for the deadlock (it would not move, and only form a new
  cycle);
- :class:`BackOff`: the vehicle drives back to the nearest node it can reach over free resources
  that lies off the other cycle members' remaining routes and waits there; the shell re-plans
  it to its destination once it has arrived (a route through the back-off node would not stop
  there when the node lies on a one-lane spur: see the release gate's waiting nodes);
- :class:`MoveToParking`: an idle vehicle in the way drives to a free parking node (else to the
  nearest free node off the way that is no station), never one another vehicle heads for.

**Which vehicle moves** (:func:`propose_resolution`): every member's detour and back-off are
costed in extra metres over its remaining route; the cheapest wins, a detour before a back-off
at equal cost, then the lowest vehicle id (``manufacturer/serial``). The rule is deterministic
and moves the vehicle whose plan changes least.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Container, Iterable, Mapping, Sequence
from dataclasses import dataclass

from vda5050.topics import AgvId
from vda_master.routing import Route
from vda_master.traffic.conflicts import ConflictMap, Resource, edge, node
from vda_master.traffic.gate import next_waiting_index, route_resources
from vda_master.traffic.paths import (
    RoadMap,
    distances,
    path_to,
    route_avoiding,
    to_destination,
)
from vda_master.traffic.reservations import ReservationTable


@dataclass(frozen=True, slots=True)
class Wait:
    """A vehicle stopped at the end of its base; the gate refuses the next step."""

    #: Every vehicle holding something the refused step conflicts with.
    blockers: frozenset[AgvId]
    #: The first resource of the step that is not free.
    resource: Resource
    #: The node it waits on.
    node_id: str
    since: float


@dataclass(frozen=True, slots=True)
class Stuck:
    """What resolution needs to know about one waiting vehicle."""

    agv: AgvId
    node_id: str
    destination: str
    #: Metres still to drive on its current route.
    remaining_m: float
    #: Resources its current route still needs, from where it waits to its destination.
    remaining: frozenset[Resource]
    blockers: frozenset[AgvId]


@dataclass(frozen=True, slots=True)
class Replan:
    """Drive ``route`` (from where the vehicle waits to its destination) instead."""

    agv: AgvId
    route: Route
    avoid: frozenset[Resource]
    extra_m: float
    reason: str


@dataclass(frozen=True, slots=True)
class BackOff:
    """Drive ``route`` back to ``node_id`` (free, off the others' way) and wait there; then
    re-plan to ``resume_to``, the destination of the interrupted route."""

    agv: AgvId
    node_id: str
    #: From where the vehicle waits to ``node_id``.
    route: Route
    resume_to: str
    #: Metres added: back off, then from ``node_id`` to ``resume_to``, minus the current route.
    extra_m: float
    reason: str


@dataclass(frozen=True, slots=True)
class MoveToParking:
    """Move an idle vehicle along ``route`` to ``node_id`` (a parking node when one is free)."""

    agv: AgvId
    node_id: str
    route: Route
    reason: str


Proposal = Replan | BackOff | MoveToParking


@dataclass(frozen=True, slots=True)
class Deadlock:
    """Vehicles that wait for each other in a cycle, and the proposed way out (if any)."""

    vehicles: tuple[AgvId, ...]
    proposal: Replan | BackOff | None


def find_deadlocks(
    waiting: Iterable[AgvId], wait_of: Callable[[AgvId], Wait | None]
) -> list[tuple[AgvId, ...]]:
    """Groups of waiting vehicles that wait for each other (Tarjan's strongly connected
    components of the wait-for graph restricted to waiting vehicles), each sorted by id."""
    arcs: dict[AgvId, list[AgvId]] = {}
    for agv in sorted(waiting, key=str):
        wait = wait_of(agv)
        if wait is not None:
            arcs[agv] = sorted(wait.blockers, key=str)
    arcs = {agv: [b for b in out if b in arcs] for agv, out in arcs.items()}
    groups = [sorted(group, key=str) for group in _components(arcs) if len(group) > 1]
    return sorted((tuple(group) for group in groups), key=lambda g: str(g[0]))


def waiting_for_group(
    group: Collection[AgvId], waiters_of: Callable[[AgvId], Iterable[AgvId]]
) -> frozenset[AgvId]:
    """Waiting vehicles outside ``group`` that wait for a member of it, directly or through
    other waiting vehicles: none of them moves before the group does. ``waiters_of(agv)``: the
    vehicles waiting for ``agv`` (the state's reverse index of waits)."""
    found: set[AgvId] = set(group)
    frontier = list(group)
    while frontier:
        for waiter in waiters_of(frontier.pop()):
            if waiter not in found:
                found.add(waiter)
                frontier.append(waiter)
    return frozenset(found.difference(group))


def _components(arcs: Mapping[AgvId, list[AgvId]]) -> list[list[AgvId]]:
    """Strongly connected components: the vehicles each one reaches and is reached from.

    Quadratic in the number of waiting vehicles, which stays small; simpler than Tarjan.
    """
    reach = {agv: _reachable(arcs, agv) for agv in arcs}
    found: list[list[AgvId]] = []
    placed: set[AgvId] = set()
    for agv in arcs:
        if agv not in placed:
            group = [other for other in reach[agv] if agv in reach[other]]
            placed.update(group)
            found.append(group)
    return found


def _reachable(arcs: Mapping[AgvId, list[AgvId]], origin: AgvId) -> set[AgvId]:
    """``origin`` and every vehicle it reaches along ``arcs``."""
    seen = {origin}
    todo = [origin]
    while todo:
        for target in arcs[todo.pop()]:
            if target not in seen:
                seen.add(target)
                todo.append(target)
    return seen


def propose_resolution(
    roads: RoadMap,
    table: ReservationTable,
    members: Sequence[Stuck],
    reason: str,
    *,
    stalled: Collection[AgvId] = (),
    no_detour: Collection[AgvId] = (),
) -> Replan | BackOff | None:
    """The cheapest way to let ``members`` move on (see the module docstring), or None.

    ``stalled``: vehicles waiting for the group (:func:`waiting_for_group`); a detour must not
    start towards one of them (see :func:`propose_detour`). ``no_detour``: members that may
    only back off or wait for another member to move."""
    options: list[tuple[float, int, str, Replan | BackOff]] = []
    for member in members:
        others = [m.agv for m in members if m.agv != member.agv]
        if member.agv not in no_detour:
            detour = propose_detour(
                roads, table, member, reason, also_avoid=others, stalled=stalled
            )
            if detour is not None:
                options.append((detour.extra_m, 0, str(member.agv), detour))
        needed = [m.remaining for m in members if m.agv != member.agv]
        back = propose_back_off(roads, table, member, frozenset().union(*needed), reason)
        if back is not None:
            options.append((back.extra_m, 1, str(member.agv), back))
    if not options:
        return None
    return min(options, key=lambda option: option[:3])[3]


def propose_detour(
    roads: RoadMap,
    table: ReservationTable,
    stuck: Stuck,
    reason: str,
    *,
    also_avoid: Iterable[AgvId] = (),
    stalled: Collection[AgvId] = (),
) -> Replan | None:
    """A route for ``stuck`` that avoids everything its blockers and the ``also_avoid``
    vehicles (the other members of its deadlock) hold, conflicts included.

    A detour whose first step (up to its first waiting node) needs what a ``stalled`` vehicle
    (one waiting for the deadlock) holds would leave ``stuck`` where it is, waiting in a new
    cycle: master control would resolve that one by re-planning back, and so on every second
    (seen with four vehicles on the demo floor). Such a route is replaced by one that avoids
    the stalled vehicles' holdings as well; a detour meeting them further on is kept, since
    ``stuck`` moves off first and frees its place."""
    vehicles = stuck.blockers.union(also_avoid)
    detour = _detour_avoiding(roads, table, stuck, vehicles, reason)
    if detour is None or not stalled:
        return detour
    if table.blockers(stuck.agv, first_step(table.conflicts, detour.route)).isdisjoint(stalled):
        return detour
    return _detour_avoiding(roads, table, stuck, vehicles.union(stalled), reason)


def first_step(conflicts: ConflictMap, route: Route) -> list[Resource]:
    """What a vehicle standing at the start of ``route`` needs before it can stop again: the
    resources up to the route's first waiting node (:mod:`.gate`)."""
    return route_resources(route, 0, next_waiting_index(conflicts, route, 0))[1:]


def _detour_avoiding(
    roads: RoadMap,
    table: ReservationTable,
    stuck: Stuck,
    vehicles: Iterable[AgvId],
    reason: str,
) -> Replan | None:
    held = frozenset().union(*(table.held_by(b) for b in vehicles))
    avoid = table.conflicts.closure(held)
    route = route_avoiding(roads, stuck.node_id, stuck.destination, avoid)
    if route is None or not route.edge_ids:
        return None
    return Replan(stuck.agv, route, avoid, route.length_m - stuck.remaining_m, reason)


def propose_back_off(
    roads: RoadMap,
    table: ReservationTable,
    stuck: Stuck,
    others_need: Collection[Resource],
    reason: str,
) -> BackOff | None:
    """Back ``stuck`` off to the nearest node it can reach over free resources, out of the way
    of ``others_need`` (resources the other vehicles still need), from which its destination is
    still reachable."""
    way = table.conflicts.closure(others_need)
    agv = stuck.agv

    def allowed(edge_id: str, next_node: str) -> bool:
        return table.is_free(agv, (edge(edge_id), node(next_node)))

    reach, via = distances(roads, stuck.node_id, allowed=allowed)
    to_go = to_destination(roads, stuck.destination)
    for target in sorted(reach, key=lambda n: (reach[n], n)):
        if target == stuck.node_id or node(target) in way or target not in to_go:
            continue
        back = path_to(roads, stuck.node_id, target, via)
        extra = back.length_m + to_go[target] - stuck.remaining_m
        return BackOff(agv, target, back, stuck.destination, extra, reason)
    return None


def propose_parking(
    roads: RoadMap,
    table: ReservationTable,
    agv: AgvId,
    at_node: str,
    *,
    way: Collection[Resource],
    taken: Container[str],
    reason: str,
) -> MoveToParking | None:
    """Send idle ``agv`` from ``at_node`` to the nearest free parking node that is not in
    ``way`` (resources another vehicle needs, conflicts included) and not in ``taken`` (other
    vehicles' destinations); without one, to the nearest such node without a stationType."""
    reach, via = distances(roads, at_node)

    def usable(candidate: str) -> bool:
        return (
            candidate != at_node
            and candidate not in taken
            and node(candidate) not in way
            and table.is_free(agv, (node(candidate),))
        )

    by_distance = sorted(reach, key=lambda n: (reach[n], n))
    parking = set(roads.station_nodes("parking"))
    target = next((n for n in by_distance if n in parking and usable(n)), None)
    if target is None:  # no station (a charger or a pick place) is a place to wait at
        plain = (n for n in by_distance if roads.graph.nodes[n].station_type is None)
        target = next((n for n in plain if usable(n)), None)
    if target is None:
        return None
    return MoveToParking(agv, target, path_to(roads, at_node, target, via), reason)
