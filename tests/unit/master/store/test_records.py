"""Store records: times are aware UTC, terminal follows status, headerIds are uint32."""

from __future__ import annotations

import os
import re
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from datetime import UTC, datetime, timedelta, timezone

import pytest

from vda_master.dispatcher import OrderStatus
from vda_master.store import HeaderCounter, OrderEvent
from vda_master.store.records import next_event_id
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


def test_event_ids_stay_distinct_across_threads_and_a_forked_child() -> None:
    """32 hex digits; events made in several threads at once, and in a child process forked
    from this one, never repeat an id (the store appends idempotently per id)."""
    with ThreadPoolExecutor(4) as pool:
        ids = [
            i
            for chunk in pool.map(lambda _: [next_event_id() for _ in range(2000)], range(4))
            for i in chunk
        ]
    assert len(set(ids)) == len(ids)
    assert all(re.fullmatch("[0-9a-f]{32}", i) for i in ids)
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # the child: its next id, then leave at once
        os.write(write, next_event_id().encode())
        os._exit(0)
    os.close(write)
    os.waitpid(child, 0)
    from_child = os.read(read, 64).decode()
    os.close(read)
    ours = next_event_id()
    assert from_child[:16] != ours[:16]  # a prefix of its own
