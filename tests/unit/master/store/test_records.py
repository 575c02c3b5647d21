"""Store records: times are aware UTC, terminal follows status, headerIds are uint32."""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime, timedelta, timezone

import pytest

from vda_master.dispatcher import OrderStatus
from vda_master.store import HeaderCounter, OrderEvent
from vda_master.store.testing import make_event, make_order_record, make_vehicle_record


@pytest.mark.parametrize("status", list(OrderStatus))
def test_terminal_follows_the_dispatcher_status(status: OrderStatus) -> None:
    """An order is terminal exactly when the dispatcher's status is."""
    record = make_order_record(status=status.value)
    terminal = status in {"FINISHED", "FAILED", "REJECTED", "CANCELLED"}
    assert record.terminal is terminal
    assert replace(record, status="SENT").terminal is False


def test_naive_times_are_refused() -> None:
    """Naive datetimes are a programming error in every record."""
    naive = datetime(2026, 1, 1)  # noqa: DTZ001
    with pytest.raises(ValueError, match="created_at must be timezone-aware"):
        make_order_record(created_at=naive)
    with pytest.raises(ValueError, match="time must be timezone-aware"):
        make_event(time=naive)
    with pytest.raises(ValueError, match="last_seen must be timezone-aware"):
        make_vehicle_record(last_seen=naive)


def test_times_are_kept_in_utc() -> None:
    """A time in another zone is converted to the same instant in UTC."""
    local = datetime(2026, 1, 1, 14, 0, tzinfo=timezone(timedelta(hours=2)))
    record = make_order_record(created_at=local)
    assert record.created_at == datetime(2026, 1, 1, 12, 0, tzinfo=UTC)
    assert record.created_at.tzinfo is UTC


def test_header_ids_are_uint32() -> None:
    """A headerId counter outside 0..2**32-1 is refused (§6.4)."""
    assert HeaderCounter("m", "s", "order", 2**32 - 1).header_id == 2**32 - 1
    for bad in (-1, 2**32):
        with pytest.raises(ValueError, match="uint32"):
            HeaderCounter("m", "s", "order", bad)


def test_every_event_gets_its_own_id() -> None:
    """Two events built alike still have distinct ids (appending is idempotent per id)."""
    first, second = make_event(), make_event()
    assert first.event_id != second.event_id
    assert OrderEvent("o", first.time, "x", event_id="fixed").event_id == "fixed"
