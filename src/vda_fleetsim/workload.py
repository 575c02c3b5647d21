"""What the simulated fleet is asked to do, and how fast it could do it alone.

A transport alternates between a random ``pick`` station and a random ``drop`` station of the
graph (nodes with that ``stationType``); each order carries the matching action. With
``any_station`` (e.g. ``{"drop"}``) the legs of those kinds name no station: the order asks for
any node of that ``stationType`` and master control chooses, and the free-flow time is that of
the nearest such station (the same order with no other vehicle).

An order's *free-flow time* is what it takes one vehicle alone on the floor: the route master
control gives it when it is alone (with traffic control: the cheapest route, one-lane edges
counted at ``one_lane_cost_factor``; without: the shortest), driven at top speed, turning to
each edge's heading on the spot, then the action. An order's *stretch* is its time over that.

Also here: the separation observer (the closest two vehicles came), shared with the benchmark
that measures the real stack over MQTT (``benchmarks/traffic.py``).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Final

from vda_master.graph import Graph
from vda_master.routing import Route
from vda_master.traffic.paths import build_roadmap, cheapest_route
from vda_master.traffic.testing import free_flow_s

#: An order taking longer than this many times its free-flow time counts as stuck (issue 9
#: calls such orders deadlocks: most are queues, docs/traffic.md).
DEADLOCK_FACTOR: Final = 5.0
#: The default safety distance for the simulated 1.2 m x 0.8 m vehicles (docs/traffic.md).
SAFETY_M: Final = 1.69


@dataclass(frozen=True, slots=True)
class Pace:
    """How fast one vehicle does a leg alone: top speed, turning speed, the station action."""

    speed_mps: float = 1.5
    turn_radps: float = 1.0
    #: pick and drop of the simulated vehicle: 1 s preparing + 3 s running (action_catalog).
    action_s: float = 4.0


class Transports:
    """Random pick-then-drop transports per vehicle, reproducible from ``seed``."""

    def __init__(
        self,
        graph: Graph,
        *,
        seed: int,
        one_lane_factor: float,
        any_station: frozenset[str] = frozenset(),
        pace: Pace | None = None,
    ) -> None:
        self.graph = graph
        self.any_station = any_station
        self.pace = pace or Pace()
        self.roads = build_roadmap(graph, one_lane_factor=one_lane_factor)
        stations = sorted(graph.nodes.items())
        self.picks = [n for n, node in stations if node.station_type == "pick"]
        self.drops = [n for n, node in stations if node.station_type == "drop"]
        self._rng = random.Random(seed)  # noqa: S311 - a reproducible workload, not a secret
        self._next: dict[str, str] = {}

    def next_leg(self, serial: str) -> tuple[str, str | None]:
        """(action type, destination) of ``serial``'s next order; destination None: any
        station of the action's kind (``any_station``)."""
        action = self._next.get(serial, "pick")
        station = self._rng.choice(self.picks if action == "pick" else self.drops)
        return action, None if action in self.any_station else station

    def stations(self, action: str) -> list[str]:
        """The nodes whose ``stationType`` is ``action`` (pick or drop)."""
        return self.picks if action == "pick" else self.drops

    def finished(self, serial: str) -> None:
        """``serial`` finished its leg: the next one is the other kind."""
        self._next[serial] = "drop" if self._next.get(serial, "pick") == "pick" else "pick"

    def free_flow_s(self, start: str, destination: str, theta: float | None) -> float:
        """Free-flow seconds from ``start`` (heading ``theta``, if known) to ``destination``."""
        route = cheapest_route(self.roads, start, destination)
        return self.pace.action_s if route is None else self.route_free_flow_s(route, theta)

    def leg_free_flow_s(
        self, start: str, action: str, destination: str | None, theta: float | None
    ) -> float:
        """Free-flow seconds of a leg; without a destination, to the nearest station of the
        action's kind."""
        options = self.stations(action) if destination is None else [destination]
        return min(self.free_flow_s(start, option, theta) for option in options)

    def route_free_flow_s(self, route: Route, theta: float | None) -> float:
        """Free-flow seconds of driving ``route`` (heading ``theta`` at its start, if known)."""
        return free_flow_s(
            self.graph,
            route,
            speed_mps=self.pace.speed_mps,
            turn_radps=self.pace.turn_radps,
            action_s=self.pace.action_s,
            start_theta=theta,
        )


@dataclass
class Separation:
    """Latest position per vehicle; the minimum distance seen; violations, one per approach
    (a pair closer than ``safety_m``, counted again only after it parted by 0.5 m more)."""

    safety_m: float = SAFETY_M
    positions: dict[str, tuple[float, float]] = field(default_factory=dict)
    minimum_m: float = math.inf
    violations: int = 0
    samples: int = 0
    _close: set[tuple[str, str]] = field(default_factory=set)

    def see(self, serial: str, x: float, y: float) -> None:
        self.positions[serial] = (x, y)
        self.samples += 1
        for other, (ox, oy) in self.positions.items():
            if other != serial:
                self._pair(min(serial, other), max(serial, other), math.hypot(x - ox, y - oy))

    def _pair(self, a: str, b: str, distance: float) -> None:
        self.minimum_m = min(self.minimum_m, distance)
        if distance < self.safety_m:
            if (a, b) not in self._close:
                self._close.add((a, b))
                self.violations += 1
        elif distance > self.safety_m + 0.5:
            self._close.discard((a, b))


def percentile(values: list[float], share: float) -> float:
    """The ``share`` percentile of ``values`` (nearest rank; NaN when empty)."""
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(share * len(ordered)))]
