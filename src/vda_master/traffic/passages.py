"""Planned passages: when each vehicle is expected on which resource (issue 9 §4).

The time-aware planner needs the other vehicles' futures. A vehicle's *timeline* along its route
gives, for each node, when it arrives and when it leaves; its *passages* are the time intervals
it is expected to occupy each node and edge, widened for uncertainty:

- every interval grows by ``buffer_s`` before and after, plus ``drift`` × the time until it
  happens (estimates further in the future are less certain);
- the first node is occupied from the estimate's start (the vehicle stands there);
- the last node stays occupied for ``hold_s`` after arrival (``math.inf``: an idle vehicle).

:class:`PassageTable` keeps every vehicle's passages indexed by resource, immutable, replaced per
vehicle in O(its passages). Times are seconds on the caller's clock (monotonic), passed in.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from vda5050.topics import AgvId
from vda_master.routing import Route
from vda_master.traffic.conflicts import Resource, edge, node
from vda_master.traffic.paths import RoadMap
from vda_master.traffic.pmap import PMap

#: Per node of a route: (arrival, departure) in seconds.
Timeline = tuple[tuple[float, float], ...]


@dataclass(frozen=True, slots=True)
class SpeedModel:
    """How fast one vehicle drives: ``speed_mps`` (capped by an edge's maxSpeed) and an extra
    ``node_time_s`` for every node it reaches (turning, accelerating)."""

    speed_mps: float = 1.0
    node_time_s: float = 0.0

    def __post_init__(self) -> None:
        if self.speed_mps <= 0 or self.node_time_s < 0:
            msg = f"speed must be positive and node time non-negative, got {self}"
            raise ValueError(msg)

    def edge_time_s(self, roads: RoadMap, edge_id: str) -> float:
        """Seconds to drive ``edge_id`` and reach its end node."""
        speed = min(self.speed_mps, roads.max_speed.get(edge_id, math.inf))
        return roads.length[edge_id] / speed + self.node_time_s

    def edge_penalty_s(self, roads: RoadMap, edge_id: str) -> float:
        """What routing adds to ``edge_id``'s time for its extra cost (a one-lane edge's
        length times the one-lane factor less one, see :mod:`.paths`), in seconds."""
        return (roads.cost[edge_id] - roads.length[edge_id]) / self.speed_mps


@dataclass(frozen=True, slots=True)
class PassageSettings:
    """Uncertainty margins and the assumed stay at the destination; seconds."""

    buffer_s: float = 1.0
    drift: float = 0.1
    hold_s: float = 30.0


@dataclass(frozen=True, slots=True)
class Passage:
    """``resource`` is expected to be occupied from ``start`` to ``end``."""

    resource: Resource
    start: float
    end: float


def estimate_timeline(
    roads: RoadMap, route: Route, speed: SpeedModel, *, start_time: float, from_index: int = 0
) -> Timeline:
    """Arrival and departure at nodes ``from_index …`` of ``route`` for a vehicle that stands on
    node ``from_index`` at ``start_time`` and drives on without waiting."""
    times = [(start_time, start_time)]
    at = start_time
    for edge_id in route.edge_ids[from_index:]:
        at += speed.edge_time_s(roads, edge_id)
        times.append((at, at))
    return tuple(times)


def passages_of(
    route: Route,
    timeline: Timeline,
    settings: PassageSettings,
    *,
    from_index: int = 0,
    hold_s: float | None = None,
) -> tuple[Passage, ...]:
    """The passages of a vehicle following ``timeline`` over nodes ``from_index …`` of ``route``
    (``hold_s`` overrides the settings' stay at the last node)."""
    origin = timeline[0][0]

    def margin(at: float) -> float:
        return settings.buffer_s + settings.drift * max(0.0, at - origin)

    stay = settings.hold_s if hold_s is None else hold_s
    last = len(timeline) - 1
    found: list[Passage] = []
    for offset, (arrive, depart) in enumerate(timeline):
        index = from_index + offset
        start = origin if offset == 0 else arrive - margin(arrive)
        end = depart + stay if offset == last else depart + margin(depart)
        found.append(Passage(node(route.node_ids[index]), start, end))
        if offset < last:
            arrive_next = timeline[offset + 1][0]
            span = (depart - margin(depart), arrive_next + margin(arrive_next))
            found.append(Passage(edge(route.edge_ids[index]), *span))
    return tuple(found)


def standing(node_id: str, since: float) -> tuple[Passage, ...]:
    """An idle vehicle on ``node_id``: occupied from ``since`` on, with no end in sight."""
    return (Passage(node(node_id), since, math.inf),)


#: (start, end, vehicle) of one passage, as stored per resource.
Entry = tuple[float, float, AgvId]


class PassageTable:
    """Resource → every vehicle's expected passages over it; immutable."""

    __slots__ = ("_by_resource", "_by_vehicle")

    def __init__(
        self,
        by_resource: PMap[Resource, tuple[Entry, ...]] | None = None,
        by_vehicle: PMap[AgvId, tuple[Passage, ...]] | None = None,
    ) -> None:
        self._by_resource: PMap[Resource, tuple[Entry, ...]] = (
            by_resource if by_resource is not None else PMap()
        )
        self._by_vehicle: PMap[AgvId, tuple[Passage, ...]] = (
            by_vehicle if by_vehicle is not None else PMap()
        )

    def at(self, resource: Resource) -> tuple[Entry, ...]:
        """Every passage over ``resource``."""
        return self._by_resource.get(resource) or ()

    def over(self, resources: Iterable[Resource], since: float) -> list[Entry]:
        """Every passage over any of ``resources`` that ends after ``since``, in no order."""
        found = self._by_resource.values_of(resources)
        return [entry for entries in found for entry in entries if entry[1] > since]

    def of(self, agv: AgvId) -> tuple[Passage, ...]:
        """The passages of ``agv``."""
        return self._by_vehicle.get(agv) or ()

    def with_vehicle(self, agv: AgvId, passages: Iterable[Passage]) -> PassageTable:
        """``agv``'s passages replaced by ``passages``."""
        new = tuple(passages)
        old = self.of(agv)
        touched = {p.resource for p in old} | {p.resource for p in new}
        entries = {r: [e for e in self.at(r) if e[2] != agv] for r in touched}
        for passage in new:
            entries[passage.resource].append((passage.start, passage.end, agv))
        by_resource = self._by_resource.update(
            put=((r, tuple(e)) for r, e in entries.items() if e),
            remove=(r for r, e in entries.items() if not e),
        )
        by_vehicle = self._by_vehicle.set(agv, new) if new else self._by_vehicle.remove(agv)
        return PassageTable(by_resource, by_vehicle)

    def without(self, agv: AgvId) -> PassageTable:
        """``agv``'s passages removed."""
        return self.with_vehicle(agv, ())
