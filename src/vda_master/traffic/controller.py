"""The traffic controller: one immutable fold over what the master shell observes (issue 9).

The shell calls it on events and gets a new controller back, plus what to do:

==============================  ================================================================
``for_graph``                   once per graph load: conflict sets, one-lane edges, stations
``observe(agv, position)``      a state arrived: frees what the vehicle passed; an idle vehicle
                                holds its node. Returns the vehicles waiting for it, to retry
``request_release(...)``        how far the base may be released now, and the wait if any
``assign`` / ``finish``         a route starts (order created or re-planned) / the order ended
                                (a new order's start and free-flow time: :mod:`.priority`)
``advice(now)``                 deadlocks with a resolution, over-long waits to re-plan, idle
                                vehicles a waiting vehicle waits for, to send to parking
``in_the_way(agv, now)``        idle vehicles standing on ``agv``'s route (call after assign)
``plan`` / ``choose``           time-aware route; the candidate expected to arrive first
``record_resolution``           the shell carried out a proposal (counted in the snapshot)
``snapshot(now)``               the ``GET /traffic`` view
==============================  ================================================================

Per call the work is O(route × conflict-set size); ``advice`` is O(waiting vehicles) and only
``snapshot`` is O(fleet). The reservation invariant (no two vehicles hold conflicting resources)
holds after every call (:mod:`vda_master.traffic.reservations`). Every time value is passed in
(monotonic seconds).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial

from vda5050.topics import AgvId
from vda_master.graph import Graph
from vda_master.routing import Route
from vda_master.traffic import advice as advice_rules
from vda_master.traffic import state as rules
from vda_master.traffic.conflicts import Resource, build_conflicts
from vda_master.traffic.gate import Blocked, decide_release_end, route_resources
from vda_master.traffic.passages import SpeedModel, estimate_timeline
from vda_master.traffic.paths import build_roadmap, cheapest_route
from vda_master.traffic.planner import (
    Candidate,
    PlannedRoute,
    Spans,
    earliest_arrival,
    plan_route,
)
from vda_master.traffic.priority import claimed, claims_against
from vda_master.traffic.reservations import Refused, ReservationTable
from vda_master.traffic.snapshot import (
    Advice,
    TrafficSnapshot,
    VehicleSnapshot,
    resolution_of,
)
from vda_master.traffic.state import TrafficSettings, TrafficState, VehicleTraffic
from vda_master.traffic.waits import (
    Deadlock,
    MoveToParking,
    Proposal,
    Replan,
    SearchBudget,
    Wait,
)


@dataclass(frozen=True, slots=True)
class AtNode:
    """The vehicle stands on ``node_id`` (its ``lastNodeId``) without a route to drive."""

    node_id: str


@dataclass(frozen=True, slots=True)
class OnRoute:
    """The vehicle drives its assigned route; ``progress_index`` is its last traversed node."""

    progress_index: int


@dataclass(frozen=True, slots=True)
class OffGraph:
    """The vehicle, without a route to drive, stands off the graph's nodes and covers
    ``resources`` (:func:`~vda_master.traffic.conflicts.resources_within`)."""

    resources: frozenset[Resource]


Position = AtNode | OnRoute | OffGraph


@dataclass(frozen=True, slots=True)
class Release:
    """The answer to :meth:`TrafficController.request_release`."""

    end: int
    blocked: Blocked | None
    wait: Wait | None
    #: True on the call that made the vehicle wait (log ``traffic.wait_started`` once).
    started_waiting: bool


@dataclass(frozen=True, slots=True)
class TrafficController:
    """Reservations, waits and plans of the whole fleet; every method returns a new one."""

    state: TrafficState

    @classmethod
    def for_graph(
        cls, graph: Graph, safety_distance_m: float, settings: TrafficSettings | None = None
    ) -> TrafficController:
        """A controller with no vehicles for ``graph``; computes the conflict sets (of every
        node and edge of the file: zones close edges to routing, not to geometry)."""
        conflicts = build_conflicts(graph.unzoned(), safety_distance_m, graph.release_zones)
        settings = settings or TrafficSettings()
        roads = build_roadmap(
            graph, one_lane_factor=settings.one_lane_factor, speed_factor=settings.time_lapse
        )
        table = ReservationTable(conflicts)
        return cls(TrafficState(roads, conflicts, settings, table))

    def with_graph(self, graph: Graph) -> TrafficController:
        """The same reservations, waits and plans, routing on ``graph``: the same file with
        other zones (the conflict sets stay, being the file's geometry). Routes that use an
        edge ``graph`` closes are the shell's to change (:mod:`vda_master.graph_change`)."""
        settings = self.state.settings
        roads = build_roadmap(
            graph, one_lane_factor=settings.one_lane_factor, speed_factor=settings.time_lapse
        )
        return TrafficController(replace(self.state, roads=roads))

    def release_zone_holders(self, zone_id: str) -> frozenset[AgvId]:
        """The vehicles holding a resource from which they reach into RELEASE zone ``zone_id``
        (at most one: those resources all conflict); empty for an unknown zone."""
        group = self.state.conflicts.release_zones.get(zone_id, frozenset())
        table = self.state.table
        return frozenset(agv for r in group if (agv := table.holder(r)) is not None)

    def vehicle(self, agv: AgvId) -> VehicleTraffic:
        """What is known about ``agv`` (an empty record if nothing)."""
        return self.state.vehicle(agv)

    # -- events --------------------------------------------------------------------------------

    def observe(
        self, agv: AgvId, position: Position, now: float
    ) -> tuple[TrafficController, tuple[AgvId, ...]]:
        """Fold in where ``agv`` is; returns the vehicles waiting for it if it freed anything.

        :class:`OnRoute` applies to a vehicle with an assigned route, :class:`AtNode` and
        :class:`OffGraph` to one without (while routed, progress and not ``lastNodeId`` drives
        the holdings).
        """
        routed = self.vehicle(agv).route is not None
        if isinstance(position, OnRoute) and routed:
            state, woken = rules.advance(self.state, agv, position.progress_index, now)
        elif isinstance(position, AtNode) and not routed:
            state, woken = rules.stand(self.state, agv, position.node_id, now)
        elif isinstance(position, OffGraph) and not routed:
            state, woken = rules.occupy(self.state, agv, position.resources, now)
        else:
            return self, ()
        return TrafficController(state), woken

    def assign(
        self,
        agv: AgvId,
        route: Route,
        now: float,
        *,
        progress: int = 0,
        released_end: int = 0,
        new_order: bool = False,
    ) -> TrafficController:
        """``agv`` drives ``route`` from now on; it stands at node ``progress`` (its last
        traversed) and nodes up to ``released_end`` are already released to it (they are held as
        far as they are free). A ``new_order`` starts now and takes the free-flow time of the
        route the vehicle would get alone (:mod:`.priority`); otherwise the route replaces the
        current order's (a re-plan, a back-off), which keeps its start."""
        state = rules.set_wait(rules.set_destination(self.state, agv, route.destination), agv, None)
        vehicle = state.vehicle(agv)
        if new_order:
            alone = self._free_flow(
                route.node_ids[progress], route.destination, state.speed_of(agv), now
            )
            driving_s = alone.arrival - now if alone is not None else 0.0
            free_flow_s = driving_s + state.settings.dwell_s
            vehicle = replace(vehicle, order_since=now, free_flow_s=free_flow_s)
        vehicle = replace(
            vehicle,
            route=route,
            progress=progress,
            granted_end=progress,
            node_id=route.node_ids[progress],
            blocked=None,
            unplaced=None,
            resolving_since=None,
        )
        state = rules.hold_start(rules.store(state, vehicle), agv, route, progress)
        state = rules.adopt(state, agv, released_end)
        return TrafficController(rules.estimate(state, agv, now))

    def add_leg(self, agv: AgvId, start: str, destination: str, now: float) -> TrafficController:
        """``agv``'s order goes on from ``start`` to one more stop, ``destination``: its
        free-flow estimate grows by that leg's (driven alone, plus the action there), so that an
        order with several stops turns late against all of its legs, not its first alone."""
        vehicle = self.vehicle(agv)
        if vehicle.order_since is None or vehicle.free_flow_s is None:
            return self
        alone = self._free_flow(start, destination, self.state.speed_of(agv), now)
        driving_s = alone.arrival - now if alone is not None else 0.0
        extended = vehicle.free_flow_s + driving_s + self.state.settings.dwell_s
        return TrafficController(rules.store(self.state, replace(vehicle, free_flow_s=extended)))

    def finish(
        self, agv: AgvId, now: float, at: AtNode | OffGraph | None = None
    ) -> tuple[TrafficController, tuple[AgvId, ...]]:
        """``agv``'s order ended; it stands idle ``at`` (default: on its last traversed node)
        and holds only what it stands on from now on. Returns the vehicles waiting for it."""
        node_id = self.vehicle(agv).node_id
        if at is None and node_id is not None:
            at = AtNode(node_id)
        state = rules.set_wait(rules.set_destination(self.state, agv, None), agv, None)
        idle = replace(
            state.vehicle(agv), route=None, progress=0, granted_end=0, blocked=None,
            resolving_since=None, order_since=None, free_flow_s=None,
        )  # fmt: skip
        state = rules.store(state, idle)
        if at is None:
            return TrafficController(state), ()
        if isinstance(at, OffGraph):
            state, woken = rules.occupy(state, agv, at.resources, now)
        else:
            state, woken = rules.stand(state, agv, at.node_id, now, force=True)
        return TrafficController(state), woken

    def forget(self, agv: AgvId) -> TrafficController:
        """Drop ``agv`` entirely (it left the fleet): its holdings and passages are freed."""
        state = rules.set_wait(rules.set_destination(self.state, agv, None), agv, None)
        table = state.table.release(agv, state.table.held_by(agv))
        return TrafficController(
            replace(state, table=table, passages=state.passages.without(agv),
                    vehicles=state.vehicles.remove(agv))
        )  # fmt: skip

    def request_release(
        self,
        agv: AgvId,
        route: Route,
        *,
        progress_index: int,
        released_end: int,
        desired_end: int,
        now: float,
    ) -> tuple[TrafficController, Release]:
        """How far ``agv``'s base on ``route`` may be released now (see :mod:`.gate`).

        A route other than the assigned one is assigned first. The granted end is claimed and
        is never below ``released_end``. The vehicle *waits* while it stands at the end of its
        base (``progress_index`` equals the granted end) and the next step is refused.
        """
        before = self.vehicle(agv)
        if before.route != route:
            state = self.assign(
                agv, route, now, progress=progress_index, released_end=released_end
            ).state
        else:
            state, _ = rules.advance(self.state, agv, progress_index, now)
            state = rules.adopt(state, agv, released_end)
        vehicle = state.vehicle(agv)
        claims = claims_against(state, agv, now)
        grant = decide_release_end(
            state.table, agv, route, progress=vehicle.progress,
            released_end=vehicle.granted_end, desired_end=desired_end,
            claimed=partial(claimed, state.conflicts, claims) if claims else None,
        )  # fmt: skip
        # Only the granted steps: the node the base ends on is held already, unless the vehicle
        # could not be placed (it reported a node another vehicle holds): never claim it then.
        steps = route_resources(route, vehicle.granted_end, grant.end)[1:]
        table = state.table.claim(agv, steps)
        if not isinstance(table, ReservationTable):  # the gate checked every step
            msg = f"release gate granted resources that are not free: {table}"
            raise TypeError(msg)
        stuck = grant.blocked is not None and grant.end == vehicle.progress
        wait = _wait_of(vehicle, grant.blocked, now) if stuck else None
        vehicle = replace(vehicle, granted_end=grant.end, blocked=grant.blocked)
        state = rules.set_wait(rules.store(replace(state, table=table), vehicle), agv, wait)
        started = wait is not None and before.wait is None
        return TrafficController(state), Release(grant.end, grant.blocked, wait, started)

    def record_resolution(
        self, proposal: Proposal, now: float, vehicles: Sequence[AgvId] = ()
    ) -> TrafficController:
        """The shell carried out ``proposal`` (for the deadlock of ``vehicles``, if any)."""
        state = self.state
        entry = resolution_of(proposal, now, tuple(vehicles))
        vehicle = replace(state.vehicle(proposal.agv), resolving_since=now)
        if vehicles and isinstance(proposal, Replan):
            window_s = state.settings.detour_repeat_window_s
            detours = (*rules.recent_detours(vehicle, now, window_s), now)
            vehicle = replace(vehicle, deadlock_detours=detours)
        history = (*state.history, entry)[-state.settings.history :]
        resolved = state.resolved + bool(vehicles)
        return TrafficController(
            replace(rules.store(state, vehicle), resolved=resolved, history=history)
        )

    # -- advice --------------------------------------------------------------------------------

    def advice(self, now: float, budget: SearchBudget | None = None) -> Advice:
        """Deadlocks with resolutions, over-long waits to re-plan, idle vehicles to move away
        (``budget``: how many idle vehicles' parking places may be looked for)."""
        return advice_rules.advise(self.state, now, budget)

    def deadlocks(self, now: float) -> tuple[Deadlock, ...]:
        """Groups of waiting vehicles that wait for each other, each with a proposal."""
        return advice_rules.deadlocks(self.state, now)

    def in_the_way(
        self, agv: AgvId, now: float, budget: SearchBudget | None = None
    ) -> tuple[MoveToParking, ...]:
        """Idle vehicles standing on (or too close to) what is left of ``agv``'s route."""
        return advice_rules.in_the_way(self.state, agv, now, budget)

    # -- planning ------------------------------------------------------------------------------

    def plan(self, agv: AgvId, start: str, destination: str, now: float) -> PlannedRoute | None:
        """The time-aware route for ``agv`` (see :mod:`.planner`): the cheapest static route,
        waiting where the others' passages say, unless a route round them is expected to arrive
        at least ``detour_margin_s`` earlier; without a traffic-free plan, the static route at
        free-flow times; None if there is no route at all. A route that would start towards a
        vehicle waiting for ``agv`` (or about to) is replaced by the cheapest one around it
        (:func:`~vda_master.traffic.advice.facing`), if there is one."""
        planned = self._plan(agv, start, destination, now)
        if planned is None or not planned.route.edge_ids:
            return planned
        facing = advice_rules.facing(self.state, agv, planned.route)
        if not facing:
            return planned
        around = advice_rules.route_not_facing(self.state, start, destination, facing)
        if around is None:
            return planned
        return self._at_free_flow(around, self.state.speed_of(agv), now)

    def _plan(self, agv: AgvId, start: str, destination: str, now: float) -> PlannedRoute | None:
        state = self.state
        speed = state.speed_of(agv)
        static = cheapest_route(state.roads, start, destination)
        if static is None:
            return None
        plan = partial(
            plan_route, state.roads, state.conflicts, state.passages, agv=agv, start=start,
            destination=destination, start_time=now, speed=speed, dwell_s=state.settings.dwell_s,
            spans=Spans(state.conflicts, state.passages, now),  # shared by both searches
        )  # fmt: skip
        along = plan(only_edges=frozenset(static.edge_ids))
        margin = state.settings.detour_margin_s
        if along is not None and (math.isinf(margin) or along.waited_s < margin):
            return along  # a detour cannot arrive earlier by the margin
        around = plan()
        if along is None:
            return around if around is not None else self._free_flow(start, destination, speed, now)
        if around is not None and around.arrival + margin <= along.arrival:
            return around
        return along

    def choose(
        self, candidates: Sequence[tuple[AgvId, str]], destinations: tuple[str, ...], now: float
    ) -> tuple[AgvId, PlannedRoute] | None:
        """Among (vehicle, start node) pairs and ``destinations`` (one node, or the stations of
        a type), the pair expected to arrive first, with its route as :meth:`plan` gives it;
        without a traffic-free plan, the pair nearest in free flow."""
        state = self.state
        options = [Candidate(agv, start, now, state.speed_of(agv)) for agv, start in candidates]
        best = earliest_arrival(
            state.roads, state.conflicts, state.passages, options, destinations,
            dwell_s=state.settings.dwell_s,
        )  # fmt: skip
        if best is not None:
            chosen, planned = best
            destination = planned.route.destination
            return chosen.agv, self.plan(chosen.agv, chosen.start, destination, now) or planned
        fallback = [
            (plan.arrival, str(c.agv), rank, c.agv, plan)
            for c in options
            for rank, destination in enumerate(destinations)
            if (plan := self._free_flow(c.start, destination, c.speed, now)) is not None
        ]
        if not fallback:
            return None
        *_, agv, plan = min(fallback, key=lambda option: option[:3])
        return agv, plan

    def with_speed(self, agv: AgvId, speed: SpeedModel) -> TrafficController:
        """Remember ``agv``'s speed (e.g. from its factsheet's ``speedMax``)."""
        return TrafficController(rules.store(self.state, replace(self.vehicle(agv), speed=speed)))

    def static_route(self, start: str, destination: str) -> Route | None:
        """The route a vehicle alone would be given (least cost, one-lane edges counted at the
        one-lane factor; None if there is none): what a leg not yet planned is expected to
        take."""
        return cheapest_route(self.state.roads, start, destination)

    def _free_flow(
        self, start: str, destination: str, speed: SpeedModel, now: float
    ) -> PlannedRoute | None:
        route = cheapest_route(self.state.roads, start, destination)
        return None if route is None else self._at_free_flow(route, speed, now)

    def _at_free_flow(self, route: Route, speed: SpeedModel, now: float) -> PlannedRoute:
        """``route`` driven from now without waiting, ignoring the others' passages."""
        timeline = estimate_timeline(self.state.roads, route, speed, start_time=now)
        return PlannedRoute(route, timeline, avoids_traffic=False)

    # -- observability -------------------------------------------------------------------------

    def snapshot(self, now: float) -> TrafficSnapshot:
        """Per vehicle: holdings, route still to release, whom it waits for and since when."""
        state = self.state
        rows = sorted(
            (self._row(v, now) for _, v in state.vehicles.items()), key=lambda r: str(r.agv)
        )
        return TrafficSnapshot(
            state.conflicts.safety_distance_m, tuple(rows), state.resolved, state.history
        )

    def _row(self, vehicle: VehicleTraffic, now: float) -> VehicleSnapshot:
        held = tuple(sorted(str(r) for r in self.state.table.held_by(vehicle.agv)))
        route, wait = vehicle.route, vehicle.wait
        pending = route.node_ids[vehicle.granted_end + 1 :] if route is not None else ()
        return VehicleSnapshot(
            agv=vehicle.agv, node_id=vehicle.node_id, held=held, pending_node_ids=pending,
            waiting_for=tuple(sorted(wait.blockers, key=str)) if wait else (),
            waiting_at=str(wait.resource) if wait else None,
            since=wait.since if wait else None,
            waited_s=now - wait.since if wait else None,
            conflict=_describe(vehicle.unplaced) if vehicle.unplaced else None,
        )  # fmt: skip


def _describe(refused: Refused) -> str:
    return f"{refused.wanted} conflicts with {refused.held} held by {refused.holder}"


def _wait_of(vehicle: VehicleTraffic, blocked: Blocked | None, now: float) -> Wait | None:
    """The vehicle's wait, keeping the time it started if it was already waiting."""
    if blocked is None or vehicle.node_id is None:
        return None
    since = vehicle.wait.since if vehicle.wait is not None else now
    return Wait(blocked.holders, blocked.refused.wanted, vehicle.node_id, since)
