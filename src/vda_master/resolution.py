"""Carrying out what traffic control advises (issue 9, :mod:`vda_master.traffic.advice`).

The controller proposes, as values, how to get vehicles going again; this module does it with
the master's own means:

- ``Replan``: the order's route is replaced from the decision point on (the base never changes,
  R66); the next base extension sends the new horizon.
- ``BackOff``: the route is replaced by the way back to a free node; once there, the order goes
  on to its destination (with its destination actions) by a new route.
- ``MoveToParking``: master control sends the idle vehicle an order of its own to the parking
  node (its ``note`` says why).

Each is recorded with the controller, so one situation is not resolved twice, and logged once
(``traffic.replanned``, ``traffic.deadlock_resolved``, ``traffic.vehicle_parked``).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import TYPE_CHECKING, Final

import structlog

from vda5050.models import Action, State
from vda5050.topics import AgvId
from vda_master.capabilities import ActionSpec
from vda_master.coordination import Coordinator
from vda_master.dispatcher import TRAFFIC_NOTE, OrderTrack, Resume
from vda_master.fleet import FleetView, VehicleView
from vda_master.graph import Graph
from vda_master.order_builder import BuildProblem, replan
from vda_master.release import progress_index
from vda_master.routing import Route, RouteProblem, shortest_route
from vda_master.stops import Stop
from vda_master.traffic import BackOff, MoveToParking, Proposal, Replan, SearchBudget

log = structlog.get_logger()
#: Seconds between two looks at the controller's advice (simulated seconds: divided by the
#: config's ``time_lapse``).
ADVICE_EVERY_S: Final = 1.0
#: Idle vehicles whose parking place one request or one look at the advice may look for: a new
#: order's way, then the ways of the vehicles it sends to parking (each clears its own way in
#: turn), or the advice's. The rest are left to the next look at the advice, which sends
#: whoever still stands in a waiting vehicle's way. Unbounded, on a crowded floor one order moved
#: vehicle after vehicle within its own request, each search settling most of the map (300
#: vehicles on 400 nodes: 4 s before the first answer; 1000 on 4000: no answer within 10 s).
PARKING_SEARCHES_MAX: Final = 24


class Resolution:
    """Mixed into the master service: what to do when vehicles wait for each other."""

    graph: Graph
    fleet: FleetView
    tracks: dict[str, OrderTrack]
    active: dict[AgvId, str]
    coordinator: Coordinator

    if TYPE_CHECKING:

        def _store(self, agv: AgvId, track: OrderTrack) -> None: ...
        def _extended(self, track: OrderTrack, state: State, now: float) -> OrderTrack: ...
        def _pump(self, agv: AgvId, now: float) -> None: ...
        def availability(
            self, vehicle: VehicleView, now: float, *, automatic_only: bool = True
        ) -> str | None: ...
        def start_order(
            self,
            vehicle: VehicleView,
            route: Route,
            destination_actions: tuple[ActionSpec, ...],
            now: float,
            *,
            note: str = "",
        ) -> OrderTrack: ...

    def resolve_traffic(self, now: float) -> None:
        """Look at the controller's advice and carry it out."""
        with self._search_budget() as budget:
            advice = self.coordinator.advice(now, budget)
            if advice is None:
                return
            for deadlock in advice.deadlocks:
                proposal = deadlock.proposal
                if proposal is not None and self._carry_out(proposal, now):
                    self.coordinator.record(proposal, now, deadlock.vehicles)
                    log.info(
                        "traffic.deadlock_resolved",
                        vehicles=[str(a) for a in deadlock.vehicles],
                        kind=type(proposal).__name__,
                        agv=str(proposal.agv),
                        reason=proposal.reason,
                    )
            for single in (*advice.replans, *advice.moves):
                if self._carry_out(single, now):
                    self.coordinator.record(single, now, ())

    #: The searches left to the request or look at the advice under way (None: none is).
    _searches: SearchBudget | None = None

    def clear_the_way(self, agv: AgvId, now: float) -> None:
        """Send idle vehicles standing on ``agv``'s new route to parking (as many as
        :data:`PARKING_SEARCHES_MAX` allows in this request or look at the advice)."""
        with self._search_budget() as budget:
            for move in self.coordinator.in_the_way(agv, now, budget):
                if self._carry_out(move, now):  # its parking order clears its way in turn
                    self.coordinator.record(move, now, ())

    @contextmanager
    def _search_budget(self) -> Iterator[SearchBudget]:
        """The budget of parking searches of the request or look under way, or a new one."""
        if self._searches is not None:
            yield self._searches
            return
        self._searches = SearchBudget(PARKING_SEARCHES_MAX)
        try:
            yield self._searches
        finally:
            self._searches = None

    def resume_after_back_off(self, agv: AgvId, state: State, now: float) -> None:
        """A vehicle that backed off and reached its back-off node goes on to its destination."""
        order_id = self.active.get(agv)
        track = None if order_id is None else self.tracks[order_id]
        if track is None or track.resume is None or track.pending is not None:
            return
        last = track.plan.last_index
        if track.released_end != last or progress_index(track.plan, state) != last:
            return
        assert track.plan.route is not None  # noqa: S101 - backed-off tracks have a route
        here = track.plan.route.node_ids[last]
        planned = self.coordinator.plan(agv, here, track.resume.node_id, now)
        tail: Route | RouteProblem = (
            planned.route if planned else shortest_route(self.graph, here, track.resume.node_id)
        )
        if isinstance(tail, RouteProblem):
            return
        self._replace_tail(
            track, tail, last_actions=track.resume.actions, resume=None, state=state, now=now
        )
        log.info("traffic.resumed", agv=str(agv), destination=track.resume.node_id)

    def _carry_out(self, proposal: Proposal, now: float) -> bool:
        if isinstance(proposal, MoveToParking):
            return self._park(proposal, now)
        order_id = self.active.get(proposal.agv)
        vehicle = self.fleet.get(proposal.agv)
        if order_id is None or vehicle is None or vehicle.state is None:
            return False
        track = self.tracks[order_id]
        if track.pending is not None or track.cancel_action_id is not None:
            return False  # one message per order at a time; try again later
        if isinstance(proposal, Replan):
            done = self._replace_tail(
                track,
                proposal.route,
                last_actions=track.plan.nodes[-1].actions,
                resume=track.resume,
                state=vehicle.state,
                now=now,
            )
            if done:
                log.info(
                    "traffic.replanned",
                    agv=str(proposal.agv),
                    order_id=track.order_id,
                    extra_m=round(proposal.extra_m, 1),
                    reason=proposal.reason,
                )
            return done
        return self._back_off(proposal, track, vehicle.state, now)

    def _back_off(self, proposal: BackOff, track: OrderTrack, state: State, now: float) -> bool:
        resume = track.resume or Resume(proposal.resume_to, tuple(track.plan.nodes[-1].actions))
        done = self._replace_tail(
            track, proposal.route, last_actions=(), resume=resume, state=state, now=now
        )
        if done:
            log.info(
                "traffic.backed_off",
                agv=str(proposal.agv),
                node_id=proposal.node_id,
                resume_to=proposal.resume_to,
                reason=proposal.reason,
            )
        return done

    def _replace_tail(
        self,
        track: OrderTrack,
        tail: Route,
        *,
        last_actions: tuple[Action, ...] | list[Action],
        resume: Resume | None,
        state: State,
        now: float,
        onward: tuple[Stop, ...] | None = None,
    ) -> bool:
        """``track`` driving ``tail`` from its released end on, ``last_actions`` at its end;
        ``onward`` replaces the stops still to come (None: they stay)."""
        agv = track.plan.agv
        vehicle = self.fleet.get(agv)
        plan = replan(
            self.graph,
            track.plan,
            from_index=track.released_end,
            tail=tail,
            factsheet=None if vehicle is None else vehicle.factsheet,
            last_actions=tuple(last_actions),
        )
        if isinstance(plan, BuildProblem):
            log.warning("traffic.replan_failed", agv=str(agv), reason=plan.reason)
            return False
        changed = replace(
            track, plan=plan, resume=resume, onward=track.onward if onward is None else onward
        )
        self._store(agv, self._extended(changed, state, now))
        self._pump(agv, now)
        return True

    def _park(self, move: MoveToParking, now: float) -> bool:
        vehicle = self.fleet.get(move.agv)
        if vehicle is None or self.availability(vehicle, now) is not None:
            return False
        self.start_order(vehicle, move.route, (), now, note=f"{TRAFFIC_NOTE}{move.reason}")
        log.info(
            "traffic.vehicle_parked", agv=str(move.agv), node_id=move.node_id, reason=move.reason
        )
        return True
