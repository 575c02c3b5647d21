"""``expectedFinishAt`` of the order view: the shell of :mod:`vda_master.eta`.

Mixed into :class:`vda_master.service.MasterService`. Each new order is noted with the drive
its plan expects; each state of its vehicle tells whether it has reached the end of its plan
(a leg's pace) and whether the actions there have ended (a stop's dwell); an order's end is the
dwell of its last stop when no state showed that first. The estimate itself is computed when an
order view is asked for, from the plan's times (kept per plan, so a view costs O(1) after the
first), the vehicle's latest state and factsheet, and the stops still to come.
"""

from __future__ import annotations

import asyncio
from datetime import timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Final

import orjson
import structlog

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
from vda_master.files import write_atomically
from vda_master.fleet import FleetView, VehicleView
from vda_master.graph import Graph
from vda_master.order_builder import OrderPlan
from vda_master.release import progress_index
from vda_master.routing import Route, RouteProblem
from vda_master.stops import Stop

log = structlog.get_logger()

#: What master control has learned for its estimates, in ``data_dir``.
LEARNED_FILE: Final = "eta-learned.json"
#: An estimate further ahead than this (or not a number) is none: 30 days.
_NO_ESTIMATE_BEYOND_S = 30 * 86400.0
#: At most this many legs not yet planned are remembered (then they are found again).
_LEGS_REMEMBERED = 10_000
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
        self._learned_kept: bytes | None = None  # what the data folder holds, as last written
        #: Per order: the plan its times were computed for, the drive, and the times.
        self._plan_times: dict[str, tuple[OrderPlan, Drive, PlanTimes]] = {}
        #: Legs not yet planned, by (start, the stop's node, its station type, drive): driving
        #: seconds and where the leg ends (None: no way), for the graph they were found on.
        self._legs: dict[tuple[str, str | None, str | None, Drive], tuple[float, str] | None] = {}
        self._legs_graph: Graph | None = None

    @property
    def learned_path(self) -> Path:
        """The file in ``data_dir`` that keeps what was learned across restarts."""
        return self.config.data_dir / LEARNED_FILE

    def load_learned(self) -> None:
        """Start from what an earlier run learned (the runtime calls this once at start; a
        file that cannot be used is logged and left alone: everything is learned again)."""
        path = self.learned_path
        try:
            content = path.read_bytes()
            document = orjson.loads(content)
        except FileNotFoundError:
            return
        except (OSError, orjson.JSONDecodeError) as exc:
            log.warning("eta.learned_unreadable", file=str(path), error=str(exc))
            return
        why = self.estimates.restore_learned(document, self.config.time_lapse)
        if why is not None:
            log.warning("eta.learned_not_taken", file=str(path), why=why)
            return
        self._learned_kept = content
        log.info(
            "eta.learned_resumed",
            manufacturers=len(self.estimates.pace),
            dwell_kinds=len(self.estimates.dwell),
        )

    async def keep_learned(self) -> None:
        """Write what has been learned to the data folder when it changed since the last
        write (the document is built here, the file written in a worker thread); a failure is
        logged."""
        estimates = self.estimates
        if not (estimates.pace or estimates.unplanned_pace or estimates.dwell):
            return
        content = orjson.dumps(estimates.learned_document(self.config.time_lapse))
        if content == self._learned_kept:
            return
        path = self.learned_path
        try:
            await asyncio.to_thread(write_atomically, path, content)
        except OSError as exc:
            log.warning("eta.learned_not_kept", file=str(path), error=str(exc))
            return
        self._learned_kept = content

    def drive_of(self, agv: AgvId, vehicle: VehicleView | None = None) -> Drive:
        """How ``agv`` (its view ``vehicle``, when at hand) drives, from its factsheet
        (:data:`DEFAULT_SPEED_MPS` without one)."""
        vehicle = vehicle or self.fleet.get(agv)
        physical = vehicle.factsheet.physical_parameters if vehicle and vehicle.factsheet else None
        lapse = self.config.time_lapse
        if physical is None or physical.speed_max <= 0:
            return Drive(DEFAULT_SPEED_MPS * lapse, None, lapse)
        return Drive(physical.speed_max, physical.angular_speed_max or None, lapse)

    def _times_of(
        self, track: OrderTrack, vehicle: VehicleView | None = None
    ) -> tuple[Drive, PlanTimes]:
        kept = self._plan_times.get(track.order_id)
        drive = self.drive_of(track.plan.agv, vehicle)
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
            leg = self._leg_ahead(plan.nodes[start].node_id, Stop(plan.destination, None), drive)
            return 0.0 if leg is None else leg[0]

        self.estimates.progressed(order_id, progress, last, now, leg_drive_s)
        if self.estimates.waits_for_dwell(order_id, last):
            node = track.plan.nodes[last]
            ids = {action.action_id for action in node.actions}
            ended = {a.action_id for a in state.action_states if a.action_status in _ENDED}
            if ids <= ended:
                self.estimates.dwelt(order_id, node_action_types(node), last, now)

    def expected_finish_utc(self, track: OrderTrack) -> str | None:
        """When the order is expected to finish (UTC, ISO 8601), for an order sent to its
        vehicle and not ended, from that vehicle's latest state; None otherwise."""
        at = self.expected_finish_s(track)
        if at is None:
            return None
        left = at - self.clock.monotonic()
        if not left < _NO_ESTIMATE_BEYOND_S:
            return None  # a speed of almost nothing: no time worth naming (nor a date overflow)
        return format_timestamp(self.clock.now() + timedelta(seconds=left))

    def expected_finish_s(
        self, track: OrderTrack, learned: FinishEstimates | None = None
    ) -> float | None:
        """:meth:`expected_finish_utc` on the monotonic clock; ``learned`` instead of what
        master control has learned (benchmarks compare with nothing learned)."""
        if track.status not in _UNDER_WAY:
            return None
        learned = self.estimates if learned is None else learned
        vehicle = self.fleet.get(track.plan.agv)
        state = vehicle.state if vehicle is not None else None
        drive, times = self._times_of(track, vehicle)
        progress = progress_index(track.plan, state) if state is not None else None
        now = self.clock.monotonic()
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
        :meth:`_leg_ahead` finds it) at the pace of legs not yet planned, and the dwell
        there."""
        seconds = 0.0
        start = track.plan.destination
        manufacturer = track.plan.agv.manufacturer
        pace = learned.pace_of(manufacturer, planned=False)
        for stop in track.onward:
            leg = self._leg_ahead(start, stop, drive)
            if leg is None:
                break  # the order will end there; what follows is not driven
            driving, start = leg
            types = tuple(spec.action_type for spec in stop.actions)
            seconds += driving * pace + learned.dwell_of(manufacturer, types)
        return seconds

    def _leg_ahead(self, start: str, stop: Stop, drive: Drive) -> tuple[float, str] | None:
        """A leg not yet planned, as its estimate takes it (and the pace of such legs is
        measured against it): the driving seconds and the node it ends at, or None when no
        way leads there. To a node, the route traffic control would give a vehicle alone (its
        one-lane costs), else (traffic control off, a station type) the shortest, as the leg
        is planned then. Remembered per graph: an order view costs no route search."""
        if self._legs_graph is not self.graph or len(self._legs) > _LEGS_REMEMBERED:
            self._legs, self._legs_graph = {}, self.graph
        key = (start, stop.destination, stop.station_type, drive)
        if key not in self._legs:
            route: Route | RouteProblem | None = None
            if stop.destination is not None:
                route = self.coordinator.static_route(start, stop.destination)
            route = route or self._leg(start, stop)
            leg = None
            if not isinstance(route, RouteProblem):
                times = leg_times(self.graph, graph_legs(self.graph, route.edge_ids), drive)
                leg = (times.to_node[-1], route.destination)
            self._legs[key] = leg
        return self._legs[key]
