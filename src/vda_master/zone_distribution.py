"""Giving 3.0 robots the graph file's zone sets (the shell of :mod:`vda_master.zone_sets`).

Mixed into :class:`vda_master.service.MasterService`: a 3.0 factsheet says which zone types a
robot supports, each 3.0 state which zone sets it holds; after each state the next step of
:func:`vda_master.zone_sets.next_step` is carried out: the zone set published on ``zoneSet``,
or ``enableZoneSet``/``deleteZoneSet`` sent as instant actions (only while the robot takes
instant actions: ONLINE, AUTOMATIC or SEMIAUTOMATIC, 3.0 Table 11). Logged as
``zones.zone_set_sent``, ``zones.zone_set_enabling``, ``zones.zone_set_deleting``; a robot that
lacks a zone type of a set is logged once (``zones.not_supported``) and gets the part it
supports (:meth:`ZoneDistribution.zone_sets_for`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar

import structlog

from vda5050.clock import Clock
from vda5050.codec import HeaderStamper, encode
from vda5050.models import (
    Action,
    ActionParameter,
    BlockingType,
    ConnectionState,
    InstantActions,
    Order,
    v3,
)
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.config import MasterConfig, interface_name
from vda_master.fleet import CONTROLLABLE_MODES, FleetView
from vda_master.graph import Graph
from vda_master.journal import Journal
from vda_master.requests import instant_actions_message
from vda_master.zone_sets import (
    DeleteZoneSet,
    EnableZoneSet,
    SendZoneSet,
    Step,
    maps_without_set,
    next_step,
    stale_enabled,
    step_key,
    types_of,
    zone_sets_of,
)

if TYPE_CHECKING:
    from vda_master.service import Publisher

log = structlog.get_logger()

#: A message of a topic 3.0 added.
_V3Only = TypeVar("_V3Only", v3.ZoneSetMessage, v3.Responses)


class ZoneDistribution:
    """The zone sets of the graph, and what each 3.0 robot holds of them."""

    config: MasterConfig
    graph: Graph
    clock: Clock
    fleet: FleetView
    publisher: Publisher
    journal: Journal | None

    if TYPE_CHECKING:

        def _stamper(self, agv: AgvId) -> HeaderStamper: ...
        def _publish(self, agv: AgvId, message: Order | InstantActions, now: float) -> None: ...
        def _new_id(self) -> str: ...

    def _init_zone_distribution(self) -> None:
        #: The graph's zones as 3.0 zone sets, by mapId.
        self.zone_sets = zone_sets_of(self.graph)
        #: Every zone set this master made in this run, by id (what an older one blocked).
        self._zone_sets_made = {z.zone_set_id: z for z in self.zone_sets.values()}
        self._zone_support: dict[AgvId, frozenset[v3.ZoneType]] = {}
        self._zone_sets_held: dict[AgvId, tuple[v3.StoredZoneSet, ...]] = {}
        self._zone_asks: dict[AgvId, dict[str, float]] = {}
        self._zone_refusals: set[tuple[AgvId, str]] = set()
        #: Robots that still have an older zone set of ours ENABLED -> its id (zone_set_lag).
        self._zone_lag: dict[AgvId, str] = {}
        #: The part of the zone sets a robot that lacks some of their types is given, by the
        #: types it supports (cleared whenever the zones change).
        self._partial_sets: dict[frozenset[v3.ZoneType], dict[str, v3.ZoneSet]] = {}

    def _zones_changed(self, now: float) -> None:
        """The graph's zones changed (:mod:`vda_master.zone_changes`): new zone sets, given to
        every robot now (a map whose zones are all gone gets an empty one)."""
        self.zone_sets = zone_sets_of(self.graph, self.zone_sets.keys())
        self._zone_sets_made.update((z.zone_set_id, z) for z in self.zone_sets.values())
        self._partial_sets.clear()
        for agv in self.zone_robots():
            self._note_zone_lag(agv)
            self._distribute_zones(agv, now)

    def note_zone_support(self, agv: AgvId, factsheet: v3.Factsheet) -> None:
        """A 3.0 factsheet: the zone types the robot supports (``supportedZones``)."""
        self._zone_support[agv] = frozenset(factsheet.type_specification.supported_zones or ())

    def note_zone_sets(self, agv: AgvId, state: v3.State, now: float) -> None:
        """A 3.0 state: the zone sets the robot holds; then the next step for each of ours. A
        set of ours for a map that has no zones now (edited out of the graph file before a
        restart) is replaced by an empty one, as when the last zone is lifted at run time."""
        held = tuple(state.zone_sets or ())
        self._zone_sets_held[agv] = held
        if held and self._zone_support.get(agv):
            gone = maps_without_set(self.zone_sets, held)
            if gone:  # only maps of this graph: another master's floor is not ours to clear
                gone &= {self.graph.node_map_id(node) for node in self.graph.nodes.values()}
            if gone:
                self.zone_sets = zone_sets_of(self.graph, (*self.zone_sets, *gone))
                self._zone_sets_made.update((z.zone_set_id, z) for z in self.zone_sets.values())
                self._partial_sets.clear()
        if self.zone_sets:
            self._note_zone_lag(agv)
            self._distribute_zones(agv, now)

    def zone_set_lag(self, agv: AgvId) -> str | None:
        """Why ``agv`` takes no new order yet: it still keeps to an older zone set of ours (a
        zone lifted since may still be BLOCKED to it, and it would refuse the order); None
        otherwise. It enables the current set within a state or two (:func:`next_step`)."""
        stale = self._zone_lag.get(agv)
        if stale is None:
            return None
        return (
            f"it still keeps to zone set {stale!r}: the zones changed and it has not enabled "
            "the new set yet"
        )

    def _note_zone_lag(self, agv: AgvId) -> None:
        supported = self._zone_support.get(agv)
        held = self._zone_sets_held.get(agv, ())
        sets = self.zone_sets_for(agv)
        stale = stale_enabled(sets, held, self._zone_sets_made) if supported else None
        if stale is None:
            self._zone_lag.pop(agv, None)
        else:
            self._zone_lag[agv] = stale

    def zone_sets_for(self, agv: AgvId) -> dict[str, v3.ZoneSet]:
        """The zone sets ``agv`` is given, by mapId: ours, or the part of them of the zone
        types it supports (empty for a robot that supports none)."""
        supported = self._zone_support.get(agv) or frozenset()
        if not supported:
            return {}
        if all(types_of(zone_set) <= supported for zone_set in self.zone_sets.values()):
            return self.zone_sets
        partial = self._partial_sets.get(supported)
        if partial is None:
            partial = zone_sets_of(self.graph, self.zone_sets.keys(), types=supported)
            self._zone_sets_made.update((z.zone_set_id, z) for z in partial.values())
            self._partial_sets[supported] = partial
        return partial

    def zone_set_status(
        self, agv: AgvId, zone_set_id: str, zone_type: v3.ZoneType | None = None
    ) -> str | None:
        """How far ``agv`` has got with one of our zone sets (its own part of it, if it lacks
        some of the types): ENABLED, DISABLED, SENT, or UNSUPPORTED for a zone of
        ``zone_type`` it does not support (None: a robot that is not given zone sets at all)."""
        supported = self._zone_support.get(agv)
        zone_set = next((z for z in self.zone_sets.values() if z.zone_set_id == zone_set_id), None)
        if not supported or zone_set is None:
            return None
        if zone_type is not None and zone_type not in supported:
            return "UNSUPPORTED"
        zone_set = self.zone_sets_for(agv).get(zone_set.map_id, zone_set)
        zone_set_id = zone_set.zone_set_id
        for held in self._zone_sets_held.get(agv, ()):
            if held.zone_set_id == zone_set_id:
                return held.zone_set_status.value
        sent = step_key(SendZoneSet(zone_set)) in self._zone_asks.get(agv, {})
        return "SENT" if sent else None

    def zone_robots(self) -> tuple[AgvId, ...]:
        """The robots that are given zone sets (their factsheet lists zone types)."""
        return tuple(agv for agv, supported in self._zone_support.items() if supported)

    def _distribute_zones(self, agv: AgvId, now: float) -> None:
        supported = self._zone_support.get(agv)
        vehicle = self.fleet.get(agv)
        if not supported or vehicle is None or vehicle.connection != ConnectionState.ONLINE:
            return
        takes_actions = (
            vehicle.state is not None and vehicle.state.operating_mode in CONTROLLABLE_MODES
        )
        asks = self._zone_asks.setdefault(agv, {})
        for map_id, zone_set in self.zone_sets_for(agv).items():
            missing = types_of(self.zone_sets[map_id]) - supported
            if missing:
                self._not_supported(agv, zone_set, missing)
            held = self._zone_sets_held.get(agv, ())
            step = next_step(zone_set, held, asks, now, takes_instant_actions=takes_actions)
            if step is None:
                continue
            self._carry_out_zone_step(agv, step, now)
            asks[step_key(step)] = now

    def _not_supported(
        self, agv: AgvId, zone_set: v3.ZoneSet, missing: frozenset[v3.ZoneType]
    ) -> None:
        key = (agv, zone_set.zone_set_id)
        if key in self._zone_refusals:
            return
        self._zone_refusals.add(key)
        log.info(
            "zones.not_supported",
            agv=str(agv),
            zone_set_id=zone_set.zone_set_id,
            missing=sorted(t.value for t in missing),
        )

    def _carry_out_zone_step(self, agv: AgvId, step: Step, now: float) -> None:
        if isinstance(step, SendZoneSet):
            self._publish_zone_set(agv, step.zone_set)
            return
        enable = isinstance(step, EnableZoneSet)
        assert enable or isinstance(step, DeleteZoneSet)  # noqa: S101 - the three steps
        action = Action(
            action_type="enableZoneSet" if enable else "deleteZoneSet",
            action_id=self._new_id(),
            blocking_type=BlockingType.NONE,
            action_parameters=[ActionParameter(key="zoneSetId", value=step.zone_set_id)],
        )
        self._publish(agv, instant_actions_message(agv, [action]), now)
        event = "zones.zone_set_enabling" if enable else "zones.zone_set_deleting"
        log.info(event, agv=str(agv), zone_set_id=step.zone_set_id, action_id=action.action_id)

    def _publish_zone_set(self, agv: AgvId, zone_set: v3.ZoneSet) -> None:
        """§7.6: the zone set on ``zoneSet`` (QoS 0), stamped like every message to ``agv``."""
        message = self._publish_v3_only(agv, Topic.ZONE_SET, v3.ZoneSetMessage, zone_set=zone_set)
        if message is None:
            return
        log.info(
            "zones.zone_set_sent",
            agv=str(agv),
            zone_set_id=zone_set.zone_set_id,
            zones=len(zone_set.zones),
            header_id=message.header_id,
        )

    def _publish_v3_only(
        self, agv: AgvId, kind: Topic, model: type[_V3Only], **content: object
    ) -> _V3Only | None:
        """A message of a topic 3.0 added (``zoneSet``, ``responses``; T02) with ``content``,
        stamped like every message to ``agv`` and published (QoS 0); None for a robot that does
        not speak 3.0."""
        stamper = self._stamper(agv)
        if stamper.major != 3:  # noqa: PLR2004 - these topics exist from 3.0 on
            return None
        unstamped = model.model_validate(
            {
                "header_id": 0,
                "timestamp": "1970-01-01T00:00:00.000Z",
                "version": stamper.version,
                "manufacturer": agv.manufacturer,
                "serial_number": agv.serial_number,
                **content,
            }
        )
        message = stamper.stamp(kind, unstamped)
        topic = build_topic(interface_name(self.config, stamper.major), stamper.major, agv, kind)
        self.publisher.publish(topic, kind, encode(message))
        if self.journal is not None:
            self.journal.published(agv, kind, message.header_id, None)
        return message
