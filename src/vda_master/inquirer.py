"""The shell side of :mod:`vda_master.inquiries`: which requests are open per vehicle, sending
them when due, and one log line per outcome (answered, refused, abandoned).

Work is driven by events (a message from the vehicle, the master's reconnect) and by a tick that
only visits vehicles with an open request, never the whole fleet.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Final

import structlog

from vda5050.models import Action, BlockingType, Factsheet, State
from vda5050.topics import AgvId
from vda_master.fleet import FleetView, VehicleView
from vda_master.inquiries import (
    CONNECT_GRACE_S,
    FIRST_DELAY_S,
    Inquiry,
    InquiryKind,
    due,
    exhausted,
    refusal,
    sent,
    wanted,
)

log = structlog.get_logger()
#: Seconds between two visits of the open inquiries while master control lags.
BEHIND_TICK_S: Final = 1.0
SendAction = Callable[[AgvId, Action], None]


class Inquirer:
    """stateRequest/factsheetRequest inquiries of every vehicle, open and closed."""

    def __init__(self, send: SendAction, new_id: Callable[[], str]) -> None:
        self._send = send
        self._new_id = new_id
        #: Every inquiry per vehicle; a closed one stays so that it is not reopened.
        self._inquiries: dict[AgvId, dict[InquiryKind, Inquiry]] = {}
        #: Vehicles with at least one open inquiry: the only ones the tick visits.
        self._active: set[AgvId] = set()
        #: Monotonic time of the master's last (re)connect to the broker: older states are stale.
        self._stale_before: float | None = None
        #: Master control lags behind its inbound messages (the service sets it every tick):
        #: requests wait longer, the answer may be unread (inquiries.BEHIND_FACTOR).
        self.behind = False
        self._next_behind_tick = 0.0

    def pending(self) -> int:
        """Vehicles with at least one open inquiry."""
        return len(self._active)

    def inquiry(self, agv: AgvId, kind: InquiryKind) -> Inquiry | None:
        """The inquiry of ``kind`` to ``agv``, open or closed, if there is one."""
        return self._inquiries.get(agv, {}).get(kind)

    def broker_connected(self, fleet: FleetView, now: float) -> None:
        """After every (re)connect: states seen before are stale, ask every ONLINE vehicle."""
        self._stale_before = now
        for vehicle in fleet:
            self._inquiries.get(vehicle.agv, {}).pop(InquiryKind.STATE, None)
            self.consider(vehicle, now)

    def vehicle_reconnected(self, vehicle: VehicleView, now: float, *, live: bool = False) -> None:
        """A vehicle came (back) ONLINE: what it refused or ignored before may work now.
        ``live``: its ONLINE was published just now (not a retained one from before master
        control subscribed), so its own state and factsheet are on their way: the first
        requests wait CONNECT_GRACE_S."""
        grace = CONNECT_GRACE_S if live else FIRST_DELAY_S
        self._inquiries[vehicle.agv] = {
            kind: Inquiry(kind, now, first_delay_s=grace)
            for kind in InquiryKind
            if wanted(kind, vehicle, stale_before=self._stale_before)
        }
        self.consider(vehicle, now)

    def forget(self, agv: AgvId) -> None:
        """Drop everything about a vehicle that left the fleet view."""
        self._inquiries.pop(agv, None)
        self._active.discard(agv)

    def consider(self, vehicle: VehicleView, now: float) -> None:
        """Open what is wanted, close what is no longer wanted, send what is due."""
        held = self._inquiries.setdefault(vehicle.agv, {})
        for kind in InquiryKind:
            inquiry = held.get(kind)
            if wanted(kind, vehicle, stale_before=self._stale_before):
                held[kind] = self._advance(vehicle.agv, inquiry or Inquiry(kind, now), now)
            elif inquiry is not None and inquiry.open:
                held[kind] = self._closed(vehicle.agv, inquiry, "answered")
        if any(i.open for i in held.values()):
            self._active.add(vehicle.agv)
        else:
            self._active.discard(vehicle.agv)

    def observe_state(self, vehicle: VehicleView, state: State, now: float) -> None:
        """A state arrived: it may refuse a request, and it answers the stateRequest."""
        held = self._inquiries.get(vehicle.agv, {})
        for kind, inquiry in list(held.items()):
            reason = refusal(inquiry, state) if inquiry.open else None
            if reason is not None:
                log.warning(
                    "vehicle.request_refused",
                    agv=str(vehicle.agv),
                    action=kind.value,
                    action_id=inquiry.action_id,
                    reason=reason,
                )
                held[kind] = replace(inquiry, closed=f"refused: {reason}")
        self.consider(vehicle, now)

    def observe_factsheet(self, vehicle: VehicleView, factsheet: Factsheet | None) -> None:
        """A factsheet arrived; an invalid one (None) answers the factsheetRequest too."""
        held = self._inquiries.get(vehicle.agv, {})
        inquiry = held.get(InquiryKind.FACTSHEET)
        if inquiry is not None and inquiry.open and inquiry.attempts and factsheet is None:
            held[InquiryKind.FACTSHEET] = self._closed(
                vehicle.agv, inquiry, "answered with an invalid factsheet"
            )

    def tick(self, fleet: FleetView, now: float) -> None:
        """Resend what is due; only vehicles with an open inquiry are visited, and while
        master control lags at most every :data:`BEHIND_TICK_S` (a fleet connecting at once
        has an inquiry open for each vehicle whose state is still unread)."""
        if self.behind:
            if now < self._next_behind_tick:
                return
            self._next_behind_tick = now + BEHIND_TICK_S
        for agv in list(self._active):
            vehicle = fleet.get(agv)
            if vehicle is None:
                self.forget(agv)
            else:
                self.consider(vehicle, now)

    def _advance(self, agv: AgvId, inquiry: Inquiry, now: float) -> Inquiry:
        if not inquiry.open:
            return inquiry
        if exhausted(inquiry, now):
            return self._closed(agv, inquiry, f"no answer after {inquiry.attempts} requests")
        if not due(inquiry, now, behind=self.behind):
            return inquiry
        action_id = self._new_id()
        self._send(
            agv,
            Action(
                action_type=inquiry.kind.value,
                action_id=action_id,
                blocking_type=BlockingType.NONE,
            ),
        )
        return sent(inquiry, action_id, now)

    @staticmethod
    def _closed(agv: AgvId, inquiry: Inquiry, why: str) -> Inquiry:
        if inquiry.attempts:
            log.info(
                "vehicle.request_closed",
                agv=str(agv),
                action=inquiry.kind.value,
                attempts=inquiry.attempts,
                outcome=why,
            )
        return replace(inquiry, closed=why)
