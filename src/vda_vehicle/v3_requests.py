"""Zone requests of the 3.0 vehicle for RELEASE zones, pure (3.0 §6.4.3, §6.9, Figure 16;
rules T91 and T93 of docs/vda5050-3.md).

The shell (:class:`vda_vehicle.runtime3.VehicleRuntimeV3`) tells this module, at every full
tick and after every message that can change them, which RELEASE zones the edges of the
released base ahead reach into (:class:`EdgeZones`, in driving order), which zones of its
requests the body is inside now, and the time; it gets back the requests to report in
``state.zoneRequests``, the first edge it may not start yet (:func:`first_closed`) and the
errors a lost release raises (:func:`loss_errors`). No clock is read here.

The lifecycle of one request (an ACCESS request names one zone; ``requestId`` ``zr-<n>``,
counted per vehicle run, so never reused while the vehicle runs, §6.4.3):

- **asked** (REQUESTED) as soon as an edge of the released base ahead reaches into an enabled
  RELEASE zone the vehicle holds no request for: an order, an order update or an enabled zone
  set brings the request at once, so a prompt grant lets the vehicle drive on without
  stopping. It never starts such an edge before every zone the edge reaches is GRANTED
  (§6.4.3: all zones of an area); it stops at the edge's start node and waits.
- **GRANTED** by a response; its ``leaseExpiry`` is kept, and a later GRANTED replaces it
  (extends the lease, §6.9). **QUEUED** changes nothing: the official state schema has no
  QUEUED, so the request stays REQUESTED (Figure 16).
- **REJECTED**: the request goes and the zone is not asked for again until fleet control
  accepts a new order or update (:func:`forget_refusals`); the shell raises NODE_UNREACHABLE
  (§6.4.5).
- **REVOKED**, or its lease passed, *before* the body entered the zone: a revoked request is
  removed (§6.4.3), an expired one is reported EXPIRED in one state and then removed; either
  way the vehicle asks anew (a new ``requestId``) while it still needs the zone.
- **lost inside** the zone (revoked, expired, or rejected after entry): the zone's
  ``releaseLossBehavior`` (Table 6; absent means STOP). STOP: the vehicle stops where it is,
  the request stays with REVOKED/EXPIRED (§6.9: kept until the loss behaviour is done),
  RELEASE_LOST (CRITICAL) is raised. While an edge ahead still needs the zone it asks anew
  (a new request, REQUESTED, beside the lost one); a GRANTED for either resumes it, and the
  lost request and its error go (Table 9: until the release is granted again). CONTINUE: it
  drives on along its path, the request stays GRANTED (Table 6). EVACUATE: it drives on along
  its path until the body has left the zone (the simulated stack's evacuation), the request
  REVOKED/EXPIRED until then; with the path ending inside, it stops there. CONTINUE and
  EVACUATE raise :data:`RELEASE_LOST_DRIVING_ON`, a WARNING (§6.4.3: "report a warning").
- **removed** once the body has left the zone and no edge ahead reaches into it again, or
  when it is no longer needed before entry (order cancelled, replaced by one that keeps out
  of the zone, zone set disabled). A request for a zone the body is inside stays while it is
  inside, whatever happens to the order: it tells fleet control the zone is occupied.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from enum import StrEnum
from typing import Final

from vda5050.models import v3
from vda5050.models.v3.state import RequestStatus, ZoneRequest, ZoneRequestType
from vda_vehicle.v3_zones import ReleaseZone, ZoneKey

#: The vendor error type of a release lost inside a CONTINUE or EVACUATE zone, a WARNING
#: (§6.4.3: "it shall report a warning"; RELEASE_LOST is CRITICAL by Table 9 and means STOP).
RELEASE_LOST_DRIVING_ON: Final = "RELEASE_LOST_DRIVING_ON"
_STOP: Final = v3.ZoneReleaseLossBehavior.STOP
_CONTINUE: Final = v3.ZoneReleaseLossBehavior.CONTINUE


@dataclass(frozen=True, slots=True)
class EdgeZones:
    """An edge of the released base ahead and the enabled RELEASE zones its way reaches."""

    edge_id: str
    sequence_id: int
    end_node_id: str
    zones: tuple[ReleaseZone, ...]


@dataclass(frozen=True, slots=True)
class HeldRequest:
    """One zone request the vehicle holds, as it reports it (``status``)."""

    request_id: str
    zone: ReleaseZone
    status: RequestStatus = RequestStatus.REQUESTED
    #: Until when a GRANTED request holds (§7.5 ``leaseExpiry``); None: no limit.
    lease_expiry: datetime | None = None
    #: The release was lost with the body inside: the zone's loss behaviour is under way.
    lost: bool = False

    @property
    def key(self) -> ZoneKey:
        return self.zone.key

    @property
    def passable(self) -> bool:
        """The vehicle may drive in the zone: granted, or lost where the zone lets it drive
        on (CONTINUE, EVACUATE)."""
        if self.lost:
            return self.zone.loss is not _STOP
        return self.status is RequestStatus.GRANTED


@dataclass(frozen=True, slots=True)
class ZoneRequests:
    """The vehicle's zone requests (the first asked first) and its request counter."""

    held: tuple[HeldRequest, ...] = ()
    #: Requests asked so far in this run: the next requestId is ``zr-<issued + 1>``.
    issued: int = 0
    #: Zones fleet control REJECTED for the current order: not asked for again (§6.4.5).
    refused: frozenset[ZoneKey] = frozenset()

    def request(self, request_id: str) -> HeldRequest | None:
        return next((r for r in self.held if r.request_id == request_id), None)


class Outcome(StrEnum):
    """What one response did to the requests (:func:`answer`)."""

    #: No request with that requestId: ignored (and logged by the shell).
    UNKNOWN = "UNKNOWN"
    GRANTED = "GRANTED"
    #: GRANTED again after the release was lost inside: the vehicle goes on.
    REGRANTED = "REGRANTED"
    #: QUEUED for a waiting request: it keeps waiting, still REQUESTED.
    QUEUED = "QUEUED"
    #: An answer that changes nothing (QUEUED for a granted request, REVOKED after a loss).
    IGNORED = "IGNORED"
    REJECTED = "REJECTED"
    #: REVOKED before entry: the request is gone (asked anew while still needed).
    REVOKED = "REVOKED"
    #: REVOKED (or REJECTED) with the body inside: the zone's loss behaviour.
    LOST = "LOST"


@dataclass(frozen=True, slots=True)
class Answer:
    """The outcome of one response and the request it named (as it was)."""

    outcome: Outcome
    request: HeldRequest | None = None


def track(
    book: ZoneRequests,
    ahead: Sequence[EdgeZones],
    inside: frozenset[ZoneKey],
    now: datetime,
    *,
    reported: bool,
) -> ZoneRequests:
    """The requests after a step: leases checked against ``now``, requests no longer needed
    removed, new ones asked for the zones ``ahead`` reaches (T91).

    ``inside``: the zones (of held requests) the body is inside now. ``reported``: the last
    change is out in a state, so an EXPIRED request (before entry) may go now.
    """
    needed = {zone.key: zone for edge in ahead for zone in edge.zones}
    kept: list[HeldRequest] = []
    for before in book.held:
        request = _expire(before, now, inside=before.key in inside)
        keeps = _keeps(before, request, needed=before.key in needed, inside=before.key in inside)
        # An EXPIRED request goes once a state has said so (§6.4.3: EXPIRED, not entered).
        if keeps or (before.status is RequestStatus.EXPIRED and not before.lost and not reported):
            kept.append(request)
    # A grant supersedes the other requests for its zone: a release lost in a STOP zone
    # (Table 9: RELEASE_LOST lasts until the release is granted again), an alternative asked.
    granted = {r.key for r in kept if r.passable and not r.lost}
    kept = [r for r in kept if r.key not in granted or (r.passable and not r.lost)]
    # A stopped vehicle asks anew while it still needs the zone; the lost request stays.
    covered = {r.key for r in kept if r.passable or not r.lost}
    issued = book.issued
    for key, zone in needed.items():
        if key in covered or key in book.refused:
            continue
        issued += 1
        kept.append(HeldRequest(f"zr-{issued}", zone))
    if issued == book.issued and tuple(kept) == book.held:
        return book
    return ZoneRequests(tuple(kept), issued, book.refused)


def _expire(request: HeldRequest, now: datetime, *, inside: bool) -> HeldRequest:
    """§6.4.3: a GRANTED request whose ``leaseExpiry`` has passed is EXPIRED; inside the zone
    the loss behaviour starts (CONTINUE reports GRANTED on, Table 6)."""
    expiry = request.lease_expiry
    if request.status is not RequestStatus.GRANTED or request.lost or expiry is None:
        return request
    if now < expiry:
        return request
    if not inside:
        return replace(request, status=RequestStatus.EXPIRED)
    status = RequestStatus.GRANTED if request.zone.loss is _CONTINUE else RequestStatus.EXPIRED
    return replace(request, status=status, lost=True)


def _keeps(before: HeldRequest, request: HeldRequest, *, needed: bool, inside: bool) -> bool:
    """Whether ``request`` (``before`` as it was before this step) stays in the state."""
    if request.lost:
        return inside  # the loss behaviour is done once the body has left the zone
    if request.status is RequestStatus.EXPIRED:
        return before.status is not RequestStatus.EXPIRED  # reported once, then asked anew
    if request.status is RequestStatus.GRANTED:
        return inside or needed  # removed after the zone is left (§6.4.3)
    return needed  # REQUESTED: no longer relevant once no edge ahead needs the zone


def answer(
    book: ZoneRequests, response: v3.Response, inside: frozenset[ZoneKey]
) -> tuple[ZoneRequests, Answer]:
    """One response from fleet control applied (§6.4.3, §6.9, T93); ``inside`` as for
    :func:`track`."""
    request = book.request(response.request_id)
    if request is None:
        return book, Answer(Outcome.UNKNOWN)
    changed, outcome = _decided(request, response, inside=request.key in inside)
    result = Answer(outcome, request)
    if changed is request:
        return book, result
    if changed is not None:
        held = tuple(changed if r is request else r for r in book.held)
        return replace(book, held=held), result
    rest = tuple(r for r in book.held if r is not request)
    if outcome is Outcome.REJECTED:
        return replace(book, held=rest, refused=book.refused | {request.key}), result
    return replace(book, held=rest), result


def _decided(
    request: HeldRequest, response: v3.Response, *, inside: bool
) -> tuple[HeldRequest | None, Outcome]:
    """The request after ``response`` (None: removed) and what happened."""
    grant = response.grant_type
    if grant is v3.GrantType.GRANTED:
        lease = _lease(response.lease_expiry)
        granted = replace(request, status=RequestStatus.GRANTED, lease_expiry=lease, lost=False)
        return granted, Outcome.REGRANTED if request.lost else Outcome.GRANTED
    if grant is v3.GrantType.QUEUED:  # Figure 16: keeps waiting, reported REQUESTED
        waiting = request.status is RequestStatus.REQUESTED
        return request, Outcome.QUEUED if waiting else Outcome.IGNORED
    if request.lost:
        return request, Outcome.IGNORED
    if inside and request.status is RequestStatus.GRANTED:
        # REVOKED, or REJECTED after the grant it entered with: the release is lost inside
        # (§6.4.3, Table 6); CONTINUE reports GRANTED on, the others what happened (§6.9).
        status = RequestStatus.GRANTED if request.zone.loss is _CONTINUE else RequestStatus.REVOKED
        return replace(request, status=status, lost=True), Outcome.LOST
    if grant is v3.GrantType.REJECTED:
        return None, Outcome.REJECTED
    return None, Outcome.REVOKED  # §6.4.3: removed; asked anew while still needed


def _lease(text: str | None) -> datetime | None:
    """``leaseExpiry`` as an aware date-time; None without one (a grant without limit). The
    wire model checked the format; a value Python cannot read counts as already passed."""
    if text is None:
        return None
    try:
        when = datetime.fromisoformat(text.upper())  # Python 3.11 reads a trailing Z as UTC
    except ValueError:
        return datetime.min.replace(tzinfo=UTC)
    return when if when.tzinfo is not None else when.replace(tzinfo=UTC)


def first_closed(book: ZoneRequests, ahead: Sequence[EdgeZones]) -> EdgeZones | None:
    """The first edge ahead the vehicle may not start (T91: every zone it reaches must be
    passable, §6.4.3), or None when the way ahead is open. An edge the vehicle is on counts
    too: it stops where it is (a lease that expired before entry, a STOP loss inside)."""
    passable = {r.key for r in book.held if r.passable}
    for edge in ahead:
        if any(zone.key not in passable for zone in edge.zones):
            return edge
    return None


def forget_refusals(book: ZoneRequests) -> ZoneRequests:
    """A new order or order update is fleet control's decision how to go on (§6.4.5): the
    zones it rejected may be asked for again."""
    return replace(book, refused=frozenset()) if book.refused else book


def cleared(book: ZoneRequests) -> ZoneRequests:
    """All requests removed (Table 11: entering INTERVENED, MANUAL, STARTUP, SERVICE or
    TEACH_IN, also inside a RELEASE zone); the counter keeps running."""
    return ZoneRequests(issued=book.issued) if book.held or book.refused else book


def reported(book: ZoneRequests) -> list[ZoneRequest]:
    """``state.zoneRequests`` (§7.8): every request held, ACCESS, its status as kept."""
    return [
        ZoneRequest(
            request_id=r.request_id,
            request_type=ZoneRequestType.ACCESS,
            zone_id=r.zone.zone.zone_id,
            zone_set_id=r.zone.zone_set_id,
            request_status=r.status,
        )
        for r in book.held
    ]


def loss_errors(book: ZoneRequests) -> tuple[v3.Error, ...]:
    """The errors of releases lost inside a zone, while the loss lasts (Table 9: until the
    zone is left or the release granted again): RELEASE_LOST (CRITICAL) for STOP,
    :data:`RELEASE_LOST_DRIVING_ON` (WARNING) for CONTINUE and EVACUATE."""
    errors: list[v3.Error] = []
    for r in book.held:
        if not r.lost:
            continue
        refs = (
            ("zoneId", r.zone.zone.zone_id),
            ("zoneSetId", r.zone.zone_set_id),
            ("requestId", r.request_id),
        )
        loss = r.zone.loss
        if loss is _STOP:
            text = f"release of zone {r.zone.zone.zone_id!r} lost inside it: the vehicle stops"
            errors.append(v3.predefined_error(v3.ErrorType.RELEASE_LOST, *refs, description=text))
            continue
        doing = "drives on along its path" if loss is _CONTINUE else "leaves it along its path"
        errors.append(
            v3.Error(
                error_type=RELEASE_LOST_DRIVING_ON,
                error_references=[
                    v3.ErrorReference(reference_key=k, reference_value=v)
                    for k, v in (*refs, ("releaseLossBehavior", loss.value))
                ],
                error_description=f"release of zone {r.zone.zone.zone_id!r} lost inside it: "
                f"the vehicle {doing} ({loss.value})",
                error_level=v3.ErrorLevel.WARNING,
            )
        )
    return tuple(errors)
