"""Zone requests and their answers as a listener sees them (3.0 §6.4.3, §6.9, §7.5; rules T91,
T92 of docs/vda5050-3.md), pure.

From the ``zoneSet`` messages master control sends, the robot's states (which sets it holds
ENABLED, its ``zoneRequests``, its position) and the ``responses``:

- **T92** (master control): every response answers a request the robot's latest state holds;
  ``leaseExpiry`` comes only with GRANTED; a request the robot keeps stating (REQUESTED) gets an
  answer within ``within_s``.
- **T91** (robot): the robot enters a RELEASE zone of an ENABLED zone set only with a GRANTED
  request for it. A listener knows the reference point, not the contour: entry is judged when
  the position crosses into the polygon (lenient: a contour enters earlier), and a robot first
  seen inside is not judged. Inside, losing the grant (REVOKED, EXPIRED) is the zone's
  ``releaseLossBehavior``, not a violation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from vda5050.models import v3
from vda5050.models.v3.state import RequestStatus, ZoneRequestType, ZoneSetStatus
from vda5050.polygons import inside

#: (rule, text)
Problem = tuple[str, str]


@dataclass
class ZoneRequestWatch:
    """One robot's zone sets, requests and whereabouts."""

    within_s: float
    #: zoneSetId -> the zone set master control sent
    sets: dict[str, v3.ZoneSet] = field(default_factory=dict)
    #: requestId -> when first seen REQUESTED, while no response has named it
    open: dict[str, float] = field(default_factory=dict)
    #: the requestIds some response has named (a robot keeps a QUEUED request REQUESTED)
    answered: set[str] = field(default_factory=set)
    #: the requestIds of the robot's latest state
    live: frozenset[str] = frozenset()
    #: (zoneSetId, zoneId) of the RELEASE zones its position was inside at the last state
    inside: frozenset[tuple[str, str]] | None = None

    def zone_set(self, message: v3.ZoneSetMessage) -> None:
        self.sets[message.zone_set.zone_set_id] = message.zone_set

    def responses(self, message: v3.Responses) -> list[Problem]:
        """T92: what master control answered."""
        problems = []
        for response in message.responses:
            rid = response.request_id
            if rid not in self.live:
                text = f"a response to request {rid!r}, which the robot's latest state lacks"
                problems.append(("T92", text))
            if (
                response.lease_expiry is not None
                and response.grant_type is not v3.GrantType.GRANTED
            ):
                problems.append(
                    ("T92", f"leaseExpiry with {response.grant_type.value} for request {rid!r}")
                )
            self.open.pop(rid, None)
            self.answered.add(rid)
        return problems

    def state(self, state: v3.State, now: float) -> list[Problem]:
        """T91 by the robot's position; the requests still to be answered (T92)."""
        requests = state.zone_requests or []
        self.live = frozenset(r.request_id for r in (*requests, *(state.edge_requests or ())))
        self.open = {rid: since for rid, since in self.open.items() if rid in self.live}
        self.answered &= self.live
        for request in (*requests, *(state.edge_requests or ())):
            rid = request.request_id
            if request.request_status is RequestStatus.REQUESTED and rid not in self.answered:
                self.open.setdefault(rid, now)
        position = state.mobile_robot_position
        if position is None or not position.localized:
            return []
        now_inside = frozenset(self._release_zones_at(state, (position.x, position.y)))
        before, self.inside = self.inside, now_inside
        if before is None:
            return []  # first seen: not judged
        granted = {
            (r.zone_set_id, r.zone_id)
            for r in requests
            if r.request_type is ZoneRequestType.ACCESS
            and r.request_status is RequestStatus.GRANTED
        }
        entered = sorted(now_inside - before - granted)
        return [
            (
                "T91",
                f"entered RELEASE zone {zone!r} (zone set {set_id!r}) without a GRANTED request",
            )
            for set_id, zone in entered
        ]

    def overdue(self, now: float) -> list[Problem]:
        """T92: requests stated for longer than ``within_s`` with no response (once each)."""
        late = [rid for rid, since in self.open.items() if now - since > self.within_s]
        for rid in late:
            del self.open[rid]
            self.answered.add(rid)  # reported once
        return [
            ("T92", f"no response to request {rid!r} within {self.within_s:g} s") for rid in late
        ]

    def _release_zones_at(
        self, state: v3.State, point: tuple[float, float]
    ) -> list[tuple[str, str]]:
        enabled = {
            held.zone_set_id
            for held in state.zone_sets or ()
            if held.zone_set_status is ZoneSetStatus.ENABLED
        }
        return [
            (set_id, zone.zone_id)
            for set_id in enabled
            if (zone_set := self.sets.get(set_id)) is not None
            for zone in zone_set.zones
            if zone.zone_type is v3.ZoneType.RELEASE and inside(zone.vertices, point)
        ]
