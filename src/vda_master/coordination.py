"""The shell side of traffic control (issue 9; the pure core is :mod:`vda_master.traffic`).

:class:`Coordinator` holds the immutable :class:`~vda_master.traffic.TrafficController`, feeds it
what the service observes (states, new orders, finished orders, factsheets) and answers the
dispatcher's one question: how far may this vehicle's base be released now? It logs one line per
wait, and turns the controller's snapshot into what the API shows. With ``traffic_control`` off
it answers "as far as the release window wants" and plans plain shortest routes, as before.

The safety distance comes from ``safety_distance_m`` or, unset, from the largest footprint of
the factsheets seen (:func:`~vda_master.traffic.default_safety_distance_m`, 1.0 m without any);
a larger footprint arriving later rebuilds the conflict sets once no vehicle drives a route
(with traffic control off, once the controller is next used: Coordinator._settled).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import structlog

from vda5050.models import Factsheet, State
from vda5050.topics import AgvId
from vda_master.config import MasterConfig
from vda_master.graph import Graph
from vda_master.routing import Route
from vda_master.traffic import (
    Advice,
    AtNode,
    MoveToParking,
    OffGraph,
    OnRoute,
    PlannedRoute,
    Position,
    Proposal,
    SearchBudget,
    SpeedModel,
    TrafficController,
    TrafficSettings,
    TrafficSnapshot,
    default_safety_distance_m,
)
from vda_master.traffic.conflicts import DEFAULT_SAFETY_MARGIN_M, resources_within

log = structlog.get_logger()

#: A vehicle without an order reported farther than this from its lastNodeId stands off the
#: graph's nodes (the safety distance's margin covers localisation and path deviation).
OFF_NODE_M = DEFAULT_SAFETY_MARGIN_M


def off_node_spot(graph: Graph, state: State) -> tuple[float, float, str] | None:
    """Where ``state`` puts its vehicle, (x, y, mapId), if that is off its lastNodeId (or the
    node is not in ``graph``); None when it stands on the node or reports no position."""
    position = state.agv_position
    if position is None or not position.position_initialized:
        return None
    node = graph.nodes.get(state.last_node_id)
    if (
        node is not None
        and graph.node_map_id(node) == position.map_id
        and math.hypot(position.x - node.x, position.y - node.y) <= OFF_NODE_M
    ):
        return None
    return position.x, position.y, position.map_id


@dataclass(frozen=True, slots=True)
class WaitView:
    """Whom a vehicle waits for, where and how long (for the order view and the map)."""

    waiting_for: tuple[str, ...]
    node_id: str
    waited_s: float


@dataclass(frozen=True, slots=True)
class WaitChange:
    """A vehicle started waiting in traffic (``waited_s`` None) or stopped waiting."""

    agv: AgvId
    node_id: str | None = None
    waiting_for: tuple[str, ...] = ()
    resource: str | None = None
    waited_s: float | None = None


class Coordinator:
    """Traffic control as the master service uses it. ``on_wait`` (optional) hears every wait
    that starts or ends (the order history records them)."""

    def __init__(self, graph: Graph, config: MasterConfig) -> None:
        self.graph = graph
        self.enabled = config.traffic_control
        #: Told every resolution carried out (``vda-fleetsim`` counts them per order).
        self.on_record: Callable[[Proposal, float, tuple[AgvId, ...]], None] = _ignore
        self._configured_distance = config.safety_distance_m
        self._settings = TrafficSettings(
            max_wait_s=config.max_wait_s,
            one_lane_factor=config.one_lane_cost_factor,
            detour_margin_s=config.detour_margin_s,
        ).at_time_lapse(config.time_lapse)
        self._factsheets: dict[AgvId, Factsheet] = {}
        self._idle_at: dict[AgvId, str] = {}
        #: Where vehicles without an order stand off the graph's nodes: (x, y, mapId).
        self._off_graph_at: dict[AgvId, tuple[float, float, str]] = {}
        self._rebuild_pending = False
        distance = self._configured_distance or default_safety_distance_m(())
        self.controller = TrafficController.for_graph(graph, distance, self._settings)
        self.on_wait: Callable[[WaitChange], None] | None = None

    def set_graph(self, graph: Graph) -> None:
        """Route on ``graph`` from now on: the same file with other zones (``POST /zones``).
        Holdings and waits stay; the shell changes the routes that use a closed edge."""
        self.graph = graph
        self.controller = self.controller.with_graph(graph)

    @property
    def safety_distance_m(self) -> float:
        return self.controller.state.conflicts.safety_distance_m

    # -- what the service observes -------------------------------------------------------------

    def note_factsheet(self, agv: AgvId, factsheet: Factsheet) -> None:
        """Speed for planning; a larger footprint may widen the safety distance."""
        self._factsheets[agv] = factsheet
        speed = factsheet.physical_parameters.speed_max
        if speed > 0 and self.enabled:  # off: nothing plans (a fleet connecting pays nothing)
            self.controller = self.controller.with_speed(agv, SpeedModel(speed))
        if self._configured_distance is None:
            # Only this footprint can widen the distance (it never shrinks): O(1) per factsheet,
            # not O(fleet); the rebuild takes the largest of all.
            wanted = default_safety_distance_m((factsheet,))
            if wanted > self.safety_distance_m + 1e-9:
                self._rebuild_pending = True
                if self.enabled:  # off: put off until the controller is used (_settled)
                    self._try_rebuild()

    def observe(
        self, agv: AgvId, state: State, progress: int | None, now: float
    ) -> tuple[AgvId, ...]:
        """Fold in a state: ``progress`` is the vehicle's index on its order's route, None when
        it runs no order of ours. Returns the vehicles waiting for it that may go on now.
        With traffic control off nothing is kept (nothing would use it)."""
        if not self.enabled:
            return ()
        if progress is not None:
            position: Position = OnRoute(progress)
        else:
            idle = self._idle_position(agv, state)
            if idle is None:
                return ()
            position = idle
        self.controller, woken = self.controller.observe(agv, position, now)
        return woken

    def _idle_position(self, agv: AgvId, state: State) -> AtNode | OffGraph | None:
        """Where a vehicle without an order of ours stands: on its lastNodeId, or, reported
        farther than :data:`OFF_NODE_M` from it (moved by hand, stopped between two nodes, an
        unknown node), off the graph, covering what lies within the safety distance; None
        when neither is known. Remembered for a rebuild of the conflict sets."""
        spot = off_node_spot(self.graph, state)
        if spot is not None:
            self._idle_at.pop(agv, None)
            self._off_graph_at[agv] = spot
            return self._off_graph(spot)
        self._off_graph_at.pop(agv, None)
        if state.last_node_id in self.graph.nodes:
            self._idle_at[agv] = state.last_node_id
            return AtNode(state.last_node_id)
        return None

    def _off_graph(self, spot: tuple[float, float, str]) -> OffGraph:
        x, y, map_id = spot
        return OffGraph(resources_within(self.graph, (x, y), map_id, self.safety_distance_m))

    def assign(
        self, agv: AgvId, route: Route, now: float, *, progress: int = 0, released_end: int = 0
    ) -> None:
        """``agv`` drives ``route`` (a new order, or one resumed after a restart, which counts
        from now): it stands at node ``progress`` and holds its base up to ``released_end``.
        Re-plans and back-offs reach the controller through :meth:`grant`, keeping the order's
        start."""
        if not self.enabled:
            return
        self._idle_at.pop(agv, None)
        self.controller = self.controller.assign(
            agv, route, now, progress=progress, released_end=released_end, new_order=True
        )

    def add_leg(self, agv: AgvId, start: str, destination: str, now: float) -> None:
        """``agv``'s order was given one more stop (docs/master.md, *Orders with several
        stops*): it is due later by that leg's free-flow time (traffic.priority)."""
        if self.enabled:
            self.controller = self.controller.add_leg(agv, start, destination, now)

    def finish(self, agv: AgvId, state: State | None, now: float) -> tuple[AgvId, ...]:
        """``agv``'s order ended; it stands idle where its last ``state`` says: on its
        lastNodeId, or off the graph's nodes (an order it cleared in MANUAL, say)."""
        if not self.enabled:
            return ()
        at = self._idle_position(agv, state) if state is not None else None
        self.controller, woken = self.controller.finish(agv, now, at)
        self._try_rebuild()
        return woken

    def forget(self, agv: AgvId) -> None:
        """``agv`` left the fleet view."""
        self._idle_at.pop(agv, None)
        self._off_graph_at.pop(agv, None)
        self._factsheets.pop(agv, None)
        self.controller = self.controller.forget(agv)

    # -- the dispatcher's question -------------------------------------------------------------

    def grant(
        self,
        agv: AgvId,
        route: Route,
        *,
        progress: int,
        released_end: int,
        desired_end: int,
        now: float,
    ) -> int:
        """How far the base may be released now (never below ``released_end``)."""
        if not self.enabled:
            return desired_end
        before = self.controller.vehicle(agv).wait
        self.controller, release = self.controller.request_release(
            agv,
            route,
            progress_index=progress,
            released_end=released_end,
            desired_end=desired_end,
            now=now,
        )
        wait = release.wait
        change = None
        if release.started_waiting and wait is not None:
            blockers = tuple(sorted(str(a) for a in wait.blockers))
            change = WaitChange(agv, wait.node_id, blockers, str(wait.resource))
            log.info(
                "traffic.wait_started",
                agv=str(agv),
                node_id=wait.node_id,
                waiting_for=list(blockers),
                resource=str(wait.resource),
                # free, but claimed by a late vehicle (traffic.priority)
                claimed=release.blocked is not None and release.blocked.claim,
            )
        elif before is not None and wait is None:
            change = WaitChange(agv, before.node_id, waited_s=round(now - before.since, 2))
            log.info("traffic.wait_ended", agv=str(agv), waited_s=change.waited_s)
        if change is not None and self.on_wait is not None:
            self.on_wait(change)
        return release.end

    # -- planning ------------------------------------------------------------------------------

    def plan(self, agv: AgvId, start: str, destination: str, now: float) -> PlannedRoute | None:
        """The time-aware route (None: no route at all); shortest route when disabled."""
        if not self.enabled:
            return None
        return self.controller.plan(agv, start, destination, now)

    def static_route(self, start: str, destination: str) -> Route | None:
        """The route traffic control would give a vehicle alone (None when it is off, or there
        is none)."""
        if not self.enabled:
            return None
        return self.controller.static_route(start, destination)

    def choose(
        self, candidates: Iterable[tuple[AgvId, str]], destinations: tuple[str, ...], now: float
    ) -> tuple[AgvId, PlannedRoute] | None:
        """The candidate and destination expected to meet first, counting traffic."""
        self._settled()
        return self.controller.choose(list(candidates), destinations, now)

    # -- advice and views ----------------------------------------------------------------------

    def advice(self, now: float, budget: SearchBudget | None = None) -> Advice | None:
        """What to do about waits and deadlocks now (None when traffic control is off)."""
        return self.controller.advice(now, budget) if self.enabled else None

    def record(self, proposal: Proposal, now: float, vehicles: tuple[AgvId, ...]) -> None:
        """A proposal was carried out (for the deadlock of ``vehicles``, if any)."""
        self.controller = self.controller.record_resolution(proposal, now, vehicles)
        self.on_record(proposal, now, vehicles)

    def in_the_way(
        self, agv: AgvId, now: float, budget: SearchBudget | None = None
    ) -> tuple[MoveToParking, ...]:
        """Idle vehicles standing on ``agv``'s route (none when traffic control is off)."""
        return self.controller.in_the_way(agv, now, budget) if self.enabled else ()

    def wait_of(self, agv: AgvId, now: float) -> WaitView | None:
        """Whom ``agv`` waits for, if it waits."""
        wait = self.controller.vehicle(agv).wait
        if wait is None:
            return None
        blockers = tuple(sorted(str(a) for a in wait.blockers))
        return WaitView(blockers, wait.node_id, round(now - wait.since, 3))

    def snapshot(self, now: float) -> TrafficSnapshot:
        self._settled()
        return self.controller.snapshot(now)

    def _settled(self) -> None:
        """With traffic control off, a wider safety distance from a factsheet is applied when
        the controller is first used (a vehicle chosen, a snapshot), not on
        the factsheet: a fleet connecting at once would otherwise pay the conflict-set
        rebuild (~0.3 s for 3000 nodes) in the middle of its start-up. The rebuild is the same
        (with traffic control off no vehicle holds a route, so it can always be made)."""
        if not self.enabled:
            self._try_rebuild()

    def _try_rebuild(self) -> None:
        """Rebuild the conflict sets with the wider safety distance once no vehicle drives a
        route (reservations of driving vehicles must not change under them)."""
        if not self._rebuild_pending:
            return
        state = self.controller.state
        if any(vehicle.route is not None for _, vehicle in state.vehicles.items()):
            return
        distance = default_safety_distance_m(self._factsheets.values())
        rebuilt = TrafficController.for_graph(self.graph, distance, self._settings)
        for agv, factsheet in self._factsheets.items():
            if factsheet.physical_parameters.speed_max > 0:
                rebuilt = rebuilt.with_speed(
                    agv, SpeedModel(factsheet.physical_parameters.speed_max)
                )
        for agv, node_id in self._idle_at.items():
            rebuilt, _ = rebuilt.observe(agv, AtNode(node_id), 0.0)
        self.controller = rebuilt
        for agv, spot in self._off_graph_at.items():  # what they cover grows with the distance
            self.controller, _ = self.controller.observe(agv, self._off_graph(spot), 0.0)
        self._rebuild_pending = False
        log.info("traffic.safety_distance_set", safety_distance_m=round(distance, 3))


def _ignore(_proposal: Proposal, _now: float, _vehicles: tuple[AgvId, ...]) -> None:
    """No one listens to the resolutions carried out."""
