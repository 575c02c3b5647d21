"""Late orders go first: the claims of late waiting vehicles (issue 9 §3, §4).

Issue 9 counts an order that takes over five times its free-flow time as a deadlock. At high
load such orders are short transports caught in a jam, while most orders have time to spare. So
the release gate weighs *lateness*:

- an order is **late** once it has taken ``late_stretch`` times its free-flow estimate (the
  route master control would give the vehicle alone, driven without waiting, plus ``dwell_s``
  for the action at its end), and **due** at its start plus ``due_stretch`` times that estimate;
- a late vehicle that waits **claims** the step it was refused (:attr:`VehicleTraffic.blocked`:
  the resources from the end of its base to the step's end);
- the gate grants another vehicle no step that conflicts with a claim whose order is due
  earlier than its own, unless the claimant waits for it, directly or through other waiting
  vehicles: that one must move for the claimant to go on.

A refused vehicle waits for the claimant and is woken when the claimant moves on. Claims only
hold vehicles back, so the reservation invariant is untouched; and a claim never stops a vehicle
the claimant needs to move, so it adds no cycle of waits by itself (one that forms later is a
deadlock like any other, resolved as usual). Work per release: a lateness check per waiting
vehicle and, only if one is late, one walk of the reverse index of waits (who waits for the
asking vehicle, :func:`~vda_master.traffic.waits.waiting_for_group`) and O(step x conflict-set
size) per claim.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

from vda5050.topics import AgvId
from vda_master.traffic.conflicts import ConflictMap, Resource
from vda_master.traffic.gate import route_resources
from vda_master.traffic.reservations import Refused
from vda_master.traffic.state import TrafficSettings, TrafficState, VehicleTraffic, waiters_of
from vda_master.traffic.waits import waiting_for_group


@dataclass(frozen=True, slots=True)
class Claim:
    """``agv``, late and waiting, claims ``resources``: the step it was refused."""

    agv: AgvId
    resources: frozenset[Resource]


def due_time(vehicle: VehicleTraffic, settings: TrafficSettings) -> float:
    """When ``vehicle``'s order turns into a deadlock in issue 9's sense (inf: no order known)."""
    if vehicle.order_since is None or vehicle.free_flow_s is None:
        return math.inf
    return vehicle.order_since + settings.due_stretch * vehicle.free_flow_s


def is_late(vehicle: VehicleTraffic, settings: TrafficSettings, now: float) -> bool:
    """Whether ``vehicle``'s order has taken ``late_stretch`` times its free-flow estimate."""
    if vehicle.order_since is None or vehicle.free_flow_s is None:
        return False
    return now - vehicle.order_since >= settings.late_stretch * vehicle.free_flow_s


def claims_against(state: TrafficState, agv: AgvId, now: float) -> tuple[Claim, ...]:
    """The claims that ``agv`` must not be granted anything conflicting with, now."""
    settings = state.settings
    due = due_time(state.vehicle(agv), settings)
    late = [
        other
        for other in state.waiting
        if other != agv
        and is_late(vehicle := state.vehicle(other), settings, now)
        and due_time(vehicle, settings) < due
    ]
    if not late:
        return ()
    # vehicles waiting for agv, directly or not: agv must be let move for them to go on
    stalled = waiting_for_group((agv,), partial(waiters_of, state))
    found = []
    for other in sorted(late, key=str):
        vehicle = state.vehicle(other)
        route, blocked = vehicle.route, vehicle.blocked
        if other in stalled or route is None or blocked is None:
            continue
        step = route_resources(route, vehicle.granted_end, blocked.step_end)[1:]
        found.append(Claim(other, frozenset(step)))
    return tuple(found)


def claimed(
    conflicts: ConflictMap, claims: tuple[Claim, ...], step: list[Resource]
) -> Refused | None:
    """The first resource of ``step`` that conflicts with a claim, as a refusal naming the
    claimed resource and the claimant; None when the step touches no claim."""
    for claim in claims:
        for wanted in step:
            touched = conflicts[wanted] & claim.resources
            if touched:
                return Refused(wanted, min(touched), claim.agv)
    return None
