"""Time-aware routing over the other vehicles' planned passages (issue 9 §4).

**Method: prioritized planning with safe-interval A\\* (SIPP), a continuous-time TEA\\*.** Vehicles
are planned one at a time, in the order their orders arrive; each plan respects the passages of
every vehicle planned before it (:mod:`vda_master.traffic.passages`). A resource is *blocked* for
the planning vehicle while another vehicle's passage occupies it or anything that conflicts with
it. A node's *safe intervals* are the gaps between its blocked intervals. The search runs over
states (node, safe interval) and keeps, for each, the cheapest arrival: moving along an edge
starts as early as the edge is free for its whole traversal and still within the current node's
safe interval (the vehicle waits on the node until then), and must arrive inside a safe interval
of the next node. Times are real driving times; the cost is arrival time plus the one-lane
penalty of the edges taken (:meth:`SpeedModel.edge_penalty_s`, so routes keep to two-way
corridors as in :mod:`.paths`); the heuristic is the cost-weighted free-flow time to the
destination (reverse Dijkstra, admissible and consistent). Keeping one arrival per state, the
cheapest, can miss a dearer but earlier arrival that a later safe interval would have needed: a
heuristic trade that keeps the search as small as plain SIPP. The destination must stay free
for ``dwell_s`` after arrival.

Trade-offs, and why this and not a discretised TEA\\*:

- *Continuous time, few states.* Time is not sliced into steps: a node has as many states as safe
  intervals (one when nobody passes), so a 150-node graph with 20 planned vehicles plans in
  about a millisecond, where a TEA\\* over (node, time step) grows with horizon / step.
- *Prioritized, not joint.* Earlier plans never yield to later ones, so the result is not
  fleet-optimal and can fail where a joint plan exists; then the caller falls back to the
  static shortest route and the release gate sequences the vehicles at run time.
- *Estimates, not promises.* Passages are widened for uncertainty and re-estimated as vehicles
  report progress. Safety never depends on them: only the reservation table does.
- *Waiting anywhere.* The plan may wait on any node; the release gate then moves a wait that
  would fall inside a one-lane stretch back to the waiting node before it.

:func:`earliest_arrival` picks, among candidate vehicles and candidate destinations (the stations
of a type), the pair expected to arrive first (real time), counting traffic: pairs are tried in
the order of their free-flow lower bound (plain metres at top speed) and the search stops once no
remaining bound can beat the best plan.
"""

from __future__ import annotations

import heapq
import math
from bisect import bisect_right
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from operator import itemgetter
from types import MappingProxyType

from vda5050.topics import AgvId
from vda_master.routing import Route, route_of
from vda_master.traffic.conflicts import ConflictMap, Resource, edge, node
from vda_master.traffic.passages import Entry, PassageTable, SpeedModel, Timeline
from vda_master.traffic.paths import RoadMap, to_destination

#: An entry's start, the sort key (itemgetter runs in C; a Python function would run per entry).
_START = itemgetter(0)
#: Upper bound on state expansions per plan: a guard, never reached on warehouse-sized graphs.
MAX_EXPANSIONS = 50_000


@dataclass(frozen=True, slots=True)
class PlannedRoute:
    """A route with the times it is expected to reach and leave each of its nodes."""

    route: Route
    timeline: Timeline
    #: False for a fallback that ignores the other vehicles (no traffic-free plan exists).
    avoids_traffic: bool = True

    @property
    def departure(self) -> float:
        """When the vehicle leaves its start node."""
        return self.timeline[0][1]

    @property
    def arrival(self) -> float:
        """When the vehicle reaches its destination."""
        return self.timeline[-1][0]

    @property
    def waited_s(self) -> float:
        """Seconds planned standing on nodes before the destination."""
        return sum(depart - arrive for arrive, depart in self.timeline[:-1])


@dataclass(frozen=True, slots=True)
class Candidate:
    """A vehicle that could take an order: where it stands, when it is ready, how fast it is."""

    agv: AgvId
    start: str
    ready_at: float
    speed: SpeedModel


#: Starts and ends of disjoint blocked intervals, sorted.
Blocked = tuple[list[float], list[float]]


class Spans:
    """Every vehicle's passages over each resource's conflict set, merged per vehicle set; shared
    by the plans of one request, which differ only in whose passages they ignore."""

    def __init__(self, conflicts: ConflictMap, passages: PassageTable, since: float) -> None:
        self._conflicts = conflicts
        self._passages = passages
        self._since = since
        self._entries: dict[Resource, tuple[list[Entry], frozenset[AgvId]]] = {}
        self._all: dict[Resource, Blocked] = {}
        self._without: dict[tuple[Resource, AgvId], Blocked] = {}
        self._gaps: dict[tuple[Resource, AgvId | None], list[tuple[float, float]]] = {}

    def _collect(self, resource: Resource) -> tuple[list[Entry], frozenset[AgvId]]:
        """Passages over ``resource`` or anything conflicting with it that end after ``since``,
        sorted by start, and the vehicles they belong to; worked out once per resource."""
        found = self._entries.get(resource)
        if found is not None:
            return found
        entries = self._passages.over(self._conflicts[resource], self._since)
        entries.sort(key=_START)
        found = self._entries[resource] = (entries, frozenset(e[2] for e in entries))
        return found

    def blocked(self, resource: Resource, agv: AgvId) -> Blocked:
        """When ``resource`` is not free for ``agv`` (its own passages do not count)."""
        entries, holders = self._collect(resource)
        if agv not in holders:
            merged = self._all.get(resource)
            if merged is None:
                merged = self._all[resource] = _merge(entries)
            return merged
        key = (resource, agv)
        merged = self._without.get(key)
        if merged is None:
            merged = self._without[key] = _merge([e for e in entries if e[2] != agv])
        return merged

    def gaps(self, node_id: str, agv: AgvId) -> list[tuple[float, float]]:
        """The safe intervals of ``node_id`` for ``agv``."""
        resource = node(node_id)
        _, holders = self._collect(resource)
        key = (resource, agv if agv in holders else None)
        cached = self._gaps.get(key)
        if cached is None:
            cached = self._gaps[key] = _gaps_between(*self.blocked(resource, agv))
        return cached


def _gaps_between(
    starts: list[float], ends: list[float], ignore_at: float | None = None
) -> list[tuple[float, float]]:
    """The gaps between disjoint blocked intervals, the first from -inf and the last to inf; an
    interval containing ``ignore_at`` is ignored."""
    gaps: list[tuple[float, float]] = []
    free_from = -math.inf
    for start, end in zip(starts, ends, strict=True):
        if ignore_at is not None and start <= ignore_at < end:
            continue
        if start > free_from:
            gaps.append((free_from, start))
        free_from = max(free_from, end)
    gaps.append((free_from, math.inf))
    return gaps


def _merge(entries: list[Entry]) -> Blocked:
    """Disjoint intervals covering ``entries`` (sorted by start)."""
    starts: list[float] = []
    ends: list[float] = []
    for start, end, _ in entries:
        if starts and start <= ends[-1]:
            ends[-1] = max(ends[-1], end)
        else:
            starts.append(start)
            ends.append(end)
    return starts, ends


class _Occupancy:
    """Blocked intervals and safe intervals for one planning vehicle, cached."""

    def __init__(self, spans: Spans, agv: AgvId) -> None:
        self._spans = spans
        self._agv = agv
        self._blocked: dict[Resource, Blocked] = {}
        self._gaps: dict[str, list[tuple[float, float]]] = {}

    def blocked(self, resource: Resource) -> Blocked:
        """Starts and ends of the disjoint intervals in which ``resource`` is not free."""
        cached = self._blocked.get(resource)
        if cached is None:
            cached = self._blocked[resource] = self._spans.blocked(resource, self._agv)
        return cached

    def gaps(self, node_id: str) -> list[tuple[float, float]]:
        """Safe intervals of ``node_id``, cached."""
        cached = self._gaps.get(node_id)
        if cached is None:
            cached = self._gaps[node_id] = self._spans.gaps(node_id, self._agv)
        return cached

    def safe_intervals(
        self, node_id: str, *, ignore_at: float | None = None
    ) -> list[tuple[float, float]]:
        """Gaps between the blocked intervals of ``node_id``; a blocked interval containing
        ``ignore_at`` is ignored (the planning vehicle already stands there)."""
        return _gaps_between(*self.blocked(node(node_id)), ignore_at)

    def earliest_free(self, resource: Resource, at: float, duration: float) -> float:
        """The earliest time from ``at`` at which ``resource`` stays free for ``duration``."""
        starts, ends = self.blocked(resource)
        index = bisect_right(ends, at)
        while index < len(starts) and starts[index] < at + duration:
            at = max(at, ends[index])
            index += 1
        return at


#: One way out of a node: (edge id, node at its end, the edge's resource, seconds to drive it,
#: its one-lane penalty in seconds).
Step = tuple[str, str, Resource, float, float]


def steps_for(roads: RoadMap, speed: SpeedModel) -> Mapping[str, tuple[Step, ...]]:
    """Every node's ways out at ``speed``; worked out once per road map and speed."""
    return roads.remembered(("steps", speed), lambda: MappingProxyType({
        at: tuple(
            (edge_id, other, edge(edge_id), speed.edge_time_s(roads, edge_id),
             speed.edge_penalty_s(roads, edge_id))
            for edge_id, other, _ in arcs
        )
        for at, arcs in roads.outgoing.items()
    }))  # fmt: skip


@dataclass(frozen=True, slots=True)
class _Search:
    roads: RoadMap
    steps: Mapping[str, tuple[Step, ...]]
    occupancy: _Occupancy
    speed: SpeedModel
    destination: str
    dwell_s: float
    to_go: Mapping[str, float]
    #: Only these edges may be taken (None: any).
    only_edges: frozenset[str] | None = None


State = tuple[str, int]


def plan_route(
    roads: RoadMap,
    conflicts: ConflictMap,
    passages: PassageTable,
    *,
    agv: AgvId,
    start: str,
    destination: str,
    start_time: float,
    speed: SpeedModel,
    dwell_s: float = 0.0,
    to_go: Mapping[str, float] | None = None,
    spans: Spans | None = None,
    only_edges: frozenset[str] | None = None,
) -> PlannedRoute | None:
    """The earliest-arriving route from ``start`` to ``destination`` that keeps clear of every
    other vehicle's passages (``agv``'s own are ignored), or None if there is none.

    ``to_go`` (metres from every node to ``destination``) and ``spans`` may be passed to share
    work between several plans to the same destination at the same time. ``only_edges`` keeps
    the search to those edges (e.g. one fixed route: then it only decides where to wait).
    """
    if to_go is None:
        to_go = to_destination(roads, destination)
    if start not in to_go:
        return None
    if spans is None:
        spans = Spans(conflicts, passages, start_time)
    occupancy = _Occupancy(spans, agv)
    if start != destination and occupancy.safe_intervals(destination)[-1][0] == math.inf:
        return None  # taken for good (an idle vehicle stands there): no need to search
    steps = steps_for(roads, speed)
    search = _Search(roads, steps, occupancy, speed, destination, dwell_s, to_go, only_edges)
    start_gaps = occupancy.safe_intervals(start, ignore_at=start_time)
    first = next(k for k, (_, end) in enumerate(start_gaps) if end > start_time)
    return _astar(search, (start, first), start_time, start_gaps[first][1])


def _astar(
    search: _Search, origin: State, start_time: float, origin_end: float
) -> PlannedRoute | None:
    # ordered by cost = arrival time + the penalties of the one-lane edges taken so far
    best: dict[State, float] = {origin: start_time}
    cost: dict[State, float] = {origin: start_time}
    gap_end: dict[State, float] = {origin: origin_end}
    parent: dict[State, tuple[State, str, float]] = {}
    queue: list[tuple[float, int, float, State]] = [(start_time, 0, start_time, origin)]
    counter = 1
    for _ in range(MAX_EXPANSIONS):
        if not queue:
            return None
        _, _, spent, state = heapq.heappop(queue)
        if spent > cost[state]:
            continue
        arrival = best[state]
        if state[0] == search.destination and _can_dwell(search, arrival, gap_end[state]):
            return _reconstruct(search.roads, state, arrival, best, parent)
        for successor, depart, edge_id, reached, end, penalty in _successors(
            search, state[0], arrival, gap_end[state]
        ):
            total = spent + (reached - arrival) + penalty
            if total < cost.get(successor, math.inf):
                best[successor], cost[successor], gap_end[successor] = reached, total, end
                parent[successor] = (state, edge_id, depart)
                estimate = total + search.to_go[successor[0]] / search.speed.speed_mps
                heapq.heappush(queue, (estimate, counter, total, successor))
                counter += 1
    return None


def _can_dwell(search: _Search, arrival: float, end: float) -> bool:
    return arrival + search.dwell_s <= end


def _successors(
    search: _Search, at: str, arrival: float, leave_by: float
) -> list[tuple[State, float, str, float, float, float]]:
    """(state, departure, edge, arrival, end of the arrival's safe interval, the edge's one-lane
    penalty) per reachable safe interval of each neighbour, leaving ``at`` no later than
    ``leave_by``."""
    found = []
    only = search.only_edges
    to_go = search.to_go
    occupancy = search.occupancy
    for edge_id, other, resource, duration, penalty in search.steps[at]:
        if other not in to_go or (only is not None and edge_id not in only):
            continue
        for index, (opens, closes) in enumerate(occupancy.gaps(other)):
            if closes <= arrival + duration:
                continue
            if opens > leave_by + duration:
                break
            depart = occupancy.earliest_free(resource, max(arrival, opens - duration), duration)
            if depart > leave_by:
                break
            if depart + duration < closes:
                found.append(((other, index), depart, edge_id, depart + duration, closes, penalty))
    return found


def _reconstruct(
    roads: RoadMap,
    state: State,
    arrival: float,
    best: Mapping[State, float],
    parent: Mapping[State, tuple[State, str, float]],
) -> PlannedRoute:
    edges: list[str] = []
    times: list[tuple[float, float]] = [(arrival, arrival)]
    while state in parent:
        previous, edge_id, depart = parent[state]
        edges.append(edge_id)
        times.append((best[previous], depart))
        state = previous
    edges.reverse()
    times.reverse()
    return PlannedRoute(route_of(roads.graph, state[0], edges), tuple(times))


def earliest_arrival(
    roads: RoadMap,
    conflicts: ConflictMap,
    passages: PassageTable,
    candidates: Sequence[Candidate],
    destinations: tuple[str, ...],
    *,
    dwell_s: float = 0.0,
) -> tuple[Candidate, PlannedRoute] | None:
    """The (candidate, destination) pair expected to arrive first, counting traffic, with its
    plan (``plan.route.destination`` says which destination); ties go to the lowest vehicle id,
    then to the destination given first. None if no pair has a traffic-free plan."""
    bounds: list[tuple[float, str, int, Candidate]] = []
    for rank, destination in enumerate(destinations):
        metres_to_go = to_destination(roads, destination, metres=True)
        bounds.extend(
            (c.ready_at + metres_to_go[c.start] / c.speed.speed_mps, str(c.agv), rank, c)
            for c in candidates if c.start in metres_to_go
        )  # fmt: skip
    bounds.sort(key=itemgetter(0, 1, 2))
    best: tuple[Candidate, PlannedRoute] | None = None
    shared: dict[float, Spans] = {}
    for bound, _, rank, candidate in bounds:
        if best is not None and bound >= best[1].arrival:
            break
        destination = destinations[rank]
        plan = plan_route(
            roads,
            conflicts,
            passages,
            agv=candidate.agv,
            start=candidate.start,
            destination=destination,
            start_time=candidate.ready_at,
            speed=candidate.speed,
            dwell_s=dwell_s,
            to_go=to_destination(roads, destination),
            spans=shared.setdefault(
                candidate.ready_at, Spans(conflicts, passages, candidate.ready_at)
            ),
        )
        if plan is not None and (best is None or plan.arrival < best[1].arrival):
            best = (candidate, plan)
    return best
