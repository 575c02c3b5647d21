"""What master control tells a plant's systems (a WMS, an MES) by webhook, and how (pure).

VDA 5050 ends at master control; the systems that order transports need to hear when one
ends without asking every second. Every change of an order's status and of a vehicle's
connection becomes an event, POSTed as JSON to each configured ``webhook_urls`` entry
(:mod:`vda_master.webhooks` delivers them; docs/master.md, *Webhooks*):

- ``order.status``: ``orderId``, ``status`` and ``previousStatus`` (null for a new order),
  ``manufacturer`` and ``serialNumber`` (null for a queued order any vehicle may take),
  ``reason`` (why it failed, was rejected or waits);
- ``vehicle.connection``: ``manufacturer``, ``serialNumber``, ``connectionState`` and
  ``previousConnectionState`` (null for a vehicle heard from the first time);
- ``vehicle.errors``: the errors a vehicle's state raised and cleared against its last one,
  and all it lists now (:mod:`vda_master.alarms` says when an error is the same), with the
  ``orderId`` it runs (null when none);
- ``vehicle.safety``: ``eStop`` and ``fieldViolation`` when either changes, with the
  previous values (null for the vehicle's first state) and the ``orderId``.

Every event has ``eventId`` (1, 2, …; it goes on across restarts when a store keeps the
events, :mod:`vda_master.webhook_outbox`), ``type`` and ``timestamp`` (ISO 8601 UTC). With
``webhook_secret`` each request carries ``X-VDA-Signature: sha256=<hex>``, the HMAC-SHA256 of
the body under the secret, so a receiver can tell master control's events from anybody else's.
"""

from __future__ import annotations

import hashlib
import hmac
from collections.abc import Sequence
from enum import Enum
from typing import Final

from pydantic import JsonValue

from vda5050.topics import AgvId

ORDER_STATUS: Final = "order.status"
VEHICLE_CONNECTION: Final = "vehicle.connection"
VEHICLE_ERRORS: Final = "vehicle.errors"
VEHICLE_SAFETY: Final = "vehicle.safety"
#: The header naming the signature, and the one naming the event type.
SIGNATURE_HEADER: Final = "X-VDA-Signature"
EVENT_HEADER: Final = "X-VDA-Event"
#: Waits between two attempts of one delivery: doubled each time from the first, capped.
FIRST_RETRY_S: Final = 0.5
LAST_RETRY_S: Final = 30.0

Event = dict[str, JsonValue]


def order_event(
    order_id: str,
    status: str,
    previous: str | None,
    agv: AgvId | None,
    reason: str | None,
    *,
    expected_finish: str | None = None,
) -> Event:
    """An ``order.status`` event (without eventId and timestamp: :func:`stamped`);
    ``expected_finish``: the order's ``expectedFinishAt`` while it is under way."""
    return {
        "type": ORDER_STATUS,
        "orderId": order_id,
        "status": status,
        "previousStatus": previous,
        "manufacturer": None if agv is None else agv.manufacturer,
        "serialNumber": None if agv is None else agv.serial_number,
        "reason": reason or None,
        "expectedFinishAt": expected_finish,
    }


def connection_event(agv: AgvId, state: str, previous: str | None) -> Event:
    """A ``vehicle.connection`` event (without eventId and timestamp)."""
    return {
        "type": VEHICLE_CONNECTION,
        "manufacturer": agv.manufacturer,
        "serialNumber": agv.serial_number,
        "connectionState": state,
        "previousConnectionState": previous,
    }


def errors_event(
    agv: AgvId,
    order_id: str | None,
    *,
    raised: Sequence[dict[str, JsonValue]],
    cleared: Sequence[dict[str, JsonValue]],
    errors: Sequence[dict[str, JsonValue]],
) -> Event:
    """A ``vehicle.errors`` event: each error as :func:`vda_master.alarms.error_document`
    gives it."""
    as_json: tuple[list[JsonValue], ...] = ([*raised], [*cleared], [*errors])
    return {
        "type": VEHICLE_ERRORS,
        "manufacturer": agv.manufacturer,
        "serialNumber": agv.serial_number,
        "orderId": order_id,
        "raised": as_json[0],
        "cleared": as_json[1],
        "errors": as_json[2],
    }


def safety_event(
    agv: AgvId,
    order_id: str | None,
    *,
    e_stop: str,
    field_violation: bool,
    previous: tuple[str, bool] | None,
) -> Event:
    """A ``vehicle.safety`` event; ``previous``: eStop and fieldViolation before (None: the
    vehicle's first state)."""
    return {
        "type": VEHICLE_SAFETY,
        "manufacturer": agv.manufacturer,
        "serialNumber": agv.serial_number,
        "orderId": order_id,
        "eStop": e_stop,
        "fieldViolation": field_violation,
        "previousEStop": None if previous is None else previous[0],
        "previousFieldViolation": None if previous is None else previous[1],
    }


def stamped(event: Event, event_id: int, timestamp: str) -> Event:
    """``event`` with its id and time first."""
    return {"eventId": event_id, "timestamp": timestamp, **event}


def signature(secret: str, body: bytes) -> str:
    """The ``X-VDA-Signature`` value of ``body``: ``sha256=`` and the hex HMAC-SHA256."""
    digest = hmac.new(secret.encode(), body, hashlib.sha256).hexdigest()
    return f"sha256={digest}"


class Verdict(Enum):
    """What an answer (or its absence) means for a delivery."""

    DELIVERED = "delivered"
    RETRY = "retry"
    REFUSED = "refused"


#: Answers that say "not now" rather than "never" (RFC 9110: request timeout, too many
#: requests); every 5xx says the same.
_TRY_AGAIN: Final = frozenset({408, 425, 429})


def verdict(status: int | None) -> Verdict:
    """None: no answer (the receiver cannot be reached, or did not answer in time)."""
    if status is None or status in _TRY_AGAIN or status >= 500:  # noqa: PLR2004 - HTTP 5xx
        return Verdict.RETRY
    if 200 <= status < 300:  # noqa: PLR2004 - HTTP 2xx
        return Verdict.DELIVERED
    return Verdict.REFUSED


def retry_delay(attempt: int) -> float:
    """Seconds to wait after failed attempt ``attempt`` (1, 2, …): 0.5, 1, 2, … up to 30."""
    return float(min(LAST_RETRY_S, FIRST_RETRY_S * 2.0 ** (attempt - 1)))
