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

from collections import Counter
from collections.abc import (
    Callable,
    Collection,
    Container,
    Iterable,
    Iterator,
    Mapping,
    Sequence,
)
from dataclasses import dataclass, field

from vda5050.topics import AgvId
from vda_master.routing import Route
from vda_master.traffic.conflicts import ConflictMap, Resource, edge, node
from vda_master.traffic.gate import next_waiting_index, route_resources
from vda_master.traffic.paths import (
    RoadMap,
    nearest,
    nearest_first,
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
    #: What the route keeps clear of (a set, or a view of a group's resources).
    avoid: Container[Resource]
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
    """Groups of waiting vehicles that wait for each other (the strongly connected components
    of the wait-for graph restricted to waiting vehicles), each sorted by id."""
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

    Kosaraju's two searches, linear in vehicles and arcs (a floor at a standstill has hundreds
    of waiting vehicles): a depth-first search along the arcs notes the order in which vehicles
    are finished; searches against the arcs, from the last finished on, each collect one
    component."""
    against: dict[AgvId, list[AgvId]] = {agv: [] for agv in arcs}
    for agv, targets in arcs.items():
        for target in targets:
            against[target].append(agv)
    found: list[list[AgvId]] = []
    placed: set[AgvId] = set()
    for root in reversed(_finish_order(arcs)):
        if root not in placed:
            placed.add(root)
            group = [root, *_reachable(against, root, placed)]
            found.append(group)
    return found


def _finish_order(arcs: Mapping[AgvId, list[AgvId]]) -> list[AgvId]:
    """Every vehicle, in the order a depth-first search along ``arcs`` finishes with it."""
    finished: list[AgvId] = []
    seen: set[AgvId] = set()
    for root in arcs:
        if root in seen:
            continue
        seen.add(root)
        path = [(root, iter(arcs[root]))]
        while path:
            at, targets = path[-1]
            for target in targets:
                if target not in seen:
                    seen.add(target)
                    path.append((target, iter(arcs[target])))
                    break
            else:
                path.pop()
                finished.append(at)
    return finished


def _reachable(arcs: Mapping[AgvId, list[AgvId]], origin: AgvId, seen: set[AgvId]) -> list[AgvId]:
    """The vehicles ``origin`` reaches along ``arcs`` that are not in ``seen`` (added to it)."""
    found: list[AgvId] = []
    todo = [origin]
    while todo:
        for target in arcs[todo.pop()]:
            if target not in seen:
                seen.add(target)
                found.append(target)
                todo.append(target)
    return found


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
    only back off or wait for another member to move. Each member's holdings and needs are
    widened by their conflicts once, and what the others hold or need is looked up in their
    counts, so a large group (a floor at a standstill) costs its searches, not its size
    squared."""
    conflicts = table.conflicts
    held = {m.agv: conflicts.closure(table.held_by(m.agv)) for m in members}
    needs = {m.agv: conflicts.closure(m.remaining) for m in members}
    held_counts = Counter(r for resources in held.values() for r in resources)
    need_counts = Counter(r for resources in needs.values() for r in resources)
    options: list[tuple[float, int, str, Replan | BackOff]] = []
    for member in members:
        if member.agv not in no_detour:
            outside = member.blockers.difference(held)  # not in the group

            def avoid_with(
                extra: frozenset[AgvId],
                outside: frozenset[AgvId] = outside,
                agv: AgvId = member.agv,
            ) -> Container[Resource]:
                around = _held_closure(table, outside.union(extra))
                return _OthersOf(held_counts, held[agv], around)

            detour = _detour(roads, table, member, reason, avoid_with=avoid_with, stalled=stalled)
            if detour is not None:
                options.append((detour.extra_m, 0, str(member.agv), detour))
        way = _OthersOf(need_counts, needs[member.agv])
        back = _back_off(roads, table, member, way, reason)
        if back is not None:
            options.append((back.extra_m, 1, str(member.agv), back))
    if not options:
        return None
    return min(options, key=lambda option: option[:3])[3]


@dataclass(frozen=True, slots=True)
class _OthersOf:
    """The resources of the other members of a group (counted in ``counts``, one count per
    member holding or needing it; ``own``: this member's), and those in ``also``."""

    counts: Mapping[Resource, int]
    own: Container[Resource]
    also: Container[Resource] = frozenset()

    def __contains__(self, resource: object) -> bool:
        mine = 1 if resource in self.own else 0
        counted: int = self.counts.get(resource, 0)  # type: ignore[call-overload]
        return counted > mine or resource in self.also


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

    def avoid_with(extra: frozenset[AgvId]) -> Container[Resource]:
        return _held_closure(table, vehicles.union(extra))

    return _detour(roads, table, stuck, reason, avoid_with=avoid_with, stalled=stalled)


def _detour(
    roads: RoadMap,
    table: ReservationTable,
    stuck: Stuck,
    reason: str,
    *,
    avoid_with: Callable[[frozenset[AgvId]], Container[Resource]],
    stalled: Collection[AgvId],
) -> Replan | None:
    """:func:`propose_detour` given what to avoid: ``avoid_with(more vehicles)``."""
    detour = _detour_avoiding(roads, stuck, avoid_with(frozenset()), reason)
    if detour is None or not stalled:
        return detour
    if table.blockers(stuck.agv, first_step(table.conflicts, detour.route)).isdisjoint(stalled):
        return detour
    return _detour_avoiding(roads, stuck, avoid_with(frozenset(stalled)), reason)


def _held_closure(table: ReservationTable, vehicles: Iterable[AgvId]) -> frozenset[Resource]:
    """What ``vehicles`` hold, and everything conflicting with it."""
    return table.conflicts.closure(frozenset().union(*(table.held_by(v) for v in vehicles)))


def first_step(conflicts: ConflictMap, route: Route) -> list[Resource]:
    """What a vehicle standing at the start of ``route`` needs before it can stop again: the
    resources up to the route's first waiting node (:mod:`.gate`)."""
    return route_resources(route, 0, next_waiting_index(conflicts, route, 0))[1:]


def _detour_avoiding(
    roads: RoadMap, stuck: Stuck, avoid: Container[Resource], reason: str
) -> Replan | None:
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
    return _back_off(roads, table, stuck, table.conflicts.closure(others_need), reason)


def _back_off(
    roads: RoadMap,
    table: ReservationTable,
    stuck: Stuck,
    way: Container[Resource],
    reason: str,
) -> BackOff | None:
    """:func:`propose_back_off` given the way to keep clear (conflicts included)."""
    agv = stuck.agv

    def allowed(edge_id: str, next_node: str) -> bool:
        return table.is_free(agv, (edge(edge_id), node(next_node)))

    to_go = to_destination(roads, stuck.destination)

    def off_the_way(target: str) -> bool:
        return target != stuck.node_id and node(target) not in way and target in to_go

    via: dict[str, str] = {}
    target = nearest(roads, stuck.node_id, off_the_way, allowed=allowed, via=via)
    if target is None:
        return None
    back = path_to(roads, stuck.node_id, target, via)
    extra = back.length_m + to_go[target] - stuck.remaining_m
    return BackOff(agv, target, back, stuck.destination, extra, reason)


def propose_parking(
    roads: RoadMap,
    table: ReservationTable,
    agv: AgvId,
    at_node: str,
    *,
    way: Collection[Resource],
    taken: Container[str],
    reason: str,
    search: ParkingSearch | None = None,
) -> MoveToParking | None:
    """Send idle ``agv`` from ``at_node`` to the nearest free parking node that is not in
    ``way`` (resources another vehicle needs, conflicts included) and not in ``taken`` (other
    vehicles' destinations); without one, to the nearest such node without a stationType.
    ``search``: the free nodes already found for ``agv`` on this ``table``, if any."""
    search = search or ParkingSearch(roads, table)

    def fits(candidate: str) -> bool:
        return candidate not in taken and node(candidate) not in way

    target = next(filter(fits, search.free(agv, at_node, parking=True)), None)
    if target is None:  # no station (a charger or a pick place) is a place to wait at
        target = next(filter(fits, search.free(agv, at_node, parking=False)), None)
    if target is None:
        return None
    return MoveToParking(agv, target, path_to(roads, at_node, target, search.via(agv)), reason)


class ParkingSearch:
    """Where idle vehicles may go, for one reservation table: per idle vehicle, the free nodes
    (none other vehicles hold or conflict with) nearest first, parking nodes and nodes without
    a stationType apart. Found as far as asked, once, and shared by every vehicle it stands in
    the way of (on a floor at a standstill, tens of vehicles wait for one idle vehicle, and the
    free nodes lie far away)."""

    def __init__(
        self, roads: RoadMap, table: ReservationTable, budget: SearchBudget | None = None
    ) -> None:
        self._roads = roads
        self._table = table
        self._budget = budget
        self._parking = frozenset(roads.station_nodes("parking"))
        self._reach: dict[AgvId, _Reach | None] = {}

    def free(self, agv: AgvId, at_node: str, *, parking: bool) -> Iterator[str]:
        """The free parking nodes (``parking``) or free nodes without a stationType that
        ``agv``, standing on ``at_node``, may go to, nearest first."""
        if agv not in self._reach:  # None: the budget allowed no search for it
            searched = self._budget is None or self._budget.take()
            via: dict[str, str] = {}
            found = _Reach(nearest_first(self._roads, at_node, via=via), via)
            self._reach[agv] = found if searched else None
        reach = self._reach[agv]
        if reach is None:
            return
        kind = self._is_parking if parking else self._is_plain
        index = 0
        while True:
            if index == len(reach.settled):
                if parking and reach.parking_seen == len(self._parking):
                    return  # every parking node is nearer than the nodes not settled yet
                if not self._settle_one(reach):
                    return
            candidate = reach.settled[index]
            index += 1
            if kind(candidate) and candidate != at_node and self._is_free(agv, reach, candidate):
                yield candidate

    def via(self, agv: AgvId) -> Mapping[str, str]:
        """The edges that lead to the nodes :meth:`free` gave for ``agv``."""
        reach = self._reach[agv]
        assert reach is not None  # noqa: S101 - free() gave nothing without a search
        return reach.via

    def _settle_one(self, reach: _Reach) -> bool:
        """One more node for ``reach``; False once every node is settled."""
        candidate = next(reach.nodes, None)
        if candidate is None:
            return False
        reach.settled.append(candidate)
        reach.parking_seen += candidate in self._parking
        return True

    def _is_free(self, agv: AgvId, reach: _Reach, candidate: str) -> bool:
        free = reach.free.get(candidate)
        if free is None:
            free = reach.free[candidate] = self._table.is_free(agv, (node(candidate),))
        return free

    def _is_parking(self, candidate: str) -> bool:
        return candidate in self._parking

    def _is_plain(self, candidate: str) -> bool:
        return self._roads.graph.nodes[candidate].station_type is None


@dataclass(slots=True)
class SearchBudget:
    """How many idle vehicles' places may still be looked for, by every :class:`ParkingSearch`
    of one request or one look at the advice: on a crowded floor each search may settle most of
    the map before it finds a free node (or none), and an order's way, the ways of the vehicles
    it sends to parking and so on would otherwise be searched within one request."""

    left: int

    def take(self) -> bool:
        """Whether one more search is allowed (and counted)."""
        if self.left <= 0:
            return False
        self.left -= 1
        return True


@dataclass(slots=True)
class _Reach:
    """One idle vehicle's search (:class:`ParkingSearch`)."""

    nodes: Iterator[str]
    via: dict[str, str]
    #: The nodes settled so far, nearest first; how many of them are parking nodes.
    settled: list[str] = field(default_factory=list)
    parking_seen: int = 0
    free: dict[str, bool] = field(default_factory=dict)
