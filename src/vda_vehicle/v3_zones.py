"""Zone sets of the 3.0 vehicle, pure (3.0 §6.4, §7.6; rules T82-T91 of docs/vda5050-3.md).

The simulated vehicle honours three zone types, the ones it can keep without perceiving
anything: BLOCKED (never entered: an order that would drive into or through an enabled BLOCKED
zone is refused with NO_ROUTE_TO_TARGET; an edge from inside to outside leaves it and is
driven), SPEED_LIMIT (every edge that touches an enabled zone is driven at most at the
zone's ``maximumSpeed``, so the limit is met on entry; overlapping limits take the lowest,
T89) and RELEASE (entered only with fleet control's grant of a zone request:
:mod:`vda_vehicle.v3_requests`). A zone set arrives on ``zoneSet`` DISABLED; ``enableZoneSet``
enables it and disables the other sets of its map; ``deleteZoneSet`` removes it (T87,
§6.2.3.1).

Geometry is in map coordinates: an edge is the straight segment between its nodes (the
simulated stack is VIRTUAL_LINE_GUIDED), or its trajectory's polyline, and it touches a zone
when it crosses the polygon's border or lies inside it. RELEASE zones are contour-based
(§6.4.1.1): the vehicle's body counts, taken as the circle round its footprint (the
``reach``, half the footprint's diagonal), so a way enters such a zone when it passes within
``reach`` of the polygon.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final

from vda5050.models import v3
from vda5050.models.v3.state import StoredZoneSet, ZoneSetStatus
from vda5050.polygons import Point, inside, near, point_near, touches

#: The zone types this vehicle honours (T82: exactly these are in ``supportedZones``).
SUPPORTED_ZONES: Final = frozenset(
    {v3.ZoneType.BLOCKED, v3.ZoneType.SPEED_LIMIT, v3.ZoneType.RELEASE}
)
#: Table 6: a RELEASE zone without ``releaseLossBehavior`` means STOP.
DEFAULT_RELEASE_LOSS: Final = v3.ZoneReleaseLossBehavior.STOP


@dataclass(frozen=True, slots=True)
class HeldZoneSet:
    """A zone set the vehicle holds, and whether it is in use."""

    zone_set: v3.ZoneSet
    enabled: bool = False


ZoneSets = tuple[HeldZoneSet, ...]


def receive_zone_set(held: ZoneSets, message: v3.ZoneSetMessage) -> tuple[ZoneSets, list[v3.Error]]:
    """T87, T88: store a new zone set DISABLED, or say why not: a zoneSetId already held is
    DUPLICATE_ZONE_SET; a zone type outside :data:`SUPPORTED_ZONES` is UNSUPPORTED_PARAMETER
    (CRITICAL) naming the zone. Nothing of a refused zone set is kept."""
    zone_set = message.zone_set
    refs = (("topic", "zoneSet"), ("headerId", str(message.header_id)))
    if any(h.zone_set.zone_set_id == zone_set.zone_set_id for h in held):
        return held, [
            v3.predefined_error(
                v3.ErrorType.DUPLICATE_ZONE_SET,
                *refs,
                ("zoneSetId", zone_set.zone_set_id),
                description=f"zone set {zone_set.zone_set_id!r} is already held",
            )
        ]
    unsupported = [
        v3.predefined_error(
            v3.ErrorType.UNSUPPORTED_PARAMETER,
            *refs,
            ("zoneSetId", zone_set.zone_set_id),
            ("zoneId", zone.zone_id),
            ("zoneType", zone.zone_type.value),
            description=f"zone type {zone.zone_type.value} is not supported by this vehicle",
        )
        for zone in zone_set.zones
        if zone.zone_type not in SUPPORTED_ZONES
    ]
    if unsupported:
        return held, unsupported
    return (*held, HeldZoneSet(zone_set)), []


def enable_zone_set(held: ZoneSets, zone_set_id: str) -> ZoneSets | None:
    """``enableZoneSet``: this set ENABLED, the other sets of its map DISABLED; None if the
    vehicle does not hold it."""
    target = next((h for h in held if h.zone_set.zone_set_id == zone_set_id), None)
    if target is None:
        return None
    map_id = target.zone_set.map_id
    return tuple(
        HeldZoneSet(h.zone_set, enabled=h is target) if h.zone_set.map_id == map_id else h
        for h in held
    )


def delete_zone_set(held: ZoneSets, zone_set_id: str) -> ZoneSets | None:
    """``deleteZoneSet``: the set is gone; None if the vehicle does not hold it."""
    kept = tuple(h for h in held if h.zone_set.zone_set_id != zone_set_id)
    return None if len(kept) == len(held) else kept


def reported(held: ZoneSets) -> list[StoredZoneSet]:
    """``state.zoneSets``."""
    return [
        StoredZoneSet(
            zone_set_id=h.zone_set.zone_set_id,
            map_id=h.zone_set.map_id,
            zone_set_status=ZoneSetStatus.ENABLED if h.enabled else ZoneSetStatus.DISABLED,
        )
        for h in held
    ]


def _enabled_zones(held: ZoneSets, map_id: str, zone_type: v3.ZoneType) -> Iterable[v3.Zone]:
    for h in held:
        if h.enabled and h.zone_set.map_id == map_id:
            yield from (z for z in h.zone_set.zones if z.zone_type is zone_type)


def blocked_zone(held: ZoneSets, map_id: str, path: Sequence[Point]) -> v3.Zone | None:
    """The enabled BLOCKED zone the way along ``path`` (an edge's points, start to end: its
    trajectory's polyline, or the two ends) enters, if any (T89): it touches the zone and does
    not leave it. A way from inside to outside leaves it: a robot that stands in a zone enabled
    around it may drive out (the rule master control routes by)."""
    for zone in _enabled_zones(held, map_id, v3.ZoneType.BLOCKED):
        leaves = inside(zone.vertices, path[0]) and not inside(zone.vertices, path[-1])
        if not leaves and _touches(zone, path):
            return zone
    return None


def speed_limit(held: ZoneSets, map_id: str, path: Sequence[Point]) -> float | None:
    """The lowest ``maximumSpeed`` of the enabled SPEED_LIMIT zones the way along ``path``
    touches (T89)."""
    limits = [
        zone.maximum_speed
        for zone in _enabled_zones(held, map_id, v3.ZoneType.SPEED_LIMIT)
        if zone.maximum_speed is not None and _touches(zone, path)
    ]
    return min(limits) if limits else None


def _touches(zone: v3.Zone, path: Sequence[Point]) -> bool:
    return any(touches(zone.vertices, a, b) for a, b in itertools.pairwise(path))


# -- RELEASE zones (§6.4.1.1, §6.4.3) --------------------------------------------------------------

#: A RELEASE zone's identity: (zoneSetId, zoneId); a zoneId is unique only within its set.
ZoneKey = tuple[str, str]


@dataclass(frozen=True, slots=True)
class ReleaseZone:
    """A RELEASE zone of an enabled zone set, with what the vehicle needs to ask for it."""

    zone_set_id: str
    map_id: str
    zone: v3.Zone

    @property
    def key(self) -> ZoneKey:
        return (self.zone_set_id, self.zone.zone_id)

    @property
    def loss(self) -> v3.ZoneReleaseLossBehavior:
        """What to do when the release is lost inside the zone (Table 6; absent: STOP)."""
        return self.zone.release_loss_behavior or DEFAULT_RELEASE_LOSS

    def reached(self, path: Sequence[Point], reach: float) -> bool:
        """The body, ``reach`` round its reference point, touches the zone somewhere along
        ``path`` (§6.4.1.1: any part of the contour inside is an entry)."""
        vertices = self.zone.vertices
        if len(path) == 1:
            return point_near(vertices, path[0], reach)
        return any(near(vertices, a, b, reach) for a, b in itertools.pairwise(path))

    def holds(self, map_id: str, point: Point, reach: float) -> bool:
        """Some part of the body standing at ``point`` on ``map_id`` is inside the zone."""
        return map_id == self.map_id and point_near(self.zone.vertices, point, reach)


def release_zones(held: ZoneSets) -> tuple[ReleaseZone, ...]:
    """The RELEASE zones of the enabled zone sets: only these are asked for (§6.4.3, T91)."""
    return tuple(
        ReleaseZone(h.zone_set.zone_set_id, h.zone_set.map_id, zone)
        for h in held
        if h.enabled
        for zone in h.zone_set.zones
        if zone.zone_type is v3.ZoneType.RELEASE
    )


def release_loss_defaulted(payload: bytes) -> tuple[bytes, tuple[str, ...]]:
    """A zoneSet payload whose RELEASE zones without ``releaseLossBehavior`` get STOP, and the
    ids of those zones. §7.6 and the official schema require the field, but Table 6 says a
    zone without it means STOP, so the vehicle takes such a zone set (and logs it) rather than
    refuse it. Anything that is not such a zone set comes back unchanged."""
    if b"RELEASE" not in payload:
        return payload, ()
    try:
        message = json.loads(payload)
    except ValueError:
        return payload, ()
    zone_set = message.get("zoneSet") if isinstance(message, dict) else None
    zones = zone_set.get("zones") if isinstance(zone_set, dict) else None
    if not isinstance(zones, list):
        return payload, ()
    defaulted: list[str] = []
    for zone in zones:
        if (
            isinstance(zone, dict)
            and zone.get("zoneType") == v3.ZoneType.RELEASE.value
            and "releaseLossBehavior" not in zone
        ):
            zone["releaseLossBehavior"] = DEFAULT_RELEASE_LOSS.value
            defaulted.append(str(zone.get("zoneId")))
    if not defaulted:
        return payload, ()
    return json.dumps(message, ensure_ascii=False).encode(), tuple(defaulted)
