"""Merging pending write batches (the writer's pure core, issue 10)."""

from __future__ import annotations

from vda_master.store import HeaderCounter, WriteBatch, merge_batches
from vda_master.store.batch import PendingWrites, split_batch
from vda_master.store.testing import at, make_event, make_order_record, make_vehicle_record


def test_a_later_order_upsert_replaces_an_earlier_one() -> None:
    """Only the newest version of an order is written; other orders stay."""
    first, second = make_order_record(status="SENT"), make_order_record(status="RUNNING")
    other = make_order_record("order-2")
    merged = merge_batches(WriteBatch(orders=(first, other)), WriteBatch(orders=(second,)))
    assert merged.orders == (other, second)


def test_events_accumulate_in_submission_order_once_each() -> None:
    """Events are appended in the order submitted; the same event twice is kept once."""
    a, b, c = (make_event(event=name) for name in "abc")
    merged = merge_batches(WriteBatch(events=(a, b)), WriteBatch(events=(c, a)))
    assert merged.events == (a, b, c)


def test_vehicles_and_counters_keep_their_latest_value() -> None:
    """Vehicle and header-counter upserts merge by key, the latest winning (even a wrap to 0)."""
    old, new = make_vehicle_record(last_seen=at(1)), make_vehicle_record(last_seen=at(2))
    merged = merge_batches(
        WriteBatch(vehicles=(old,), counters=(HeaderCounter("m", "s", "order", 7),)),
        WriteBatch(vehicles=(new,), counters=(HeaderCounter("m", "s", "order", 0),)),
    )
    assert merged.vehicles == (new,)
    assert merged.counters == (HeaderCounter("m", "s", "order", 0),)


def test_a_failed_batch_put_back_is_older_than_what_came_since() -> None:
    """A batch put back after a failed write loses to newer order versions queued meanwhile,
    and its events come first."""
    pending = PendingWrites()
    pending.add(WriteBatch(orders=(make_order_record(status="SENT"),), events=(make_event(),)))
    taken = pending.take()
    assert len(pending) == 0
    newer = make_order_record(status="RUNNING")
    later_event = make_event(event="later")
    pending.add(WriteBatch(orders=(newer,), events=(later_event,)))
    pending.add_older(taken)
    assert pending.peek() == WriteBatch(orders=(newer,), events=(*taken.events, later_event))


def test_dropping_the_oldest_events_keeps_the_newest() -> None:
    """Bounding the queue drops the oldest events and returns them; orders are untouched."""
    pending = PendingWrites()
    events = [make_event(event=f"e{i}") for i in range(5)]
    pending.add(WriteBatch(orders=(make_order_record(),), events=tuple(events)))
    assert pending.drop_oldest_events(keep=2) == events[:3]
    assert pending.peek().events == tuple(events[3:])
    assert len(pending.peek().orders) == 1
    assert pending.event_count == 2


def test_a_batch_splits_into_single_records_with_their_keys() -> None:
    """Splitting gives one batch per record, keyed so a refused record can be named."""
    order, event = make_order_record(), make_event()
    vehicle, counter = make_vehicle_record(), HeaderCounter("acme", "robot_0", "order", 1)
    batch = WriteBatch(orders=(order,), events=(event,), vehicles=(vehicle,), counters=(counter,))
    parts = split_batch(batch)
    assert [key for key, _ in parts] == [
        ("order", "order-1"),
        ("event", event.event_id),
        ("vehicle", "acme", "robot_0"),
        ("counter", "acme", "robot_0", "order"),
    ]
    assert all(part.size == 1 for _, part in parts)
    assert merge_batches(*(part for _, part in parts)) == batch
    assert batch.keys() == frozenset(key for key, _ in parts)
    assert WriteBatch().empty
