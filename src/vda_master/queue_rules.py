"""Queued transport orders: which one goes next, and when one is worth trying again (pure).

``POST /orders`` with ``queue: true`` keeps an order that no vehicle can take now (what would
otherwise be a 409) instead of refusing it (docs/master.md, *Queued orders*). The shell
(:mod:`vda_master.order_queue`) tries the queue whenever a vehicle may have come free; these
rules decide the order of the attempts and spare it attempts whose answer cannot have changed.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Final

from vda5050.topics import AgvId
from vda_master.dispatcher import OrderStatus
from vda_master.requests import OrderRequest

#: An order refused for the same set of available vehicles is tried again after this many
#: simulated seconds all the same: what refused it (a battery's reach, traffic, a zone) may have
#: changed without any vehicle coming or going.
RETRY_EVERY_S: Final = 10.0
#: How the reason of an order that ended before any vehicle was sent anything begins.
NEVER_SENT: Final = "no vehicle was sent this order: "


@dataclass(frozen=True, slots=True)
class QueuedOrder:
    """An order that waits for a vehicle, or one that ended while waiting.

    ``seq`` is its place in arrival order (ties of ``priority`` go first come, first served);
    ``reason`` says why it waits (the refusal of its latest attempt) or why it ended;
    ``tried_with`` and ``tried_at`` are the available vehicles it was refused with, and when;
    ``deadline`` is when it fails if it still waits (``queueTimeoutS`` after its creation).
    """

    order_id: str
    request: OrderRequest
    priority: int
    seq: int
    created_utc: str
    reason: str = ""
    status: OrderStatus = OrderStatus.QUEUED
    tried_with: frozenset[AgvId] | None = None
    tried_at: float = -math.inf
    #: When it fails if no vehicle has taken it (wall clock, UTC; None: never)
    deadline: datetime | None = None


def deadline_of(created: datetime, timeout_s: float | None, time_lapse: float) -> datetime | None:
    """When an order created at ``created`` that may wait ``timeout_s`` simulated seconds
    fails, on the wall clock (None: it may wait as long as it takes)."""
    if timeout_s is None:
        return None
    return created + timedelta(seconds=timeout_s / time_lapse)


def overdue(entries: Iterable[QueuedOrder], now: datetime) -> list[QueuedOrder]:
    """The waiting orders whose deadline has come."""
    return [
        e
        for e in entries
        if e.status is OrderStatus.QUEUED and e.deadline is not None and now >= e.deadline
    ]


def serving_order(entries: Iterable[QueuedOrder]) -> list[QueuedOrder]:
    """The waiting orders in the order they get vehicles: highest ``priority`` first, then
    first come, first served."""
    return sorted((e for e in entries if e.status is OrderStatus.QUEUED), key=_serving_key)


def relevant(entry: QueuedOrder, available: frozenset[AgvId]) -> frozenset[AgvId]:
    """The available vehicles that could take ``entry``: its own vehicle if it names one."""
    agv = entry.request.agv
    if agv is None:
        return available
    return available & {agv}


def worth_trying(
    entry: QueuedOrder, available: frozenset[AgvId], now: float, retry_s: float
) -> bool:
    """Whether an attempt could place ``entry`` now: a vehicle that could take it is
    available, and either the available vehicles changed since it was last refused or
    ``retry_s`` has passed since."""
    candidates = relevant(entry, available)
    if not candidates:
        return False
    return candidates != entry.tried_with or now - entry.tried_at >= retry_s


def queue_position(entries: Iterable[QueuedOrder], order_id: str) -> int | None:
    """Where ``order_id`` stands in :func:`serving_order` (1 goes next); None if it does not
    wait. O(entries), without sorting them."""
    waiting = [e for e in entries if e.status is OrderStatus.QUEUED]
    this = next((e for e in waiting if e.order_id == order_id), None)
    if this is None:
        return None
    key = _serving_key(this)
    return 1 + sum(1 for e in waiting if _serving_key(e) < key)


def _serving_key(entry: QueuedOrder) -> tuple[int, int]:
    return (-entry.priority, entry.seq)
