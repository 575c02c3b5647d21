"""Zones added and removed while master control runs (``POST /zones``, ``DELETE /zones/{id}``;
docs/master.md, Zones): a spill closes an aisle now, a speed limit holds while people work.

Mixed into :class:`vda_master.service.MasterService`. A change is written to the store first
(it survives a restart: :meth:`ZoneChanges.restore_zones` applies the stored zones on top of
the graph file before any order is recovered), then master control plans on the graph with the
new set of zones (:meth:`vda_master.graph.Graph.with_zones`): routing, traffic control, the
orders it builds, the zone sets of 3.0 robots and the live map (told to redraw).

Orders already running are looked at again (:mod:`vda_master.graph_change`): one whose way
ahead a BLOCKED zone now closes is re-routed beyond its released base, or cancelled on the
vehicle when that base already leads in, no other way is left or its destination lies inside
(it ends FAILED, saying why); one whose unreleased edges have another speed limit now is
re-planned on the same way. Each is looked at once no order message of it is in flight (one
message per order at a time), at the latest on the next tick; until then nothing more of it is
released.
"""

from __future__ import annotations

import asyncio
from dataclasses import replace
from typing import TYPE_CHECKING

import structlog

from vda5050.clock import Clock
from vda5050.graph_file import GraphZone, GraphZoneType
from vda5050.models import State
from vda5050.topics import AgvId
from vda_master.coordination import Coordinator
from vda_master.dispatcher import OrderTrack
from vda_master.fleet import FleetView
from vda_master.graph import Graph, GraphError
from vda_master.graph_change import closed_way, speed_changed
from vda_master.journal import Journal
from vda_master.live import LiveView
from vda_master.order_builder import BuildProblem, replan
from vda_master.release import progress_index
from vda_master.requests import RequestError
from vda_master.routing import Route
from vda_master.stops import closed_stop
from vda_master.store import ZoneRecord

log = structlog.get_logger()


class ZoneChanges:
    """The zones in force and what a change of them does to the running orders."""

    graph: Graph
    clock: Clock
    fleet: FleetView
    tracks: dict[str, OrderTrack]
    active: dict[AgvId, str]
    coordinator: Coordinator
    journal: Journal | None
    live: LiveView

    if TYPE_CHECKING:

        def _store(self, agv: AgvId, track: OrderTrack) -> None: ...
        def _pump(self, agv: AgvId, now: float) -> None: ...
        def _extended(self, track: OrderTrack, state: State, now: float) -> OrderTrack: ...
        def _around_closed_way(
            self, track: OrderTrack, progress: int, now: float
        ) -> OrderTrack: ...
        def _zones_changed(self, now: float) -> None: ...

    def _init_zone_changes(self) -> None:
        #: One change at a time: each starts from the zones the one before left.
        self._zone_lock = asyncio.Lock()
        #: Orders to look at again after a change, once no message of theirs is in flight
        #: (True: edges of it beyond the released base have another speed limit now).
        self._way_review: dict[str, bool] = {}

    def runtime_zones(self) -> tuple[GraphZone, ...]:
        """The zones added through the API (the graph file's own are not among them)."""
        from_file = self.graph.file_zone_ids
        return tuple(z for z in self.graph.zones if z.zone_id not in from_file)

    async def add_zone(self, zone: GraphZone) -> None:
        """Put ``zone`` in force: 409 for a zoneId in use, 422 for a zone the graph cannot
        take (a map no node lies on, a speed its type needs or forbids)."""
        _check_runtime_type(zone)
        async with self._zone_lock:
            known = next((z for z in self.graph.zones if z.zone_id == zone.zone_id), None)
            if known is not None:
                where = "the graph file" if zone.zone_id in self.graph.file_zone_ids else "force"
                msg = f"zone {zone.zone_id!r} is in {where} already: delete it first"
                raise RequestError(409, msg)
            graph = self._graph_with([*self.graph.zones, zone])
            await self._keep(zone)
            self._change_graph(graph, f"zone {zone.zone_id!r} added")

    async def replace_zone(self, zone: GraphZone) -> None:
        """Change a zone added through the API in one step (a spill that grew): as lifting it
        and adding the new one, without a moment in between where its area is open. 404 for
        an unknown zone, 409 for one of the graph file's, 422 as for a new zone."""
        _check_runtime_type(zone)
        async with self._zone_lock:
            self._check_runtime_zone(zone.zone_id)
            others = [z for z in self.graph.zones if z.zone_id != zone.zone_id]
            graph = self._graph_with([*others, zone])
            await self._keep(zone)
            self._change_graph(graph, f"zone {zone.zone_id!r} changed")

    async def _keep(self, zone: GraphZone) -> None:
        """Store ``zone`` (added or changed) before it acts: it survives a restart."""
        if self.journal is not None:
            document = zone.model_dump(mode="json", by_alias=True, exclude_none=True)
            await self.journal.store.put_zone(ZoneRecord(zone.zone_id, document, self.clock.now()))

    def _graph_with(self, zones: list[GraphZone]) -> Graph:
        """The graph with ``zones`` in force; 422 naming a zone it cannot take."""
        try:
            return self.graph.with_zones(zones)
        except GraphError as exc:
            raise RequestError(422, str(exc)) from None

    def _check_runtime_zone(self, zone_id: str) -> None:
        """404 for an unknown zone, 409 for one of the graph file's."""
        if zone_id in self.graph.file_zone_ids:
            source = self.graph.source
            msg = f"zone {zone_id!r} is defined in the graph file {source}: edit it there"
            raise RequestError(409, msg)
        if all(z.zone_id != zone_id for z in self.graph.zones):
            raise RequestError(404, f"no zone {zone_id!r}")

    async def remove_zone(self, zone_id: str) -> None:
        """Lift a zone added through the API: 404 unknown, 409 one of the graph file's."""
        async with self._zone_lock:
            self._check_runtime_zone(zone_id)
            graph = self.graph.with_zones([z for z in self.graph.zones if z.zone_id != zone_id])
            if self.journal is not None:
                await self.journal.store.delete_zone(zone_id)
            self._change_graph(graph, f"zone {zone_id!r} removed")

    def restore_zones(self, records: tuple[ZoneRecord, ...]) -> None:
        """At start, before orders are recovered: the zones an earlier run added. One that no
        longer fits the graph file (its id taken by the file, its map gone) is left out and
        logged; it stays in the store until deleted through the API."""
        zones = list(self.graph.zones)
        for record in records:
            try:
                zone = GraphZone.model_validate(record.document)
                self.graph.with_zones([*zones, zone])
            except (ValueError, GraphError) as exc:
                log.warning("zones.not_restored", zone_id=record.zone_id, reason=str(exc))
                continue
            zones.append(zone)
        if len(zones) > len(self.graph.zones):
            self._change_graph(self.graph.with_zones(zones), "zones restored from the store")

    # -- the change ------------------------------------------------------------------------------

    def _change_graph(self, graph: Graph, why: str) -> None:
        now = self.clock.monotonic()
        old, self.graph = self.graph, graph
        self.coordinator.set_graph(graph)
        self._zones_changed(now)
        self.live.graph_changed()
        for order_id in self.active.values():
            track = self.tracks[order_id]
            route = track.plan.route
            if route is None:
                continue
            respeed = speed_changed(old, graph, route, track.released_end)
            resume = track.resume
            if (
                respeed
                or closed_way(graph, route) is not None
                or (resume is not None and resume.node_id in graph.blocked_nodes)
                or (track.onward and closed_stop(graph, track.onward, 2) is not None)
            ):
                self._way_review[order_id] = respeed or self._way_review.get(order_id, False)
        log.info(
            "zones.changed",
            why=why,
            zones=[z.zone_id for z in graph.zones],
            closed_edges=len(graph.blocked_edges),
            limited_edges=len(graph.limited_edges),
            orders_to_review=len(self._way_review),
        )
        self.review_ways(now)

    def review_ways(self, now: float) -> None:
        """Look at the orders a change left to review whose messages are all confirmed (the
        tick calls it; O(such orders))."""
        for order_id in list(self._way_review):
            track = self.tracks.get(order_id)
            if track is None or track.terminal or track.cancel_action_id is not None:
                del self._way_review[order_id]
                continue
            if track.recovering_since is not None:
                continue  # its first state settles it (vda_master.persistence)
            if track.pending is not None and not self._base_leads_in(track):
                continue  # re-routed or re-planned once its message is confirmed
            agv = track.plan.agv
            vehicle = self.fleet.get(agv)
            state = None if vehicle is None else vehicle.state
            if state is None or track.pending is not None:
                self._store(agv, self._reviewed_way(track, now))
            else:  # _extended looks at it first, then releases what traffic allows
                self._store(agv, self._extended(track, state, now))
            self._pump(agv, now)

    def _base_leads_in(self, track: OrderTrack) -> bool:
        """Whether the released base of ``track`` takes a way the graph closed: it is stopped
        at once, whatever is in flight."""
        route = track.plan.route
        way = None if route is None else closed_way(self.graph, route, self._progress(track))
        return way is not None and way.index < track.released_end

    def _progress(self, track: OrderTrack) -> int:
        vehicle = self.fleet.get(track.plan.agv)
        state = None if vehicle is None else vehicle.state
        return (progress_index(track.plan, state) if state is not None else None) or 0

    def _reviewed_way(self, track: OrderTrack, now: float) -> OrderTrack:
        """``track`` after a change of zones: re-routed, being cancelled, re-planned with the
        new speeds, or as it was (its way is open and as fast as before)."""
        respeed = self._way_review.pop(track.order_id, False)
        route = track.plan.route
        if route is None:
            return track
        progress = self._progress(track)
        changed = self._around_closed_way(track, progress, now)
        if (
            changed is not track
            or not respeed
            or closed_way(self.graph, route, progress) is not None
        ):
            return changed
        return self._respeeded(track, route)

    def _respeeded(self, track: OrderTrack, route: Route) -> OrderTrack:
        """The unreleased part re-built on the same way: its edges take the new maxSpeed."""
        start = track.released_end
        if start >= len(route.edge_ids):
            return track
        tail = Route(
            route.node_ids[start:],
            route.edge_ids[start:],
            sum(self.graph.edge_length(e) for e in route.edge_ids[start:]),
        )
        vehicle = self.fleet.get(track.plan.agv)
        plan = replan(
            self.graph,
            track.plan,
            from_index=start,
            tail=tail,
            factsheet=None if vehicle is None else vehicle.factsheet,
            last_actions=tuple(track.plan.nodes[-1].actions),
        )
        if isinstance(plan, BuildProblem):
            log.warning("zones.replan_failed", order_id=track.order_id, reason=plan.reason)
            return track
        log.info("zones.order_respeeded", order_id=track.order_id, agv=str(track.plan.agv))
        return replace(track, plan=plan)


def _check_runtime_type(zone: GraphZone) -> None:
    """422 for a RELEASE zone: it is part of traffic control's conflict sets, which are the
    floor's geometry and computed once per graph file (docs/traffic.md, Release zones)."""
    if zone.zone_type is GraphZoneType.RELEASE:
        msg = (
            f"zone {zone.zone_id!r}: a RELEASE zone is part of traffic control's geometry and "
            "comes from the graph file only; add it there and restart master control"
        )
        raise RequestError(422, msg)
