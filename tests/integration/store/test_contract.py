"""The store contract, the same on every backend: memory, SQLite and PostgreSQL (issue 10)."""

from __future__ import annotations

import asyncio
from dataclasses import replace
from datetime import timedelta, timezone

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import inspect, text
from sqlalchemy.engine import Connection

from tests.integration.store.conftest import Database
from vda_master.store import (
    HeaderCounter,
    JsonValue,
    OutOfServiceRecord,
    SqlStore,
    Store,
    StoreError,
    StoreWriter,
    StoreWriteRejectedError,
    WebhookOutbox,
    WebhookRecord,
    WriteBatch,
    WriterSettings,
    ZoneRecord,
    migrate,
)
from vda_master.store.schema import metadata
from vda_master.store.testing import at, make_event, make_order_record, make_vehicle_record

pytestmark = pytest.mark.integration


def _schema_differences(connection: Connection) -> list[object]:
    differences: list[object] = compare_metadata(MigrationContext.configure(connection), metadata)
    return differences


async def test_migrating_from_empty_gives_the_schema_the_code_uses(sql_database: Database) -> None:
    """Opening an empty database migrates it to the newest revision, matching schema.py."""
    async with sql_database.open() as store:
        assert isinstance(store, SqlStore)
        async with store.engine.connect() as connection:
            revision = await connection.run_sync(migrate.current_revision)
            differences = await connection.run_sync(_schema_differences)
    assert revision == migrate.head_revision()
    assert differences == []


async def test_migrations_go_down_to_empty_and_up_again(sql_database: Database) -> None:
    """Every migration can be undone, and the store opens again on the emptied database."""
    async with sql_database.open() as store:
        assert isinstance(store, SqlStore)
        async with store.engine.begin() as connection:
            await connection.run_sync(
                lambda c: command.downgrade(migrate.alembic_config(c), "base")
            )
            assert await connection.run_sync(migrate.current_revision) is None
    async with sql_database.open() as store:
        await store.write(WriteBatch(orders=(make_order_record(),)))
        assert await store.get_order("order-1") == make_order_record()


async def test_a_database_from_a_newer_master_is_not_touched(sql_database: Database) -> None:
    """A schema revision this code does not know stops the open with a clear error."""
    async with sql_database.open() as store:
        assert isinstance(store, SqlStore)
        async with store.engine.begin() as connection:
            await connection.execute(text("UPDATE alembic_version SET version_num = '9999'"))
    with pytest.raises(StoreError, match=r"schema revision '9999'.*does not know"):
        async with sql_database.open():
            pass


async def test_a_database_at_revision_0001_is_migrated_keeping_its_orders(
    sql_database: Database,
) -> None:
    """A database a master without zones wrote (revision 0001, with an order in it) opens at the
    newest revision with its order intact, and stores zones and vehicles out of service."""
    async with sql_database.open() as store:
        assert isinstance(store, SqlStore)
        async with store.engine.begin() as connection:
            await connection.run_sync(
                lambda c: command.downgrade(migrate.alembic_config(c), "0001")
            )
        async with store.engine.connect() as connection:
            assert await connection.run_sync(migrate.current_revision) == "0001"
            tables = await connection.run_sync(lambda c: set(inspect(c).get_table_names()))
        assert "zones" not in tables
        await store.write(WriteBatch(orders=(make_order_record(status="RUNNING"),)))
    async with sql_database.open() as store:
        assert isinstance(store, SqlStore)
        async with store.engine.connect() as connection:
            assert await connection.run_sync(migrate.current_revision) == migrate.head_revision()
        assert await store.load_open_orders() == (make_order_record(status="RUNNING"),)
        assert await store.load_zones() == ()
        await store.put_zone(_zone("spill"))
        assert await store.load_zones() == (_zone("spill"),)
        assert await store.load_out_of_service() == ()
        await store.put_out_of_service(_out("r1"))
        assert await store.load_out_of_service() == (_out("r1"),)


async def test_every_record_type_round_trips(store: Store) -> None:
    """Orders, events, vehicles and header counters come back exactly as written."""
    order = make_order_record(
        status="RUNNING",
        sent_update_id=2,
        confirmed_update_id=1,
        cancel_action_id="cancel-7",
        reason="because",
        released_end=2,
        update_id=2,
    )
    event = make_event(event="published", header_id=4, order_update_id=2)
    vehicle = make_vehicle_record(factsheet={"typeSpecification": {"seriesName": "x"}})
    counter = HeaderCounter("acme", "robot_0", "order", 41)
    await store.write(
        WriteBatch(orders=(order,), events=(event,), vehicles=(vehicle,), counters=(counter,))
    )
    assert await store.get_order("order-1") == order
    assert await store.order_events("order-1") == (event,)
    assert await store.load_vehicles() == (vehicle,)
    assert await store.load_header_counters() == (counter,)


async def test_json_payloads_keep_unicode_nul_numbers_and_nesting(store: Store) -> None:
    """JSON payloads survive whatever strings and numbers the API or a factsheet carries."""
    request = {
        "text": "Grüße ✓ \u0000 end",
        "numbers": [0, -1, 2**53, 1.5, 1.0, 1e-9],
        "nested": {"empty": {}, "list": [], "null": None, "flag": True},
    }
    await store.write(WriteBatch(orders=(make_order_record(request=request),)))
    stored = await store.get_order("order-1")
    assert stored is not None
    assert stored.request == request
    assert isinstance(stored.request["numbers"], list)
    assert [type(n) for n in stored.request["numbers"]] == [int, int, int, float, float, float]


async def test_times_come_back_as_the_same_instant_in_utc(store: Store) -> None:
    """A time given in another zone is stored as the same instant and read back in UTC."""
    local = at(0).astimezone(timezone(timedelta(hours=2)))
    await store.write(WriteBatch(orders=(make_order_record(created_at=local),)))
    stored = await store.get_order("order-1")
    assert stored is not None
    assert stored.created_at == at(0)
    assert stored.created_at.utcoffset() == timedelta(0)


async def test_an_order_upsert_replaces_the_stored_order(store: Store) -> None:
    """Writing an order again replaces it; there is still one order."""
    first = make_order_record(status="SENT")
    later = replace(first, status="RUNNING", updated_at=at(5), confirmed_update_id=0)
    await store.write(WriteBatch(orders=(first,)))
    await store.write(WriteBatch(orders=(later,)))
    assert await store.get_order("order-1") == later
    assert await store.list_orders() == (later,)


async def test_a_vehicle_upsert_keeps_its_first_sighting(store: Store) -> None:
    """A vehicle written again takes the new values but keeps the first first_seen."""
    await store.write(WriteBatch(vehicles=(make_vehicle_record(first_seen=at(0)),)))
    later = make_vehicle_record(
        first_seen=at(100), last_seen=at(100), connection_state="OFFLINE", factsheet={"a": 1}
    )
    await store.write(WriteBatch(vehicles=(later,)))
    assert await store.load_vehicles() == (replace(later, first_seen=at(0)),)


async def test_a_header_counter_upsert_replaces_even_a_smaller_value(store: Store) -> None:
    """Counters keep the last value written, also when the uint32 headerId wrapped to 0."""
    key = ("acme", "robot_0", "order")
    await store.write(WriteBatch(counters=(HeaderCounter(*key, 2**32 - 1),)))
    await store.write(WriteBatch(counters=(HeaderCounter(*key, 0),)))
    await store.write(WriteBatch(counters=(HeaderCounter("acme", "robot_0", "instantActions", 3),)))
    assert await store.load_header_counters() == (
        HeaderCounter("acme", "robot_0", "instantActions", 3),
        HeaderCounter(*key, 0),
    )


async def test_list_orders_filters_and_returns_the_newest_first(store: Store) -> None:
    """Filters combine; results are newest first and cut at the limit."""
    orders = [
        make_order_record("o1", serial_number="r1", status="FINISHED", created_at=at(1)),
        make_order_record("o2", serial_number="r2", status="RUNNING", created_at=at(2)),
        make_order_record("o3", serial_number="r1", status="RUNNING", created_at=at(3)),
        make_order_record("o4", manufacturer="other", serial_number="r1", created_at=at(4)),
    ]
    await store.write(WriteBatch(orders=tuple(orders)))

    async def ids(**filters: object) -> list[str]:
        return [o.order_id for o in await store.list_orders(**filters)]  # type: ignore[arg-type]

    assert await ids() == ["o4", "o3", "o2", "o1"]
    assert await ids(limit=2) == ["o4", "o3"]
    assert await ids(status="RUNNING") == ["o3", "o2"]
    assert await ids(serial_number="r1") == ["o4", "o3", "o1"]
    assert await ids(manufacturer="acme", serial_number="r1") == ["o3", "o1"]
    assert await ids(manufacturer="acme", serial_number="r1", status="FINISHED") == ["o1"]
    assert await ids(status="CANCELLED") == []


async def test_orders_created_at_the_same_time_list_the_last_written_first(store: Store) -> None:
    """Ties on created_at are broken by the order in which the orders were first written."""
    for order_id in ("b", "a", "c"):
        await store.write(WriteBatch(orders=(make_order_record(order_id, created_at=at(0)),)))
    await store.write(WriteBatch(orders=(make_order_record("b", created_at=at(0), status="X"),)))
    assert [o.order_id for o in await store.list_orders()] == ["c", "a", "b"]


async def test_list_orders_refuses_a_limit_out_of_range(store: Store) -> None:
    """A limit below 1 or above 10,000 is a programming error."""
    with pytest.raises(ValueError, match="limit"):
        await store.list_orders(limit=0)
    with pytest.raises(ValueError, match="limit"):
        await store.list_orders(limit=10_001)


async def test_an_unknown_order_is_none_and_has_no_events(store: Store) -> None:
    """Asking for an order never stored gives None and an empty history."""
    assert await store.get_order("nope") is None
    assert await store.order_events("nope") == ()


async def test_events_come_back_in_time_order_then_written_order(store: Store) -> None:
    """An order's events are sorted by time; events at the same time keep their written order."""
    late, early = make_event(event="late", time=at(9)), make_event(event="early", time=at(1))
    same = [make_event(event=f"same-{i}", time=at(5)) for i in range(3)]
    other = make_event("order-2", event="other", time=at(2))
    await store.write(WriteBatch(events=(late, same[0], other)))
    await store.write(WriteBatch(events=(same[1], early, same[2])))
    assert await store.order_events("order-1") == (early, *same, late)
    assert await store.order_events("order-2") == (other,)


async def test_an_event_written_twice_is_kept_once(store: Store) -> None:
    """Appending is idempotent per event_id, so a retried batch never doubles history."""
    event = make_event()
    await store.write(WriteBatch(events=(event,)))
    await store.write(WriteBatch(events=(event, make_event(event="next", time=at(1)))))
    assert [e.event for e in await store.order_events("order-1")] == ["created", "next"]


async def test_open_orders_are_the_non_terminal_ones_oldest_first(store: Store) -> None:
    """Recovery loads every order that is not FINISHED, FAILED, REJECTED or CANCELLED."""
    statuses = ["RUNNING", "FINISHED", "SENT", "FAILED", "ACCEPTED", "REJECTED", "CANCELLED"]
    orders = [
        make_order_record(f"o{i}", status=status, created_at=at(10 - i))
        for i, status in enumerate(statuses)
    ]
    await store.write(WriteBatch(orders=tuple(orders)))
    open_orders = await store.load_open_orders()
    assert [o.order_id for o in open_orders] == ["o4", "o2", "o0"]
    assert not any(o.terminal for o in open_orders)
    finished = replace(orders[4], status="FINISHED")
    await store.write(WriteBatch(orders=(finished,)))
    assert [o.order_id for o in await store.load_open_orders()] == ["o2", "o0"]


async def test_prune_deletes_old_terminal_orders_with_their_events(store: Store) -> None:
    """Prune removes terminal orders updated before the cut-off, and only those."""
    orders = (
        make_order_record("old-done", status="FINISHED", updated_at=at(10)),
        make_order_record("old-open", status="RUNNING", updated_at=at(10)),
        make_order_record("new-done", status="CANCELLED", updated_at=at(30)),
    )
    events = tuple(make_event(o.order_id) for o in orders)
    await store.write(WriteBatch(orders=orders, events=events))
    assert await store.prune(at(20)) == 1
    assert await store.get_order("old-done") is None
    assert await store.order_events("old-done") == ()
    assert {o.order_id for o in await store.list_orders()} == {"old-open", "new-done"}
    assert len(await store.order_events("old-open")) == 1
    assert await store.prune(at(20)) == 0


async def test_a_refused_batch_writes_nothing(store: Store) -> None:
    """A batch is one transaction: when one record cannot be stored, none of it is."""
    poison = make_event(event="poison", too_big=2**70)  # beyond 64-bit JSON integers
    batch = WriteBatch(
        orders=(make_order_record(),),
        events=(make_event(), poison),
        vehicles=(make_vehicle_record(),),
        counters=(HeaderCounter("acme", "robot_0", "order", 1),),
    )
    with pytest.raises(StoreWriteRejectedError):
        await store.write(batch)
    assert await store.get_order("order-1") is None
    assert await store.order_events("order-1") == ()
    assert await store.load_vehicles() == ()
    assert await store.load_header_counters() == ()


async def test_a_reopened_store_sees_everything(database: Database) -> None:
    """Closing and opening the same database again loses nothing (what a restart relies on)."""
    order, event = make_order_record(status="RUNNING"), make_event()
    vehicle, counter = make_vehicle_record(), HeaderCounter("acme", "robot_0", "order", 9)
    async with database.open() as store:
        batch = WriteBatch(
            orders=(order,), events=(event,), vehicles=(vehicle,), counters=(counter,)
        )
        await store.write(batch)
    async with database.open() as store:
        assert await store.load_open_orders() == (order,)
        assert await store.order_events("order-1") == (event,)
        assert await store.load_vehicles() == (vehicle,)
        assert await store.load_header_counters() == (counter,)


async def test_the_writer_merges_concurrent_submissions(store: Store) -> None:
    """Many tasks submitting at once: after flush everything is there, each order at its last
    submitted version, in a handful of transactions."""
    writer = StoreWriter(store, WriterSettings(flush_interval_s=0.01))
    orders, events_per_order = 20, 10

    async def drive(order_id: str) -> None:
        for step in range(events_per_order):
            record = make_order_record(order_id, status=f"STEP-{step}", updated_at=at(step))
            writer.submit(
                WriteBatch(orders=(record,), events=(make_event(order_id, f"e{step}", at(step)),))
            )
            await asyncio.sleep(0)

    async with asyncio.TaskGroup() as tg:
        loop = tg.create_task(writer.flush_loop(), name="test.store_flush_loop")
        async with asyncio.TaskGroup() as drivers:
            for i in range(orders):
                drivers.create_task(drive(f"o{i}"), name=f"test.drive_{i}")
        await writer.flush(timeout_s=10)
        await writer.close()
        await loop
    listed = await store.list_orders(limit=100)
    assert len(listed) == orders
    assert {o.status for o in listed} == {f"STEP-{events_per_order - 1}"}
    for i in range(orders):
        events = await store.order_events(f"o{i}")
        assert [e.event for e in events] == [f"e{s}" for s in range(events_per_order)]


async def test_write_ahead_is_durable_when_it_returns(database: Database) -> None:
    """Once write_ahead returns, another store opened on the same database sees the batch
    and everything submitted before it."""
    async with database.open() as store:
        writer = StoreWriter(store, WriterSettings(flush_interval_s=60))
        writer.submit(WriteBatch(events=(make_event(event="before"),)))
        await writer.write_ahead(WriteBatch(orders=(make_order_record(),)), timeout_s=10)
        async with database.open() as other:
            assert await other.get_order("order-1") == make_order_record()
            assert [e.event for e in await other.order_events("order-1")] == ["before"]
        await writer.close()


def _zone(zone_id: str, created: float = 0, **fields: JsonValue) -> ZoneRecord:
    document: dict[str, JsonValue] = {
        "zoneId": zone_id,
        "zoneType": "BLOCKED",
        "vertices": [{"x": 0.0, "y": 0.0}, {"x": 2.0, "y": 0.0}, {"x": 2.0, "y": 1.5}],
        "maximumSpeed": 0.5,
        "mapId": "m",
        "description": "",
        **fields,
    }
    return ZoneRecord(zone_id, document, at(created))


async def test_a_zone_put_is_loaded_back_as_written(store: Store) -> None:
    """A zone comes back with the same document, and its creation time as the same instant in
    UTC."""
    local = at(7).astimezone(timezone(timedelta(hours=-5)))
    zone = ZoneRecord("spill", _zone("spill", description="Grüße \u0000 ✓").document, local)
    await store.put_zone(zone)
    loaded = await store.load_zones()
    assert loaded == (zone,)
    assert loaded[0].created_at == at(7)
    assert loaded[0].created_at.utcoffset() == timedelta(0)


async def test_putting_a_zone_again_replaces_it(store: Store) -> None:
    """A put with a stored zone_id replaces that zone's document; there is still one of it."""
    await store.put_zone(_zone("spill", 0))
    await store.put_zone(_zone("dock", 1))
    changed = _zone("spill", 0, zoneType="SPEED_LIMIT", maximumSpeed=0.2)
    await store.put_zone(changed)
    assert await store.load_zones() == (changed, _zone("dock", 1))


async def test_deleting_a_zone_says_whether_it_was_stored(store: Store) -> None:
    """Delete removes the zone and returns True; deleting it again (or a zone never put) gives
    False; other zones stay."""
    await store.put_zone(_zone("spill"))
    await store.put_zone(_zone("dock"))
    assert await store.delete_zone("spill") is True
    assert await store.delete_zone("spill") is False
    assert await store.delete_zone("never") is False
    assert await store.load_zones() == (_zone("dock"),)


async def test_zones_load_oldest_first_then_in_the_order_first_put(store: Store) -> None:
    """Zones are sorted by created_at; zones created at the same time keep the order in which
    they were first put, also after one of them is replaced."""
    for zone_id, created in (("late", 9), ("b", 5), ("early", 1), ("a", 5), ("c", 5)):
        await store.put_zone(_zone(zone_id, created))
    await store.put_zone(_zone("b", 5, description="changed"))
    assert [z.zone_id for z in await store.load_zones()] == ["early", "b", "a", "c", "late"]


async def test_a_refused_zone_is_not_stored(store: Store) -> None:
    """A document the database cannot hold is refused, and neither stored nor replacing the
    stored one."""
    await store.put_zone(_zone("spill"))
    with pytest.raises(StoreWriteRejectedError):
        await store.put_zone(_zone("spill", description=2**70))
    with pytest.raises(StoreWriteRejectedError):
        await store.put_zone(_zone("other", description=2**70))
    assert await store.load_zones() == (_zone("spill"),)


async def test_zones_are_durable_and_survive_a_reopen(database: Database) -> None:
    """Once put_zone returns another store on the same database sees the zone, and closing and
    opening the database again loses no zone (nor a deletion)."""
    async with database.open() as store:
        await store.put_zone(_zone("spill", 2))
        await store.put_zone(_zone("dock", 1))
        await store.put_zone(_zone("gone", 3))
        assert await store.delete_zone("gone")
        async with database.open() as other:
            assert await other.load_zones() == (_zone("dock", 1), _zone("spill", 2))
    async with database.open() as store:
        assert await store.load_zones() == (_zone("dock", 1), _zone("spill", 2))


def _out(serial: str, note: str = "brakes", since: float = 0) -> OutOfServiceRecord:
    return OutOfServiceRecord("acme", serial, note, at(since))


async def test_vehicles_out_of_service_are_kept_replaced_and_put_back(database: Database) -> None:
    """A vehicle marked out of service comes back with its note and time (in UTC), by
    manufacturer and serial number; a second mark replaces the first; putting it back says
    whether it was out; the marks survive closing and opening the database."""
    local = at(5).astimezone(timezone(timedelta(hours=3)))
    async with database.open() as store:
        assert await store.load_out_of_service() == ()
        await store.put_out_of_service(_out("r2", "scanner: Grüße ✓", 1))
        await store.put_out_of_service(OutOfServiceRecord("acme", "r1", "", local))
        await store.put_out_of_service(_out("r2", "scanner and brakes", 1))
        await store.put_out_of_service(_out("r3"))
        assert await store.delete_out_of_service("acme", "r3") is True
        assert await store.delete_out_of_service("acme", "r3") is False
        assert await store.delete_out_of_service("other", "r1") is False
    async with database.open() as store:
        loaded = await store.load_out_of_service()
        assert loaded == (_out("r1", "", 5), _out("r2", "scanner and brakes", 1))
        assert loaded[0].since.utcoffset() == timedelta(0)


async def test_zone_puts_alongside_batch_writes_all_land(store: Store) -> None:
    """Zone puts and deletes running while batches are written (the writer thread and inline
    writes on SQLite) all take effect."""
    await store.put_zone(_zone("doomed"))

    async def batches() -> None:
        for i in range(20):
            await store.write(WriteBatch(orders=(make_order_record(f"o{i}"),)))

    async with asyncio.timeout(30), asyncio.TaskGroup() as tg:
        tg.create_task(batches(), name="test.batches")
        tg.create_task(store.delete_zone("doomed"), name="test.delete_zone")
        for i in range(20):
            tg.create_task(store.put_zone(_zone(f"z{i}", i)), name=f"test.put_zone_{i}")
    assert [z.zone_id for z in await store.load_zones()] == [f"z{i}" for i in range(20)]
    assert len(await store.list_orders()) == 20


def _hook(url: str, event_id: int, created: float = 0) -> WebhookRecord:
    return WebhookRecord(url, event_id, f'{{"eventId": {event_id}, "text": "Grüße"}}', at(created))


async def test_webhook_events_are_kept_until_done_and_their_ids_go_on(database: Database) -> None:
    """Events added are loaded back in the order added (each (url, eventId) once) until they
    are done; the last eventId given out never goes down; all of it survives a reopen."""
    async with database.open() as store:
        assert await store.load_webhook_outbox() == WebhookOutbox((), 0)
        a1, b1, a2 = _hook("http://a/", 1), _hook("http://b/", 1), _hook("http://a/", 2, 1)
        await store.save_webhook_events([a1, b1, a2], [], 2)
        await store.save_webhook_events([a1], [("http://b/", 1), ("http://c/", 9)], 1)
        assert await store.load_webhook_outbox() == WebhookOutbox((a1, a2), 2)
        a3 = _hook("http://a/", 3, 2)
        await store.save_webhook_events([a3], [("http://a/", 1)], 3)
    async with database.open() as store:
        outbox = await store.load_webhook_outbox()
        assert outbox == WebhookOutbox((a2, a3), 3)
        assert outbox.events[0].body == a2.body
        await store.save_webhook_events([], [("http://a/", 2), ("http://a/", 3)], 3)
        assert await store.load_webhook_outbox() == WebhookOutbox((), 3)
