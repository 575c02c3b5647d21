"""Answers to a 3.0 robot's zone and edge requests, pure (3.0 §6.4.3, §6.6.10, §6.9, §7.5;
rules T91-T94 of docs/vda5050-3.md).

A robot states a request in its state (``zoneRequests``, ``edgeRequests``); master control
answers each on ``responses``. What it grants is what traffic control has already given the
vehicle, so the answer can never contradict the orders:

- **ACCESS to a RELEASE zone** is GRANTED while the vehicle holds the zone in traffic control
  (its released base reaches into it, or it stands in it: those resources all conflict, so one
  vehicle at a time; docs/traffic.md, *Release zones*), else QUEUED: the grant follows once its
  base is released into the zone. A zone that is not a RELEASE zone of one of our zone sets, and
  every REPLANNING request (master control has no COORDINATED_REPLANNING zones), is REJECTED
  with the reason logged.
- **CORRIDOR use of an edge** (``releaseRequired``) is GRANTED for an edge of the vehicle's
  released base (§6.6.10: "only for edges that are part of the base"; traffic control already
  counts the corridor's width), REJECTED for any other.
- A grant carries a lease (``leaseExpiry``) when one is configured, renewed once half of it has
  passed while the robot still reports GRANTED. A robot reporting GRANTED for a zone that
  traffic control does not give it (a restart in between) is neither renewed nor revoked
  (revoking one inside the zone would stop it): its lease runs out.
- With traffic control off (nothing holds a zone for the vehicles), a zone goes to one asking
  robot at a time, first come, until its request leaves the robot's state (:func:`owners_after`).
- An answer is sent again after :data:`RESEND_AFTER_S` while the robot still reports REQUESTED
  (``responses`` goes QoS 0). A request the robot marks REVOKED or EXPIRED, or drops, needs no
  answer.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Final

from vda5050.models import v3
from vda5050.models.v3.state import EdgeRequest, RequestStatus, ZoneRequest, ZoneRequestType
from vda5050.topics import AgvId

#: An answer the robot's state does not reflect yet is sent again after this long (seconds).
RESEND_AFTER_S: Final = 5.0

GRANTED: Final = v3.GrantType.GRANTED
QUEUED: Final = v3.GrantType.QUEUED
REJECTED: Final = v3.GrantType.REJECTED


@dataclass(frozen=True, slots=True)
class Answered:
    """What was last answered to one request, when (monotonic seconds), and, for a grant with a
    lease, when the lease ends (monotonic seconds)."""

    grant_type: v3.GrantType
    at: float
    lease_end: float | None = None


@dataclass(frozen=True, slots=True)
class Decision:
    """One response to send; ``reason`` says why (logged), ``lease`` whether it has one."""

    request_id: str
    grant_type: v3.GrantType
    reason: str
    lease: bool = False


@dataclass(frozen=True, slots=True)
class Facts:
    """What master control knows about one robot when it answers.

    ``release_zone(zone_set_id, zone_id)`` is None for a RELEASE zone of one of our zone sets,
    else why the request cannot be answered with a grant; ``holds(zone_id)`` whether traffic
    control gives the robot the zone; ``in_base(edge_id, sequence_id)`` whether that edge is
    in its released base.
    """

    release_zone: Callable[[str, str], str | None]
    holds: Callable[[str], bool]
    in_base: Callable[[str, int], bool]
    #: Seconds a grant lasts (None: no lease).
    lease_s: float | None = None


Request = ZoneRequest | EdgeRequest


def decide(
    requests: Iterable[Request],
    facts: Facts,
    answered: Mapping[str, Answered],
    now: float,
) -> list[Decision]:
    """The responses to send now for the robot's current ``requests`` (``answered``: the last
    answer to each request id, which the caller keeps)."""
    decisions = []
    for request in requests:
        if request.request_status in (RequestStatus.REVOKED, RequestStatus.EXPIRED):
            continue  # the robot lets it go (§6.9); nothing to answer
        decision = _decision(request, facts)
        last = answered.get(request.request_id)
        if _due(decision, request, last, facts, now):
            decisions.append(decision)
    return decisions


def remember(
    answered: Mapping[str, Answered],
    decisions: Iterable[Decision],
    live: Iterable[str],
    lease_s: float | None,
    now: float,
) -> dict[str, Answered]:
    """The answers to keep: those of requests still in the robot's state (``live``), updated by
    the ``decisions`` just sent."""
    kept = {request_id: answered[request_id] for request_id in live if request_id in answered}
    for decision in decisions:
        lease_end = now + lease_s if decision.lease and lease_s else None
        kept[decision.request_id] = Answered(decision.grant_type, now, lease_end)
    return kept


def owners_after(
    owners: Mapping[str, AgvId], agv: AgvId, requests: Iterable[Request]
) -> dict[str, AgvId]:
    """Traffic control off: each RELEASE zone's robot, first come, first served, after
    ``agv`` states ``requests``: it keeps the zones it still asks for (ACCESS) and gets those
    nobody has; a zone it no longer asks for (it has left) is free again."""
    asking = {
        r.zone_id
        for r in requests
        if isinstance(r, ZoneRequest) and r.request_type is ZoneRequestType.ACCESS
    }
    kept = {z: owner for z, owner in owners.items() if owner != agv or z in asking}
    for zone_id in sorted(asking):
        kept.setdefault(zone_id, agv)
    return kept


def _decision(request: Request, facts: Facts) -> Decision:
    rid = request.request_id
    if isinstance(request, EdgeRequest):
        where = f"edge {request.edge_id!r} (sequenceId {request.sequence_id})"
        if facts.in_base(request.edge_id, request.sequence_id):
            return Decision(rid, GRANTED, f"{where} is in the released base", lease=True)
        return Decision(rid, REJECTED, f"{where} is not in the robot's released base (§6.6.10)")
    zone = f"zone {request.zone_id!r} of zone set {request.zone_set_id!r}"
    if request.request_type is not ZoneRequestType.ACCESS:
        why = "master control has no COORDINATED_REPLANNING zones"
        return Decision(rid, REJECTED, f"{request.request_type.value} of {zone}: {why}")
    problem = facts.release_zone(request.zone_set_id, request.zone_id)
    if problem is not None:
        return Decision(rid, REJECTED, f"{zone}: {problem}")
    if facts.holds(request.zone_id):
        return Decision(rid, GRANTED, f"{zone}: the robot's base is released into it", lease=True)
    return Decision(rid, QUEUED, f"{zone}: another vehicle has it, or the base is not there yet")


def _due(
    decision: Decision, request: Request, last: Answered | None, facts: Facts, now: float
) -> bool:
    """Whether ``decision`` is to be sent now, given the last answer and the robot's status."""
    status = request.request_status
    if status is RequestStatus.GRANTED:
        if decision.grant_type is not GRANTED:
            return False  # not ours to back (a restart): no renewal, no revocation
        if facts.lease_s is None:
            return False
        if last is None or last.lease_end is None:
            return True  # a grant we did not send (a restart): give it our lease
        return now >= last.lease_end - facts.lease_s / 2
    # REQUESTED (or QUEUED, as some robots mirror it): answer once, again if it stays unseen
    if last is None or last.grant_type is not decision.grant_type:
        return True
    return now - last.at >= RESEND_AFTER_S
