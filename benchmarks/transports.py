"""What the two traffic benchmarks share (``traffic.py`` over MQTT, ``traffic_sim.py`` in one
process): the transports the fleet drives, their free-flow times, and the separation observer.

A transport alternates between a random ``pick`` station and a random ``drop`` station of the
graph; each order carries the matching action. With ``any_station`` (e.g. ``{"drop"}``) the legs
of those kinds name no station: the order asks for any node of that ``stationType`` and master
control chooses, and the free-flow time is that of the nearest such station (the same order
with no other vehicle). An order's free-flow time is what it takes one
simulated vehicle alone on the floor: the route master control gives it when it is alone (with
traffic control: the cheapest route, one-lane edges counted at ``one_lane_cost_factor``;
without: the shortest), driven at top speed, turning to each edge's heading on the spot, then
the action.
"""

from __future__ import annotations

import argparse
import math
import random
from dataclasses import dataclass, field

from vda_master.graph import Graph
from vda_master.routing import Route
from vda_master.traffic.paths import build_roadmap, cheapest_route
from vda_master.traffic.testing import free_flow_s

#: The simulated vehicle's defaults (vda_vehicle config): top speed, turning speed.
SPEED_MPS = 1.5
TURN_RADPS = 1.0
#: pick and drop of the simulated vehicle: 1 s preparing + 3 s running (action_catalog).
ACTION_S = 4.0
#: The default safety distance for the simulated 1.2 m x 0.8 m vehicles.
SAFETY_M = 1.69
#: An order taking longer than this many times its free-flow time counts as a deadlock.
DEADLOCK_FACTOR = 5.0


class Transports:
    """Random pick-then-drop transports per vehicle, reproducible from ``seed``."""

    def __init__(
        self,
        graph: Graph,
        *,
        seed: int,
        one_lane_factor: float,
        any_station: frozenset[str] = frozenset(),
    ) -> None:
        self.graph = graph
        self.any_station = any_station
        self.roads = build_roadmap(graph, one_lane_factor=one_lane_factor)
        stations = sorted(graph.nodes.items())
        self.picks = [n for n, node in stations if node.station_type == "pick"]
        self.drops = [n for n, node in stations if node.station_type == "drop"]
        self._rng = random.Random(seed)
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
        return ACTION_S if route is None else self.route_free_flow_s(route, theta)

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
            speed_mps=SPEED_MPS,
            turn_radps=TURN_RADPS,
            action_s=ACTION_S,
            start_theta=theta,
        )


@dataclass
class Separation:
    """Latest position per vehicle; the minimum distance seen; violations, one per approach
    (a pair closer than ``SAFETY_M``, counted again only after it parted by 0.5 m more)."""

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
        if distance < SAFETY_M:
            if (a, b) not in self._close:
                self._close.add((a, b))
                self.violations += 1
        elif distance > SAFETY_M + 0.5:
            self._close.discard((a, b))


def percentile(values: list[float], share: float) -> float:
    """The ``share`` percentile of ``values`` (nearest rank; NaN when empty)."""
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(share * len(ordered)))]


def add_any_station_option(cli: argparse.ArgumentParser) -> None:
    """``--any-station pick drop``: the leg kinds that ask for any station of their type."""
    cli.add_argument(
        "--any-station",
        nargs="+",
        choices=["pick", "drop"],
        default=[],
        help="legs of these kinds ask for any station of the type (POST /orders stationType)",
    )
