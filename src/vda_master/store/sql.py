"""The SQL store: one implementation of :class:`~vda_master.store.interface.Store` for SQLite
(embedded, aiosqlite) and PostgreSQL (asyncpg), on SQLAlchemy Core's asyncio engine.

The two backends differ only in how the engine is made (SQLite pragmas, PostgreSQL pool and
timeouts) and in which dialect's ``INSERT … ON CONFLICT`` builds the upserts; every query is the
same, which is why one class serves both and one contract test suite checks both.

Database I/O never blocks the event loop: aiosqlite runs SQLite in its own thread and asyncpg is
asynchronous. SQLite writes take one more way: a synchronous engine on the same file in a
thread of their own, so that a write (BEGIN, a statement per table, COMMIT) costs the event loop
one hand-over instead of one per statement; with the loop busy, each hand-over waited its turn,
and the write-ahead of an order waited for all of them (docs/performance.md, lever 22). That
thread sends each statement's rows to the driver itself, after SQLAlchemy's own bind processors
(lever 28).

A small SQLite write (at most :data:`_INLINE_MAX_RECORDS` records: the write-aheads of a burst of
orders) runs on the event loop itself, while such writes commit within :data:`_INLINE_MAX_S`. In
the thread, each of its GIL hand-overs (BEGIN, every row of a statement, COMMIT) waited for the
busy loop to let go: 20-30 ms for a write-ahead of 30 orders during a burst, which SQLite does
in 1-2 ms (docs/performance.md, lever 50). A slower commit (a slow disk) sends every write to the
thread again for :data:`_INLINE_PAUSE_S`, so the loop waits on such a disk once per pause at most.
An inline write never waits for another connection's lock: a locked database fails it at once,
and the write goes to the thread (which waits up to ``busy_timeout``), as do the next ones.

Driver and SQLAlchemy exceptions never leave this module: they become
:class:`StoreUnavailableError` (try again later) or :class:`StoreWriteRejectedError` (the data
itself was refused).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import asynccontextmanager
from dataclasses import dataclass
from datetime import datetime
from operator import attrgetter
from pathlib import Path
from types import TracebackType
from typing import Any, Self, TypeVar

import orjson
import structlog
from sqlalchemy import (
    Insert,
    Row,
    Select,
    bindparam,
    create_engine,
    delete,
    event,
    false,
    func,
    select,
    true,
)
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.engine import Connection, Dialect, Engine
from sqlalchemy.exc import (
    DataError,
    DBAPIError,
    IntegrityError,
    OperationalError,
    SQLAlchemyError,
    StatementError,
)
from sqlalchemy.ext.asyncio import AsyncEngine, create_async_engine
from sqlalchemy.pool import ConnectionPoolEntry

from vda_master.store import migrate
from vda_master.store.batch import WriteBatch
from vda_master.store.errors import StoreUnavailableError, StoreWriteRejectedError
from vda_master.store.interface import DEFAULT_LIST_LIMIT, check_limit
from vda_master.store.records import (
    HeaderCounter,
    OrderEvent,
    OrderRecord,
    OutOfServiceRecord,
    VehicleRecord,
    WebhookOutbox,
    WebhookRecord,
    ZoneRecord,
)
from vda_master.store.schema import (
    header_counters,
    order_events,
    orders,
    out_of_service,
    vehicles,
    webhook_counter,
    webhook_outbox,
    zones,
)
from vda_master.store.urls import Backend, DatabaseTarget, resolve_database_url

log = structlog.get_logger()

#: How long a write waits for another connection's lock (the writer thread; inline writes do not).
_BUSY_TIMEOUT_MS = 5000
#: WAL lets readers (the API) run while the writer commits; synchronous=FULL makes a commit
#: survive a power cut too, which write-ahead needs; batching keeps the fsyncs few.
_SQLITE_PRAGMAS = (
    "PRAGMA journal_mode=WAL",
    "PRAGMA synchronous=FULL",
    f"PRAGMA busy_timeout={_BUSY_TIMEOUT_MS}",
)
#: SQLite writes of at most this many records run on the event loop (module docstring)...
_INLINE_MAX_RECORDS = 200
#: ...while each commits within this many seconds; a slower one sends them to the writer thread
#: for _INLINE_PAUSE_S.
_INLINE_MAX_S = 0.02
_INLINE_PAUSE_S = 30.0
#: Columns an upsert leaves as stored.
_KEEP_ON_UPDATE = {"orders": {"seq", "order_id"}, "vehicles": {"first_seen"}, "zones": {"seq"}}


def open_store(
    database_url: str | None, data_dir: Path, *, connect_timeout_s: float = 5.0
) -> SqlStore:
    """The store ``database_url`` names (None: ``<data_dir>/master.sqlite3``), not yet open.

    Use it as ``async with open_store(url, data_dir) as store: ...``.

    Raises:
        ConfigError: the URL is malformed or names an unsupported database.
    """
    return SqlStore(resolve_database_url(database_url, data_dir), connect_timeout_s)


class SqlStore:
    """The store on SQLite or PostgreSQL (see the module docstring)."""

    def __init__(self, target: DatabaseTarget, connect_timeout_s: float = 5.0) -> None:
        self.target = target
        self._connect_timeout_s = connect_timeout_s
        self._engine: AsyncEngine | None = None
        #: SQLite only: the engine and the thread that write (module docstring).
        self._write_engine: Engine | None = None
        self._write_thread: ThreadPoolExecutor | None = None
        self._driver_writes: _DriverWrites | None = None
        self._inline_after = 0.0  # SQLite: small writes run inline from this monotonic time on
        dialect_insert = sqlite.insert if target.backend == Backend.SQLITE else postgresql.insert
        self._upsert_orders = _upsert(dialect_insert(orders), ["order_id"])
        self._upsert_vehicles = _upsert(dialect_insert(vehicles), ["manufacturer", "serial_number"])
        self._upsert_counters = _upsert(
            dialect_insert(header_counters), ["manufacturer", "serial_number", "topic"]
        )
        self._append_events = dialect_insert(order_events).on_conflict_do_nothing(
            index_elements=["event_id"]
        )
        self._upsert_zones = _upsert(dialect_insert(zones), ["zone_id"])
        self._upsert_out_of_service = _upsert(
            dialect_insert(out_of_service), ["manufacturer", "serial_number"]
        )
        self._append_webhook_events = dialect_insert(webhook_outbox).on_conflict_do_nothing(
            index_elements=["url", "event_id"]
        )
        self._delete_webhook_event = delete(webhook_outbox).where(
            webhook_outbox.c.url == bindparam("done_url"),
            webhook_outbox.c.event_id == bindparam("done_id"),
        )
        counter = dialect_insert(webhook_counter)
        self._raise_webhook_counter = counter.on_conflict_do_update(
            index_elements=["id"],
            set_={
                "last_event_id": func.max(
                    counter.excluded.last_event_id, webhook_counter.c.last_event_id
                )
                if target.backend == Backend.SQLITE
                else func.greatest(counter.excluded.last_event_id, webhook_counter.c.last_event_id)
            },
        )

    async def __aenter__(self) -> Self:
        if self.target.sqlite_path is not None:
            async with self._translated("create the data directory"):
                await asyncio.to_thread(
                    self.target.sqlite_path.parent.mkdir, parents=True, exist_ok=True
                )
        self._engine = _create_engine(self.target, self._connect_timeout_s)
        try:
            async with self._translated("open the store"), self._engine.begin() as connection:
                migration = await connection.run_sync(migrate.upgrade_to_head)
        except BaseException:
            await self._engine.dispose()
            self._engine = None
            raise
        if self.target.backend == Backend.SQLITE:
            self._write_engine = _create_write_engine(self.target)
            self._write_thread = ThreadPoolExecutor(1, thread_name_prefix="store-writer")
            self._driver_writes = _DriverWrites(
                self._write_engine.dialect,
                orders=self._upsert_orders,
                events=self._append_events,
                vehicles=self._upsert_vehicles,
                counters=self._upsert_counters,
            )
        log.info(
            "store.opened",
            backend=self.target.backend.value,
            where=self.target.where,
            revision=migration.after,
            migrated_from=migration.before if migration.before != migration.after else None,
        )
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if self._write_engine is not None and self._write_thread is not None:
            # Disposed in its own thread: sqlite3 connections belong to the thread that made them.
            await asyncio.get_running_loop().run_in_executor(
                self._write_thread, self._write_engine.dispose
            )
            self._write_thread.shutdown()
            self._write_engine = self._write_thread = None
        if self._engine is not None:
            await self._engine.dispose()
            self._engine = None

    @property
    def engine(self) -> AsyncEngine:
        if self._engine is None:
            msg = "the store is not open: use it as `async with store:`"
            raise RuntimeError(msg)
        return self._engine

    async def write(self, batch: WriteBatch) -> None:
        if batch.empty:
            return
        async with self._translated("write"):
            if self._write_engine is not None:
                if (
                    batch.size <= _INLINE_MAX_RECORDS
                    and time.monotonic() >= self._inline_after
                    and self._written_inline(batch)
                ):
                    return
                loop = asyncio.get_running_loop()
                await loop.run_in_executor(self._write_thread, self._write_sqlite, batch)
                return
            async with self.engine.begin() as connection:
                await connection.run_sync(self._write_rows, batch)

    def _written_inline(self, batch: WriteBatch) -> bool:
        """SQLite: ``batch`` written on the event loop (module docstring); False when the
        database was locked or failed, and the writer thread is to try. A failure or a slow
        commit sends writes to the thread for a while."""
        started = time.monotonic()
        try:
            self._write_sqlite(batch, wait_for_locks=False)
        except OperationalError as exc:
            self._pause_inline(_reason(exc))
            return False
        took = time.monotonic() - started
        if took > _INLINE_MAX_S:
            self._pause_inline(f"a commit took {took * 1000:.1f} ms ({batch.size} records)")
        return True

    def _pause_inline(self, why: str) -> None:
        self._inline_after = time.monotonic() + _INLINE_PAUSE_S
        log.info(
            "store.inline_writes_paused",
            reason=why,
            consequence=f"writes go through the writer thread for {_INLINE_PAUSE_S:.0f} s",
        )

    def _write_sqlite(self, batch: WriteBatch, *, wait_for_locks: bool = True) -> None:
        """SQLite: ``batch`` in one transaction (in the writer thread, or inline, where a lock
        held by another connection fails it at once)."""
        assert self._write_engine is not None  # noqa: S101 - only called when it is
        assert self._driver_writes is not None  # noqa: S101 - made with the engine
        with self._write_engine.begin() as connection:
            if wait_for_locks:
                self._driver_writes.write(connection, batch)
                return
            connection.exec_driver_sql("PRAGMA busy_timeout=0")
            try:
                self._driver_writes.write(connection, batch)
            finally:
                connection.exec_driver_sql(f"PRAGMA busy_timeout={_BUSY_TIMEOUT_MS}")

    def _write_rows(self, connection: Connection, batch: WriteBatch) -> None:
        """The statements of a write, one per kind of record, in the caller's transaction."""
        statements: tuple[_WithRows, _WithRows, _WithRows, _WithRows] = (
            (self._upsert_orders, _order_row),
            (self._append_events, _event_row),
            (self._upsert_vehicles, _vehicle_row),
            (self._upsert_counters, _counter_row),
        )
        for (statement, as_row), records in _records_per_statement(statements, batch):
            connection.execute(statement, [as_row(record) for record in records])

    async def load_open_orders(self) -> tuple[OrderRecord, ...]:
        query = select(orders).where(orders.c.terminal == false())
        rows = await self._fetch(query.order_by(orders.c.created_at, orders.c.seq))
        return tuple(_order_record(row) for row in rows)

    async def get_order(self, order_id: str) -> OrderRecord | None:
        rows = await self._fetch(select(orders).where(orders.c.order_id == order_id))
        return _order_record(rows[0]) if rows else None

    async def list_orders(
        self,
        *,
        status: str | None = None,
        manufacturer: str | None = None,
        serial_number: str | None = None,
        limit: int = DEFAULT_LIST_LIMIT,
    ) -> tuple[OrderRecord, ...]:
        check_limit(limit)
        query = select(orders)
        for column, value in (
            (orders.c.status, status),
            (orders.c.manufacturer, manufacturer),
            (orders.c.serial_number, serial_number),
        ):
            if value is not None:
                query = query.where(column == value)
        query = query.order_by(orders.c.created_at.desc(), orders.c.seq.desc()).limit(limit)
        return tuple(_order_record(row) for row in await self._fetch(query))

    async def order_events(self, order_id: str) -> tuple[OrderEvent, ...]:
        query = select(order_events).where(order_events.c.order_id == order_id)
        rows = await self._fetch(query.order_by(order_events.c.time, order_events.c.seq))
        return tuple(_event_record(row) for row in rows)

    async def load_vehicles(self) -> tuple[VehicleRecord, ...]:
        query = select(vehicles).order_by(vehicles.c.manufacturer, vehicles.c.serial_number)
        return tuple(_vehicle_record(row) for row in await self._fetch(query))

    async def load_header_counters(self) -> tuple[HeaderCounter, ...]:
        columns = header_counters.c
        query = select(header_counters).order_by(
            columns.manufacturer, columns.serial_number, columns.topic
        )
        return tuple(_counter_record(row) for row in await self._fetch(query))

    async def prune(self, before: datetime) -> int:
        doomed = select(orders.c.order_id).where(
            orders.c.terminal == true(), orders.c.updated_at < before
        )
        async with self._translated("prune"), self.engine.begin() as connection:
            await connection.execute(
                delete(order_events).where(order_events.c.order_id.in_(doomed))
            )
            result = await connection.execute(delete(orders).where(orders.c.order_id.in_(doomed)))
        deleted: int = result.rowcount
        if deleted:
            log.info("store.pruned", orders=deleted, before=before.isoformat())
        return deleted

    # Zone writes go as prune does, on a connection of the async engine: on SQLite the database
    # lock (busy_timeout) serialises them with the batch writes.
    async def put_zone(self, record: ZoneRecord) -> None:
        async with self._translated("store a zone"), self.engine.begin() as connection:
            await connection.execute(self._upsert_zones, _zone_row(record))

    async def delete_zone(self, zone_id: str) -> bool:
        query = delete(zones).where(zones.c.zone_id == zone_id)
        async with self._translated("delete a zone"), self.engine.begin() as connection:
            result = await connection.execute(query)
        deleted: int = result.rowcount
        return deleted > 0

    async def load_zones(self) -> tuple[ZoneRecord, ...]:
        rows = await self._fetch(select(zones).order_by(zones.c.created_at, zones.c.seq))
        return tuple(_zone_record(row) for row in rows)

    async def put_out_of_service(self, record: OutOfServiceRecord) -> None:
        row = {
            "manufacturer": record.manufacturer,
            "serial_number": record.serial_number,
            "note": record.note,
            "since": record.since,
        }
        async with self._translated("mark a vehicle out of service"), self.engine.begin() as c:
            await c.execute(self._upsert_out_of_service, row)

    async def delete_out_of_service(self, manufacturer: str, serial_number: str) -> bool:
        query = delete(out_of_service).where(
            out_of_service.c.manufacturer == manufacturer,
            out_of_service.c.serial_number == serial_number,
        )
        async with self._translated("put a vehicle back in service"), self.engine.begin() as c:
            result = await c.execute(query)
        deleted: int = result.rowcount
        return deleted > 0

    async def load_out_of_service(self) -> tuple[OutOfServiceRecord, ...]:
        columns = out_of_service.c
        rows = await self._fetch(
            select(out_of_service).order_by(columns.manufacturer, columns.serial_number)
        )
        return tuple(
            OutOfServiceRecord(row.manufacturer, row.serial_number, row.note, row.since)
            for row in rows
        )

    async def save_webhook_events(
        self,
        added: Sequence[WebhookRecord],
        done: Sequence[tuple[str, int]],
        last_event_id: int,
    ) -> None:
        if added or done:
            async with self._translated("keep webhook events"), self.engine.begin() as c:
                if added:
                    await c.execute(self._append_webhook_events, [_webhook_row(r) for r in added])
                if done:
                    rows = [{"done_url": u, "done_id": i} for u, i in done]
                    await c.execute(self._delete_webhook_event, rows)
                await c.execute(
                    self._raise_webhook_counter, {"id": 1, "last_event_id": last_event_id}
                )

    async def load_webhook_outbox(self) -> WebhookOutbox:
        rows = await self._fetch(select(webhook_outbox).order_by(webhook_outbox.c.seq))
        counter = await self._fetch(select(webhook_counter.c.last_event_id))
        return WebhookOutbox(
            events=tuple(
                WebhookRecord(row.url, row.event_id, row.body, row.created_at) for row in rows
            ),
            last_event_id=counter[0].last_event_id if counter else 0,
        )

    async def _fetch(self, query: Select[Any]) -> Sequence[Row[Any]]:
        async with self._translated("read"), self.engine.connect() as connection:
            result = await connection.execute(query)
            rows: Sequence[Row[Any]] = result.all()
            return rows

    @asynccontextmanager
    async def _translated(self, doing: str) -> AsyncIterator[None]:
        """Turn driver and SQLAlchemy errors into the store's own (see the module docstring)."""
        where = f"{self.target.where} ({self.target.backend.value})"
        try:
            yield
        except (IntegrityError, DataError) as exc:
            msg = f"the database at {where} refused to {doing}: {_reason(exc)}"
            raise StoreWriteRejectedError(msg) from exc
        except StatementError as exc:
            if isinstance(exc, DBAPIError):
                msg = f"cannot {doing} at {where}: {_reason(exc)}"
                raise StoreUnavailableError(msg) from exc
            msg = f"cannot {doing} at {where}: a value cannot be stored: {_reason(exc)}"
            raise StoreWriteRejectedError(msg) from exc
        except (SQLAlchemyError, OSError) as exc:  # OSError covers refused and timed-out connects
            msg = f"cannot {doing} at {where}: {_reason(exc)}"
            raise StoreUnavailableError(msg) from exc


def _reason(exc: BaseException) -> str:
    """The driver's own message, without SQLAlchemy's statement dump."""
    cause = exc.orig if isinstance(exc, StatementError) and exc.orig is not None else exc
    text = str(cause).strip() or type(cause).__name__
    return text.splitlines()[0]


def _upsert(statement: sqlite.Insert | postgresql.Insert, keys: list[str]) -> Insert:
    keep = {*keys, *_KEEP_ON_UPDATE.get(statement.table.name, ())}
    update = {c.name: statement.excluded[c.name] for c in statement.table.c if c.name not in keep}
    return statement.on_conflict_do_update(index_elements=keys, set_=update)


def _create_engine(target: DatabaseTarget, connect_timeout_s: float) -> AsyncEngine:
    json = {"json_serializer": _dump_json, "json_deserializer": orjson.loads}
    if target.backend == Backend.SQLITE:
        engine = create_async_engine(target.url, **json)  # busy_timeout: see _SQLITE_PRAGMAS
        _configure_sqlite(engine.sync_engine)
        return engine
    return create_async_engine(
        target.url,
        pool_size=5,
        max_overflow=5,
        pool_pre_ping=True,  # a server restart costs one ping, not one failed write
        connect_args={"timeout": connect_timeout_s, "command_timeout": 30.0},
        **json,
    )


def _create_write_engine(target: DatabaseTarget) -> Engine:
    """SQLite: the synchronous engine of the writer thread, on the same file and pragmas."""
    engine = create_engine(
        target.url.set(drivername="sqlite"),
        json_serializer=_dump_json,
        json_deserializer=orjson.loads,
        pool_size=1,
        max_overflow=0,
    )
    _configure_sqlite(engine)
    return engine


def _configure_sqlite(engine: Engine) -> None:
    """Pragmas on every new connection; SQLAlchemy (not the sqlite3 module) starts transactions,
    so that DDL and every statement of a write share one transaction."""

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, record: ConnectionPoolEntry) -> None:  # noqa: ANN401
        del record
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        for pragma in _SQLITE_PRAGMAS:
            cursor.execute(pragma)
        cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(connection: Connection) -> None:
        connection.exec_driver_sql("BEGIN")


def _dump_json(value: object) -> str:
    return orjson.dumps(value).decode()


@dataclass(frozen=True, slots=True)
class _DriverStatement:
    """A statement compiled once, with SQLAlchemy's own bind processor per parameter: the rows
    go to the driver as tuples, processed as ``Connection.execute`` would process them.

    A row is read straight off its record: every parameter is the record's attribute of the
    same name (the keys of the row dictionaries :func:`_order_row` and its siblings make)."""

    sql: str
    params: tuple[tuple[str, Callable[[Any], Any] | None], ...]
    #: The record's values in parameter order, and the positions that need processing.
    values: Callable[[Any], tuple[Any, ...]]
    processed: tuple[tuple[int, Callable[[Any], Any]], ...]

    @classmethod
    def compile(cls, statement: Insert, dialect: Dialect) -> _DriverStatement:
        """Every column but an autoincrementing key, as the row dictionaries have them."""
        columns = statement.table.c
        keys = [c.name for c in columns if not (c.primary_key and c.autoincrement is True)]
        compiled = statement.compile(dialect=dialect, column_keys=keys)
        names = compiled.positiontup or ()
        params = tuple((name, columns[name].type.bind_processor(dialect)) for name in names)
        values = attrgetter(*names)  # every statement has several parameters: a tuple
        processed = tuple((i, process) for i, (_, process) in enumerate(params) if process)
        return cls(compiled.string, params, values, processed)

    def rows(self, records: Iterable[object]) -> list[tuple[object, ...]]:
        values, processed = self.values, self.processed
        if not processed:
            return [values(record) for record in records]
        rows: list[tuple[object, ...]] = []
        for record in records:
            row = list(values(record))
            for index, process in processed:
                row[index] = process(row[index])
            rows.append(tuple(row))
        return rows


class _DriverWrites:
    """SQLite's writer thread: the store's four statements compiled once and executed with
    ``exec_driver_sql``. ``Connection.execute`` compiled (from its cache) and built a parameter
    dictionary per row for every write; with a thousand orders in flight that was about a third
    of the writer thread (docs/performance.md, lever 28)."""

    def __init__(
        self,
        dialect: Dialect,
        *,
        orders: Insert,
        events: Insert,
        vehicles: Insert,
        counters: Insert,
    ) -> None:
        self.orders = _DriverStatement.compile(orders, dialect)
        self.events = _DriverStatement.compile(events, dialect)
        self.vehicles = _DriverStatement.compile(vehicles, dialect)
        self.counters = _DriverStatement.compile(counters, dialect)

    def write(self, connection: Connection, batch: WriteBatch) -> None:
        """``SqlStore._write_rows``, the same statements and values, in the caller's transaction."""
        statements = (self.orders, self.events, self.vehicles, self.counters)
        for statement, records in _records_per_statement(statements, batch):
            try:
                values = statement.rows(records)
            except (TypeError, ValueError, OverflowError) as exc:  # as execute() reports them
                raise StatementError(str(exc), statement.sql, None, exc) from exc
            connection.exec_driver_sql(statement.sql, values)


S = TypeVar("S")
#: A statement of SQLAlchemy's own ``execute`` path, with what makes a record its row.
_WithRows = tuple[Insert, Callable[[Any], dict[str, object]]]


def _records_per_statement(
    statements: tuple[S, S, S, S], batch: WriteBatch
) -> Iterator[tuple[S, tuple[Any, ...]]]:
    """The statements for orders, events, vehicles and header counters, each with the records
    of ``batch`` it writes; statements without records are left out."""
    kinds = (batch.orders, batch.events, batch.vehicles, batch.counters)
    for statement, records in zip(statements, kinds, strict=True):
        if records:
            yield statement, records


def _order_row(record: OrderRecord) -> dict[str, object]:
    return {
        "order_id": record.order_id,
        "manufacturer": record.manufacturer,
        "serial_number": record.serial_number,
        "status": record.status,
        "reason": record.reason,
        "terminal": record.terminal,
        "created_at": record.created_at,
        "updated_at": record.updated_at,
        "request": record.request,
        "plan": record.plan,
        "released_end": record.released_end,
        "update_id": record.update_id,
        "sent_update_id": record.sent_update_id,
        "confirmed_update_id": record.confirmed_update_id,
        "cancel_action_id": record.cancel_action_id,
    }


def _order_record(row: Row[Any]) -> OrderRecord:
    return OrderRecord(
        order_id=row.order_id,
        manufacturer=row.manufacturer,
        serial_number=row.serial_number,
        status=row.status,
        reason=row.reason,
        created_at=row.created_at,
        updated_at=row.updated_at,
        request=row.request,
        plan=row.plan,
        released_end=row.released_end,
        update_id=row.update_id,
        sent_update_id=row.sent_update_id,
        confirmed_update_id=row.confirmed_update_id,
        cancel_action_id=row.cancel_action_id,
    )


def _event_row(event: OrderEvent) -> dict[str, object]:
    return {
        "event_id": event.event_id,
        "order_id": event.order_id,
        "time": event.time,
        "event": event.event,
        "details": event.details,
    }


def _event_record(row: Row[Any]) -> OrderEvent:
    return OrderEvent(
        order_id=row.order_id,
        time=row.time,
        event=row.event,
        details=row.details,
        event_id=row.event_id,
    )


def _vehicle_row(record: VehicleRecord) -> dict[str, object]:
    return {
        "manufacturer": record.manufacturer,
        "serial_number": record.serial_number,
        "version": record.version,
        "connection_state": record.connection_state,
        "factsheet": record.factsheet,
        "first_seen": record.first_seen,
        "last_seen": record.last_seen,
    }


def _vehicle_record(row: Row[Any]) -> VehicleRecord:
    return VehicleRecord(
        manufacturer=row.manufacturer,
        serial_number=row.serial_number,
        version=row.version,
        connection_state=row.connection_state,
        factsheet=row.factsheet,
        first_seen=row.first_seen,
        last_seen=row.last_seen,
    )


def _counter_row(counter: HeaderCounter) -> dict[str, object]:
    return {
        "manufacturer": counter.manufacturer,
        "serial_number": counter.serial_number,
        "topic": counter.topic,
        "header_id": counter.header_id,
    }


def _counter_record(row: Row[Any]) -> HeaderCounter:
    return HeaderCounter(row.manufacturer, row.serial_number, row.topic, row.header_id)


def _zone_row(record: ZoneRecord) -> dict[str, object]:
    return {
        "zone_id": record.zone_id,
        "document": record.document,
        "created_at": record.created_at,
    }


def _zone_record(row: Row[Any]) -> ZoneRecord:
    return ZoneRecord(zone_id=row.zone_id, document=row.document, created_at=row.created_at)


def _webhook_row(record: WebhookRecord) -> dict[str, object]:
    return {
        "url": record.url,
        "event_id": record.event_id,
        "body": record.body,
        "created_at": record.created_at,
    }
