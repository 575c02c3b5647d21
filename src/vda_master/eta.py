"""When an order is expected to finish: ``expectedFinishAt`` of the order view (pure).

A WMS that ordered a transport, or an operator who sees a vehicle waiting, wants to know when
it will be done. VDA 5050 has no such field; master control estimates it from what it knows:

- **the way left**: the order's plan from the node the vehicle last passed (its state's
  ``lastNodeSequenceId``), less the part of the next edge already driven
  (``distanceSinceLastNode``), then every stop still to come (the shortest way from one to the
  next);
- **how the vehicle drives**: its factsheet's ``speedMax``, capped by each edge's ``maxSpeed``
  as the order gives it, and, where the factsheet has ``angularSpeedMax`` (2.1 and later),
  turning on the spot to each edge's heading (1.0 m/s and no turning without a factsheet);
- **what it learns** (per vehicle type, the manufacturer): the *dwell* at a stop, from the
  state that shows the vehicle there to the state that shows the stop's actions FINISHED, per
  set of action types there (0 until seen once); and the *pace*, how much longer an order's
  drive took than that model said (traffic, waits, acceleration, turns a factsheet does not
  describe), from each leg of the orders asked for: from its start (the creation, the end of
  the actions at the stop before) to its end, over the drive expected (planned at creation;
  for a further stop's leg, not yet planned: a pace of its own).

expected finish = now + (driving left) × pace + (dwell left) + (the stops still to come)

Learned values are means over the last :data:`WINDOW` samples; master control keeps them in
its data folder (:meth:`FinishEstimates.learned_document`), so a restart starts from them. All
times are seconds on the caller's monotonic clock; nothing here reads a clock.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Final

from pydantic import JsonValue

from vda5050.models import Edge, Node, State
from vda_master.graph import Graph

#: Learned means follow the last this many samples (an exponential window).
WINDOW: Final = 20
#: A learned pace stays within these bounds (a vehicle stuck for an hour says little about the
#: next order; a factsheet that understates the speed may make a drive quicker than modelled).
PACE_BOUNDS: Final = (0.5, 10.0)
#: Without a factsheet (or its speedMax), the speed assumed (m/s).
DEFAULT_SPEED_MPS: Final = 1.0


@dataclass(frozen=True, slots=True)
class Drive:
    """How one vehicle drives, in wall-clock units: ``speed_mps``; ``turn_radps`` for turning
    on the spot at a node (None: turns are not counted); ``edge_speed_factor`` scales the
    edges' ``maxSpeed`` (the master's ``time_lapse`` for a simulated fleet)."""

    speed_mps: float = DEFAULT_SPEED_MPS
    turn_radps: float | None = None
    edge_speed_factor: float = 1.0


@dataclass(slots=True)
class LearnedMean:
    """A mean over about the last :data:`WINDOW` samples."""

    value: float = 0.0
    count: int = 0

    def add(self, sample: float) -> None:
        self.count += 1
        self.value += (sample - self.value) / min(self.count, WINDOW)


@dataclass(frozen=True, slots=True)
class PlanTimes:
    """Per node of a plan: seconds from the plan's first node to this one (driving and the turns
    at the nodes between), and each edge's own driving seconds; the headings each edge is
    entered and left with (None: no position known)."""

    to_node: tuple[float, ...]
    edge_s: tuple[float, ...]
    heading_in: tuple[float | None, ...]
    #: Each edge's driving alone (without the turn onto it), and its length (m).
    drive_s: tuple[float, ...]
    edge_m: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class Leg:
    """One edge to drive: its id, ``maxSpeed`` (None: none), length if known, and the
    positions of its nodes if known (for an edge the graph does not have)."""

    edge_id: str
    max_speed: float | None = None
    length: float | None = None
    ends: tuple[tuple[float, float], tuple[float, float]] | None = None


def leg_times(graph: Graph, legs: Sequence[Leg], drive: Drive) -> PlanTimes:
    """:class:`PlanTimes` of driving ``legs`` one after the other."""
    to_node = [0.0]
    edge_s: list[float] = []
    heading_in: list[float | None] = []
    driving: list[float] = []
    lengths: list[float] = []
    heading: float | None = None
    for index, leg in enumerate(legs):
        path = _path(graph, leg)
        lengths.append(_length(graph, leg, path))
        seconds = lengths[-1] / _speed(leg, drive)
        driving.append(seconds)
        entering = _heading(path[0], path[1]) if path else None
        if index > 0:
            seconds += turn_s(heading, entering, drive)
        edge_s.append(seconds)
        heading_in.append(entering)
        to_node.append(to_node[-1] + seconds)
        heading = _heading(path[-2], path[-1]) if path else None
    return PlanTimes(
        tuple(to_node), tuple(edge_s), tuple(heading_in), tuple(driving), tuple(lengths)
    )


def plan_legs(nodes: Sequence[Node], edges: Sequence[Edge]) -> tuple[Leg, ...]:
    """The legs of an order's plan: each edge with the ``maxSpeed`` the order gives it."""
    legs = []
    for index, item in enumerate(edges):
        start, end = nodes[index].node_position, nodes[index + 1].node_position
        ends = ((start.x, start.y), (end.x, end.y)) if start and end else None
        legs.append(Leg(item.edge_id, item.max_speed, item.length, ends))
    return tuple(legs)


def graph_legs(graph: Graph, edge_ids: Sequence[str]) -> tuple[Leg, ...]:
    """The legs of a route of ``graph``'s edges, with the graph's ``maxSpeed``."""
    return tuple(Leg(e, graph.edges[e].max_speed) for e in edge_ids)


def turn_s(heading: float | None, toward: float | None, drive: Drive) -> float:
    """Seconds to turn on the spot from ``heading`` to ``toward`` (0 when either is unknown or
    the vehicle's turning speed is)."""
    if heading is None or toward is None or not drive.turn_radps:
        return 0.0
    return abs(math.remainder(toward - heading, math.tau)) / drive.turn_radps


def driving_left_s(
    times: PlanTimes, progress: int, state: State | None, drive: Drive, since_state_s: float = 0.0
) -> float:
    """Driving seconds from where ``state`` puts the vehicle (last node ``progress``) to the
    plan's last node: the rest of the edge it is on, and the turn it still has to make when it
    stands on its last node. A vehicle whose state says it drives has driven on since, for
    ``since_state_s``, up to the edge's end at most (reaching a node brings a state, §6.10)."""
    if progress >= len(times.edge_s):
        return 0.0
    left = times.to_node[-1] - times.to_node[progress]
    if state is None:
        return left
    driving, length = times.drive_s[progress], times.edge_m[progress]
    done_m = state.distance_since_last_node or 0.0
    done = driving * min(1.0, done_m / length) if length > 0 else 0.0
    if state.driving:
        done += since_state_s
    if done > 0:
        # on the edge: the turn onto it is made, and what is driven of it is off its time
        return left - (times.edge_s[progress] - driving) - min(driving, done)
    if state.agv_position is not None:
        left += turn_s(state.agv_position.theta, times.heading_in[progress], drive)
    return left


@dataclass(slots=True)
class _Started:
    """An order master control learns from: what its first leg was expected to drive, where
    and when its current leg began, and when its vehicle reached the end of its plan."""

    manufacturer: str
    #: Driving seconds expected for the first leg, at the order's creation.
    drive_s: float
    #: When and at which node the current leg began: the creation (node 0), then the end of
    #: the actions at each stop. A leg that ends without its stop's actions seen to end (no
    #: state showed them) teaches nothing.
    leg_start: float
    leg_from: int = 0
    #: When the vehicle reached the plan's last node, and which index that was (an order with
    #: several stops has a new last node after each update).
    arrived_at: float | None = None
    arrived_index: int = -1
    #: The last node whose dwell has been learned (once per stop).
    dwelt_index: int = -1


@dataclass
class FinishEstimates:
    """What master control has learned about dwell and pace, and the orders it learns from."""

    dwell: dict[tuple[str, tuple[str, ...]], LearnedMean] = field(default_factory=dict)
    pace: dict[str, LearnedMean] = field(default_factory=dict)
    #: The pace of legs estimated before they were planned (further stops), per manufacturer:
    #: their route, not yet chosen by traffic control, is part of what it learns.
    unplanned_pace: dict[str, LearnedMean] = field(default_factory=dict)
    _orders: dict[str, _Started] = field(default_factory=dict)

    def pace_of(self, manufacturer: str, *, planned: bool = True) -> float:
        """The learned pace of ``manufacturer``'s vehicles on a planned leg (1 until an order
        has been seen), or on one not yet planned (the planned pace until one has been seen)."""
        learned = self.pace.get(manufacturer)
        unplanned = None if planned else self.unplanned_pace.get(manufacturer)
        if unplanned is not None:
            return unplanned.value
        return learned.value if learned is not None else 1.0

    def dwell_of(self, manufacturer: str, action_types: tuple[str, ...]) -> float:
        """Seconds a ``manufacturer`` vehicle stays at a destination with ``action_types``
        (0 when nothing has been learned, and without actions)."""
        if not action_types:
            return 0.0
        learned = self.dwell.get((manufacturer, action_types))
        return learned.value if learned is not None else 0.0

    def started(self, order_id: str, manufacturer: str, drive_s: float, now: float) -> None:
        """An order was created, its first leg expected to drive ``drive_s``."""
        self._orders[order_id] = _Started(manufacturer, drive_s, now)

    def progressed(
        self,
        order_id: str,
        progress: int,
        last_index: int,
        now: float,
        leg_drive_s: Callable[[int], float],
    ) -> None:
        """The vehicle of ``order_id`` passed node ``progress`` of a plan ending at node
        ``last_index``; ``leg_drive_s(i)``: the driving expected from node ``i`` to there
        before the leg was planned. At the end of a leg its drive is done: a sample of the pace,
        the time since the leg began over the drive expected (the first leg: at the order's
        creation; a further one: from the stop it began at, as its estimate had it)."""
        order = self._orders.get(order_id)
        if order is None or progress < last_index or order.arrived_index == last_index:
            return
        first = order.arrived_at is None
        began_at_stop = order.leg_from == order.arrived_index
        order.arrived_at, order.arrived_index = now, last_index
        if first:
            drive, paces = order.drive_s, self.pace
        elif began_at_stop:
            drive, paces = leg_drive_s(order.leg_from), self.unplanned_pace
        else:
            return  # the stop before: its actions were not seen to end
        if drive > 0:
            low, high = PACE_BOUNDS
            sample = min(high, max(low, (now - order.leg_start) / drive))
            paces.setdefault(order.manufacturer, LearnedMean()).add(sample)

    def arrived_at(self, order_id: str, last_index: int) -> float | None:
        """When the vehicle of ``order_id`` reached node ``last_index``, the end of its plan
        (None: not yet)."""
        order = self._orders.get(order_id)
        if order is None or order.arrived_index != last_index:
            return None
        return order.arrived_at

    def waits_for_dwell(self, order_id: str, last_index: int) -> bool:
        """Whether the vehicle of ``order_id`` stands at node ``last_index``, the end of its
        plan, and the dwell there is still to be learned."""
        order = self._orders.get(order_id)
        return order is not None and order.arrived_index == last_index > order.dwelt_index

    def dwelt(
        self, order_id: str, action_types: tuple[str, ...], last_index: int, now: float
    ) -> None:
        """The actions (``action_types``) at node ``last_index`` have ended (a state shows
        them FINISHED or FAILED): the time since the vehicle got there is a dwell sample. The
        last stop of an order and every stop before it teach the dwell alike."""
        arrived = self.arrived_at(order_id, last_index)
        order = self._orders.get(order_id)
        if order is None or arrived is None or order.dwelt_index == last_index:
            return
        order.dwelt_index = last_index
        order.leg_start, order.leg_from = now, last_index  # a further leg begins here
        if action_types:
            key = (order.manufacturer, action_types)
            self.dwell.setdefault(key, LearnedMean()).add(now - arrived)

    def ended(
        self,
        order_id: str,
        action_types: tuple[str, ...],
        last_index: int,
        *,
        finished: bool,
        now: float,
    ) -> None:
        """``order_id`` ended; FINISHED at its plan's last node ``last_index`` (where
        ``action_types`` are) without a state that showed those actions ended first, the time
        there is the dwell sample."""
        if finished:
            self.dwelt(order_id, action_types, last_index, now)
        self._orders.pop(order_id, None)

    def expected_finish(
        self,
        *,
        order_id: str,
        manufacturer: str,
        times: PlanTimes,
        progress: int,
        state: State | None,
        drive: Drive,
        destination_actions: tuple[str, ...],
        stops_s: Callable[[], float],
        now: float,
        since_state_s: float = 0.0,
    ) -> float:
        """When the order is expected to finish (seconds, the caller's clock): the driving left
        (``state`` is ``since_state_s`` old) at the learned pace, the dwell left at the
        destination, and ``stops_s()``: the stops still to come (their driving at the pace of
        legs not yet planned, and their dwell)."""
        pace = self.pace_of(manufacturer)
        dwell = self.dwell_of(manufacturer, destination_actions)
        arrived = self.arrived_at(order_id, len(times.edge_s))
        if arrived is not None and progress >= len(times.edge_s):
            dwell = max(0.0, dwell - (now - arrived))
        driving = driving_left_s(times, progress, state, drive, since_state_s)
        return now + driving * pace + dwell + stops_s()

    def learned_document(self, time_lapse: float) -> dict[str, JsonValue]:
        """What has been learned, as JSON (kept across restarts; ``time_lapse``: the master's,
        which dwell times depend on)."""
        return {
            "version": LEARNED_VERSION,
            "timeLapse": time_lapse,
            "pace": _means_document(self.pace),
            "unplannedPace": _means_document(self.unplanned_pace),
            "dwell": [
                {"manufacturer": m, "actionTypes": list(types), "mean": mean.value, "n": mean.count}
                for (m, types), mean in self.dwell.items()
            ],
        }

    def restore_learned(self, document: object, time_lapse: float) -> str | None:
        """Take up what :meth:`learned_document` wrote; None when taken, else why not (a
        document of another format or time lapse, or malformed: nothing is taken then)."""
        if not isinstance(document, dict) or document.get("version") != LEARNED_VERSION:
            return "not a learned-estimates document of this version"
        if document.get("timeLapse") != time_lapse:
            return f"learned at time lapse {document.get('timeLapse')}, not {time_lapse}"
        try:
            pace = _means(document["pace"], PACE_BOUNDS)
            unplanned = _means(document["unplannedPace"], PACE_BOUNDS)
            dwell = {
                (str(d["manufacturer"]), tuple(str(t) for t in d["actionTypes"])): _mean(
                    d["mean"], d["n"], (0.0, math.inf)
                )
                for d in document["dwell"]
            }
        except (KeyError, TypeError, ValueError) as exc:
            return f"malformed: {type(exc).__name__}: {exc}"
        self.pace.update(pace)
        self.unplanned_pace.update(unplanned)
        self.dwell.update(dwell)
        return None


#: The format of :meth:`FinishEstimates.learned_document`.
LEARNED_VERSION: Final = 1


def _means_document(means: dict[str, LearnedMean]) -> dict[str, JsonValue]:
    return {key: {"mean": mean.value, "n": mean.count} for key, mean in means.items()}


def _means(document: object, bounds: tuple[float, float]) -> dict[str, LearnedMean]:
    if not isinstance(document, dict):
        msg = "a learned mean per manufacturer must be an object"
        raise TypeError(msg)
    return {str(key): _mean(v["mean"], v["n"], bounds) for key, v in document.items()}


def _mean(value: object, count: object, bounds: tuple[float, float]) -> LearnedMean:
    """A learned mean read back; ValueError unless a finite number within ``bounds`` learned
    from a positive whole number of samples."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        msg = f"mean {value!r} is no number"
        raise TypeError(msg)
    if not (math.isfinite(value) and bounds[0] <= value <= bounds[1]):
        msg = f"mean {value!r} is out of range {bounds}"
        raise ValueError(msg)
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        msg = f"sample count {count!r} is no positive whole number"
        raise ValueError(msg)
    return LearnedMean(float(value), count)


def node_action_types(node: Node) -> tuple[str, ...]:
    """The action types of ``node``, in order (the key its dwell is learned under)."""
    return tuple(action.action_type for action in node.actions)


def _path(graph: Graph, leg: Leg) -> tuple[tuple[float, float], ...]:
    """The points the edge is driven through: the graph's, else its nodes' positions."""
    known = graph.edges.get(leg.edge_id)
    if known is not None:
        return graph.edge_path(known)
    return leg.ends or ()


def _length(graph: Graph, leg: Leg, path: tuple[tuple[float, float], ...]) -> float:
    if leg.edge_id in graph.edges:
        return graph.edge_length(leg.edge_id)
    if leg.length is not None:
        return leg.length
    return math.dist(path[0], path[-1]) if path else 0.0


def _speed(leg: Leg, drive: Drive) -> float:
    """The speed an edge is driven at: the vehicle's, capped by the edge's ``maxSpeed``."""
    if leg.max_speed is None:
        return drive.speed_mps
    return max(1e-9, min(drive.speed_mps, leg.max_speed * drive.edge_speed_factor))


def _heading(a: tuple[float, float], b: tuple[float, float]) -> float:
    return math.atan2(b[1] - a[1], b[0] - a[0])
