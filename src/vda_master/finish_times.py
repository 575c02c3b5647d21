"""``expectedFinishAt`` of the order view: the shell of :mod:`vda_master.eta`.

Mixed into :class:`vda_master.service.MasterService`. Each new order is noted with the drive
its plan expects; each state of its vehicle tells whether it has reached the end of its plan
(a leg's pace) and whether the actions there have ended (a stop's dwell); an order's end is the
dwell of its last stop when no state showed that first. The estimate itself is computed when an
order view is asked for, from the plan's times (kept per plan, so a view costs O(1) after the
first), the vehicle's latest state and factsheet, and the stops still to come.
"""

from __future__ import annotations

from datetime import timedelta
from typing import TYPE_CHECKING

from vda5050.clock import Clock, format_timestamp
from vda5050.models import ActionStatus, State
from vda5050.topics import AgvId
from vda_master.config import MasterConfig
from vda_master.coordination import Coordinator
from vda_master.dispatcher import OrderStatus, OrderTrack
from vda_master.eta import (
    DEFAULT_SPEED_MPS,
    Drive,
    FinishEstimates,
    PlanTimes,
    graph_legs,
    leg_times,
    node_action_types,
    plan_legs,
)
from vda_master.fleet import FleetView
from vda_master.graph import Graph
from vda_master.order_builder import OrderPlan
from vda_master.release import progress_index
from vda_master.routing import Route, RouteProblem
from vda_master.stops import Stop

#: An estimate further ahead than this (or not a number) is none: 30 days.
_NO_ESTIMATE_BEYOND_S = 30 * 86400.0
#: Action statuses that end a stop's dwell.
_ENDED = frozenset({ActionStatus.FINISHED, ActionStatus.FAILED})
#: Statuses whose orders get an estimate: sent to a vehicle and not ended.
_UNDER_WAY = frozenset({OrderStatus.SENT, OrderStatus.ACCEPTED, OrderStatus.RUNNING})


class FinishTimes:
    """What master control learns for ``expectedFinishAt``, and the estimate of an order."""

    config: MasterConfig
    clock: Clock
    graph: Graph
    fleet: FleetView
    coordinator: Coordinator

    if TYPE_CHECKING:

        def _leg(self, start: str, stop: Stop) -> Route | RouteProblem: ...

    def _init_finish_times(self) -> None:
        self.estimates = FinishEstimates()
        #: Per order: the plan its times were computed for, the drive, and the times.
        self._plan_times: dict[str, tuple[OrderPlan, Drive, PlanTimes]] = {}

    def drive_of(self, agv: AgvId) -> Drive:
        """How ``agv`` drives, from its factsheet (:data:`DEFAULT_SPEED_MPS` without one)."""
        vehicle = self.fleet.get(agv)
        physical = vehicle.factsheet.physical_parameters if vehicle and vehicle.factsheet else None
        lapse = self.config.time_lapse
        if physical is None or physical.speed_max <= 0:
            return Drive(DEFAULT_SPEED_MPS * lapse, None, lapse)
        return Drive(physical.speed_max, physical.angular_speed_max or None, lapse)

    def _times_of(self, track: OrderTrack) -> tuple[Drive, PlanTimes]:
        kept = self._plan_times.get(track.order_id)
        drive = self.drive_of(track.plan.agv)
        if kept is not None and kept[0] is track.plan and kept[1] == drive:
            return drive, kept[2]
        times = leg_times(self.graph, plan_legs(track.plan.nodes, track.plan.edges), drive)
        self._plan_times[track.order_id] = (track.plan, drive, times)
        return drive, times

    def note_order_stored(self, old: OrderTrack | None, track: OrderTrack) -> None:
        """A track was stored: a new order is noted; an ended one is forgotten, FINISHED
        teaching its last stop's dwell if no state showed the actions there end."""
        if old is not None and (old.terminal or not track.terminal):
            return  # the usual case: a state folded into a running order
        now = self.clock.monotonic()
        if old is None and not track.terminal and track.status is not OrderStatus.QUEUED:
            _, times = self._times_of(track)
            # master control's own orders (parking, back-offs) teach nothing, nor one recovered
            # after a restart (its creation was in the run before)
            asked = not track.note and track.resume is None and track.recovering_since is None
            if asked:
                self.estimates.started(
                    track.order_id, track.plan.agv.manufacturer, times.to_node[-1], now
                )
        elif track.terminal:
            self.estimates.ended(
                track.order_id,
                node_action_types(track.plan.nodes[-1]),
                track.plan.last_index,
                finished=track.status is OrderStatus.FINISHED,
                now=now,
            )
            self._plan_times.pop(track.order_id, None)

    def note_order_progress(
        self, track: OrderTrack, state: State, progress: int | None, now: float
    ) -> None:
        """A state of the order's vehicle: has it reached the end of its plan, and are the
        actions there done?"""
        if progress is None:
            return
        order_id, last = track.order_id, track.plan.last_index

        def leg_drive_s(start: int) -> float:
            plan, drive = track.plan, self.drive_of(track.plan.agv)
            if start >= len(plan.nodes):
                return 0.0  # the plan was replaced since (a back-off): no sample
            return self._leg_drive_s(plan.nodes[start].node_id, plan.destination, drive)

        self.estimates.progressed(order_id, progress, last, now, leg_drive_s)
        if self.estimates.waits_for_dwell(order_id, last):
            node = track.plan.nodes[last]
            ids = {action.action_id for action in node.actions}
            ended = {a.action_id for a in state.action_states if a.action_status in _ENDED}
            if ids <= ended:
                self.estimates.dwelt(order_id, node_action_types(node), last, now)

    def expected_finish_utc(self, track: OrderTrack, state: State | None) -> str | None:
        """When the order is expected to finish (UTC, ISO 8601), for an order sent to its
        vehicle and not ended; None otherwise."""
        at = self.expected_finish_s(track, state)
        if at is None:
            return None
        left = at - self.clock.monotonic()
        if not left < _NO_ESTIMATE_BEYOND_S:
            return None  # a speed of almost nothing: no time worth naming (nor a date overflow)
        return format_timestamp(self.clock.now() + timedelta(seconds=left))

    def expected_finish_s(
        self, track: OrderTrack, state: State | None, learned: FinishEstimates | None = None
    ) -> float | None:
        """:meth:`expected_finish_utc` on the monotonic clock; ``learned`` instead of what
        master control has learned (benchmarks compare with nothing learned)."""
        if track.status not in _UNDER_WAY:
            return None
        learned = self.estimates if learned is None else learned
        drive, times = self._times_of(track)
        progress = progress_index(track.plan, state) if state is not None else None
        now = self.clock.monotonic()
        vehicle = self.fleet.get(track.plan.agv)
        stated_at = vehicle.last_state_at if vehicle is not None else None
        return learned.expected_finish(
            order_id=track.order_id,
            manufacturer=track.plan.agv.manufacturer,
            times=times,
            progress=progress or 0,
            state=state if progress is not None else None,
            drive=drive,
            destination_actions=node_action_types(track.plan.nodes[-1]),
            stops_s=lambda: self._stops_s(track, drive, learned),
            now=now,
            since_state_s=0.0 if stated_at is None else max(0.0, now - stated_at),
        )

    def _stops_s(self, track: OrderTrack, drive: Drive, learned: FinishEstimates) -> float:
        """Seconds for the stops after the plan's destination: the way to each (as
        :meth:`_leg_route` finds it) at the learned pace, and the dwell there."""
        seconds = 0.0
        start = track.plan.destination
        manufacturer = track.plan.agv.manufacturer
        pace = learned.pace_of(manufacturer, planned=False)
        for stop in track.onward:
            route = self._leg_route(start, stop)
            if isinstance(route, RouteProblem):
                break  # the order will end there; what follows is not driven
            times = leg_times(self.graph, graph_legs(self.graph, route.edge_ids), drive)
            types = tuple(spec.action_type for spec in stop.actions)
            seconds += times.to_node[-1] * pace + learned.dwell_of(manufacturer, types)
            start = route.destination
        return seconds

    def _leg_route(self, start: str, stop: Stop) -> Route | RouteProblem:
        """The way a leg not yet planned is expected to take: to a node, the route traffic
        control would give a vehicle alone (its one-lane costs), else (traffic control off, a
        station type) the shortest, as the leg is planned then."""
        if stop.destination is not None:
            alone = self.coordinator.static_route(start, stop.destination)
            if alone is not None:
                return alone
        return self._leg(start, stop)

    def _leg_drive_s(self, start: str, destination: str, drive: Drive) -> float:
        """The driving a leg from ``start`` to ``destination`` was expected to take before it
        was planned (the pace of a further leg is measured against it, as its estimate used
        it); 0 when there is no way."""
        route = self._leg_route(start, Stop(destination, None))
        if isinstance(route, RouteProblem):
            return 0.0
        return leg_times(self.graph, graph_legs(self.graph, route.edge_ids), drive).to_node[-1]
