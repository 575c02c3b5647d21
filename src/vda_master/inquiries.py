"""Asking a vehicle for what master control lacks: its state and its factsheet (§6.8.1, §6.15).

A vehicle that connected before master control subscribed published its first state to nobody
(state is not retained), and a vehicle may never publish a factsheet unprompted (vda-5050-lib's
virtual AGV does not). Master control therefore sends ``stateRequest`` to an ONLINE vehicle whose
state it lacks (or whose state predates the master's own reconnect to the broker), and
``factsheetRequest`` (2.x) to an ONLINE vehicle without a valid factsheet, factsheet or not: the
factsheet narrows what is sent, its absence never makes a vehicle unusable.

Each request is retried with a growing delay and abandoned after :data:`MAX_ATTEMPTS` sends.
While master control lags behind its inbound messages, every delay is :data:`BEHIND_FACTOR`
times longer: what is lacking may only be unread (a thousand vehicles connecting at once publish
their first states faster than master control reads them; asking them all again would double
the load that delayed the answers). A
vehicle that refuses one (the action FAILED, or an error names its actionId) is not asked again
for it until it reconnects; the refusal is logged by the shell, it is never fatal. Pure: the
shell passes the vehicle's view and the time in.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum
from typing import Final

from vda5050.models import ActionStatus, ConnectionState, State
from vda_master.fleet import CONTROLLABLE_MODES, VehicleView

#: Seconds to wait, once something is found lacking, before the first request: what a vehicle
#: publishes by itself right after connecting (its state, its retained factsheet) comes first.
FIRST_DELAY_S: Final = 1.0
#: ... and after a vehicle was seen connecting (its ONLINE arrived live, not as a retained
#: message from before master control subscribed): it publishes its state by itself (R09), but
#: a thousand vehicles connecting at once take seconds between their ONLINE and their state.
CONNECT_GRACE_S: Final = 5.0
#: Seconds to wait after the n-th send before sending again (n = 1, 2, ...).
RETRY_DELAYS_S: Final = (5.0, 10.0, 20.0, 40.0)
#: Sends of one request in all before master control stops asking.
MAX_ATTEMPTS: Final = len(RETRY_DELAYS_S) + 1
#: How many times longer every delay is while master control lags (load is not loss, as for
#: the resends of orders: dispatcher.BEHIND_CEILING).
BEHIND_FACTOR: Final = 5.0


class InquiryKind(StrEnum):
    """What is asked for; the value is the predefined instant action that asks (§6.8.1)."""

    STATE = "stateRequest"
    FACTSHEET = "factsheetRequest"


@dataclass(frozen=True, slots=True)
class Inquiry:
    """One kind of request to one vehicle: how often and when it was sent, and whether master
    control stopped asking (``closed`` says why)."""

    kind: InquiryKind
    opened_at: float = 0.0
    #: Seconds from ``opened_at`` to the first request.
    first_delay_s: float = FIRST_DELAY_S
    attempts: int = 0
    last_sent: float | None = None
    action_id: str | None = None
    closed: str | None = None

    @property
    def open(self) -> bool:
        return self.closed is None


def wanted(kind: InquiryKind, vehicle: VehicleView, *, stale_before: float | None) -> bool:
    """Whether master control lacks what ``kind`` asks for and the vehicle can be asked now.

    A state is lacking when none was seen, or the last one predates ``stale_before`` (the master
    reconnected to the broker since). A factsheet is lacking when no valid one was seen; only
    2.x and 3.0 know ``factsheetRequest`` by that name.
    """
    if vehicle.connection != ConnectionState.ONLINE:
        return False
    state = vehicle.state
    if state is not None and state.operating_mode not in CONTROLLABLE_MODES:
        return False  # R84: no actions to a vehicle in MANUAL, SERVICE or TEACHIN
    if kind is InquiryKind.STATE:
        if vehicle.state is None or vehicle.last_state_at is None:
            return True
        return stale_before is not None and vehicle.last_state_at < stale_before
    return vehicle.factsheet is None and (vehicle.version or "2").startswith(("2", "3"))


def due(inquiry: Inquiry, now: float, *, behind: bool = False) -> bool:
    """Whether to send the request (again) now; ``behind``: master control lags behind its
    inbound messages, every delay is :data:`BEHIND_FACTOR` times longer."""
    if not inquiry.open or inquiry.attempts >= MAX_ATTEMPTS:
        return False
    factor = BEHIND_FACTOR if behind else 1.0
    if inquiry.last_sent is None:
        return now - inquiry.opened_at >= inquiry.first_delay_s * factor
    return now - inquiry.last_sent >= RETRY_DELAYS_S[inquiry.attempts - 1] * factor


def sent(inquiry: Inquiry, action_id: str, now: float) -> Inquiry:
    """The inquiry after one more send with ``action_id``."""
    return replace(inquiry, attempts=inquiry.attempts + 1, last_sent=now, action_id=action_id)


def exhausted(inquiry: Inquiry, now: float) -> bool:
    """Every attempt was sent and the last one had its time to be answered."""
    return (
        inquiry.open
        and inquiry.attempts >= MAX_ATTEMPTS
        and inquiry.last_sent is not None
        and now - inquiry.last_sent >= RETRY_DELAYS_S[-1]
    )


def refusal(inquiry: Inquiry, state: State) -> str | None:
    """Why the vehicle refused the last request, read from its state, or None.

    Refused: the request's actionState is FAILED, or an error references its actionId (a vehicle
    that does not know the action rejects it with an error and may list no actionState).
    """
    if inquiry.action_id is None:
        return None
    for action in state.action_states:
        if action.action_id == inquiry.action_id and action.action_status == ActionStatus.FAILED:
            return action.result_description or f"{inquiry.kind} FAILED"
    for error in state.errors:
        refs = {r.reference_key: r.reference_value for r in error.error_references or ()}
        if refs.get("actionId") == inquiry.action_id:
            detail = f": {error.error_description}" if error.error_description else ""
            return f"{error.error_type}{detail}"
    return None
