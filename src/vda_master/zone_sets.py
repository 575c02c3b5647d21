"""The graph's zones (the file's and those added through the API) as VDA 5050 3.0 zone sets for
the robots that understand them (pure; 3.0 §6.4.2, §7.6; docs/master.md, Zones).

Master control honours its zones for every vehicle through what it routes and sends; a 3.0
robot that lists the zone types in its factsheet (``supportedZones``) is also given them, so it
knows the areas itself (a BLOCKED zone it never enters, a SPEED_LIMIT it keeps on its own):

- The zones of one map form one zone set, each zone's vertices counterclockwise (T85). Its
  ``zoneSetId`` is ``<mapId>.zones.<digest>``, the digest a hash of the zones' content: a zone
  set never changes under the same id (§6.4.2), and an edited graph file or a zone added or
  lifted through the API gives a new id, which replaces the old set on the robot.
- Per robot and map, the robot's own ``state.zoneSets`` says what to do next
  (:func:`next_step`): a set it does not hold is sent on ``zoneSet`` (QoS 0, so again after
  :data:`RESEND_AFTER_S` while it does not show up); one it holds DISABLED is enabled with the
  instant action ``enableZoneSet`` (which disables the map's other sets on the robot); once it
  is ENABLED, an older set of this master for that map is deleted (``deleteZoneSet``). Zone
  sets of others are left alone.
- A robot that does not support every type in the set gets the part it supports, a set of its
  own (a robot refuses a set with a type it does not know, UNSUPPORTED_PARAMETER): the orders
  keep it to the other zones anyway (a RELEASE zone is held for it by traffic control).
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Final

import orjson

from vda5050.models import v3
from vda5050.models.v3.state import StoredZoneSet, ZoneSetStatus
from vda5050.polygons import counterclockwise
from vda_master.graph import Graph

#: A zone set sent, or an enableZoneSet asked for, that the robot's states do not show yet is
#: sent again after this long (seconds; both go QoS 0).
RESEND_AFTER_S: Final = 5.0
#: What every zoneSetId of this master has after the map's id (older sets are recognised by it).
_ID_MARK: Final = ".zones."


def zone_sets_of(
    graph: Graph, maps: Iterable[str] = (), types: frozenset[v3.ZoneType] | None = None
) -> dict[str, v3.ZoneSet]:
    """The graph's zones as one zone set per map, by mapId (none without zones); each of
    ``maps`` that has none gets an empty set (its last zone was removed: the empty set replaces
    the old one on the robots, §6.4.2 allows a set without zones). With ``types``, only the
    zones of those types (the part a robot supports), each of the graph's maps with a set."""
    by_map: dict[str, list[v3.Zone]] = {map_id: [] for map_id in maps}
    for zone in graph.zones:
        zone_type = v3.ZoneType(zone.zone_type.value)
        zones = by_map.setdefault(zone.map_id or graph.map_id, [])
        if types is not None and zone_type not in types:
            continue
        release = zone_type is v3.ZoneType.RELEASE
        loss = zone.release_loss_behavior.value if zone.release_loss_behavior else "STOP"
        zones.append(
            v3.Zone(
                zone_id=zone.zone_id,
                zone_type=zone_type,
                zone_descriptor=zone.description,
                vertices=[v3.Vertex(x=v.x, y=v.y) for v in counterclockwise(zone.vertices)],
                maximum_speed=zone.maximum_speed,
                # Table 6: absent means STOP; §7.6 requires it, so it is always sent
                release_loss_behavior=v3.ZoneReleaseLossBehavior(loss) if release else None,
            )
        )
    sets = {}
    for map_id, zones in by_map.items():
        body = orjson.dumps([z.model_dump(mode="json", exclude_none=True) for z in zones])
        digest = hashlib.sha256(body).hexdigest()[:12]
        sets[map_id] = v3.ZoneSet(
            map_id=map_id,
            zone_set_id=f"{map_id}{_ID_MARK}{digest}",
            zone_set_descriptor=f"zones of master control ({len(zones)})",
            zones=zones,
        )
    return sets


def types_of(zone_set: v3.ZoneSet) -> frozenset[v3.ZoneType]:
    return frozenset(zone.zone_type for zone in zone_set.zones)


@dataclass(frozen=True, slots=True)
class SendZoneSet:
    zone_set: v3.ZoneSet


@dataclass(frozen=True, slots=True)
class EnableZoneSet:
    zone_set_id: str


@dataclass(frozen=True, slots=True)
class DeleteZoneSet:
    zone_set_id: str


Step = SendZoneSet | EnableZoneSet | DeleteZoneSet


def next_step(
    zone_set: v3.ZoneSet,
    held: Iterable[StoredZoneSet],
    asked_at: Mapping[str, float],
    now: float,
    *,
    takes_instant_actions: bool = True,
) -> Step | None:
    """What to do next for ``zone_set`` on a robot that holds ``held`` (its last state); a step
    already asked for (``asked_at``: step key → when) waits :data:`RESEND_AFTER_S`. Enabling
    and deleting are instant actions: only while the robot takes them (3.0 Table 11, T58)."""
    ours = zone_set.zone_set_id
    on_map = [h for h in held if h.map_id == zone_set.map_id]
    status = next((h.zone_set_status for h in on_map if h.zone_set_id == ours), None)
    step: Step | None
    if status is None:
        step = SendZoneSet(zone_set)
    elif status is ZoneSetStatus.DISABLED:
        step = EnableZoneSet(ours)
    else:
        stale = [
            h.zone_set_id
            for h in on_map
            if h.zone_set_id != ours
            and made_here(h)  # on_map: h.map_id is the set's
            and h.zone_set_status is ZoneSetStatus.DISABLED
        ]
        step = DeleteZoneSet(stale[0]) if stale else None
    if step is None or (not isinstance(step, SendZoneSet) and not takes_instant_actions):
        return None
    last = asked_at.get(step_key(step))
    return step if last is None or now - last >= RESEND_AFTER_S else None


def made_here(held: StoredZoneSet) -> bool:
    """Whether a zone set the robot holds is one of this master's (its id has our mark)."""
    return held.zone_set_id.startswith(held.map_id + _ID_MARK)


def maps_without_set(
    zone_sets: Mapping[str, v3.ZoneSet], held: Iterable[StoredZoneSet]
) -> frozenset[str]:
    """Maps for which the robot holds a zone set of this master but the graph has none now."""
    return frozenset(h.map_id for h in held if h.map_id not in zone_sets and made_here(h))


def stale_enabled(
    zone_sets: Mapping[str, v3.ZoneSet],
    held: Iterable[StoredZoneSet],
    known: Mapping[str, v3.ZoneSet],
) -> str | None:
    """An older zone set of this master that the robot still has ENABLED and that blocks more
    than the current one of its map (a BLOCKED zone lifted or changed since; ``known``: the
    sets this master made, by id; one it does not know counts as blocking more). The robot
    would refuse an order through such a zone. None if there is none."""
    for h in held:
        current = zone_sets.get(h.map_id)
        if (
            current is not None
            and h.zone_set_status is ZoneSetStatus.ENABLED
            and h.zone_set_id != current.zone_set_id
            and made_here(h)
            and _blocks_more(known.get(h.zone_set_id), current)
        ):
            return h.zone_set_id
    return None


def _blocks_more(older: v3.ZoneSet | None, current: v3.ZoneSet) -> bool:
    if older is None:
        return True
    blocked = v3.ZoneType.BLOCKED
    now = [z for z in current.zones if z.zone_type is blocked]
    return any(z not in now for z in older.zones if z.zone_type is blocked)


def step_key(step: Step) -> str:
    """What :func:`next_step`'s ``asked_at`` is keyed by."""
    if isinstance(step, SendZoneSet):
        return f"send {step.zone_set.zone_set_id}"
    kind = "enable" if isinstance(step, EnableZoneSet) else "delete"
    return f"{kind} {step.zone_set_id}"
