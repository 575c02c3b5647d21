"""The tables, as SQLAlchemy Core sees them (the migrations create them; a contract test checks
that migrating from empty gives exactly these).

- ``orders``: one row per order, upserted by ``order_id``; ``seq`` is the insertion order, used
  to break ties between orders created in the same microsecond.
- ``order_events``: the append-only history; ``event_id`` is unique, so a retried batch adds each
  event once. No foreign key to ``orders``: an event must never make a whole batch fail.
- ``vehicles``: the fleet registry, upserted by (manufacturer, serial_number).
- ``header_counters``: the last headerId sent per vehicle and topic.
- ``zones``: the zones added through the API, upserted by ``zone_id``; ``seq`` is the order in
  which they were first put, to break ties between zones created in the same microsecond (the
  key, as in ``orders``, because SQLite auto-increments only its primary key).
- ``out_of_service``: the vehicles an operator took out of service, by (manufacturer,
  serial_number); a row is deleted when the vehicle is put back in service.
- ``webhook_outbox``: webhook events not yet delivered, one row per (url, event_id), deleted
  once delivered or dropped; ``seq`` keeps the order they were written in.
- ``webhook_counter``: one row (``id`` 1), the last eventId given out.

Times are ``timestamp with time zone`` on PostgreSQL; SQLite has no such type, so they are
stored as fixed-width UTC text (which sorts in time order) and read back timezone-aware.
"""

from __future__ import annotations

from datetime import UTC, datetime

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    Column,
    DateTime,
    Dialect,
    Index,
    Integer,
    MetaData,
    PrimaryKeyConstraint,
    Table,
    Text,
    TypeDecorator,
)

#: Constraint and index names are spelled out so that migrations and this module agree.
NAMING = {
    "ix": "ix_%(table_name)s_%(column_0_N_name)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "pk": "pk_%(table_name)s",
}
metadata = MetaData(naming_convention=NAMING)

#: BIGINT autoincrement primary keys; SQLite only auto-increments INTEGER PRIMARY KEY.
SequenceId = BigInteger().with_variant(Integer(), "sqlite")


class UtcDateTime(TypeDecorator[datetime]):
    """A timezone-aware UTC datetime on every backend."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        value = value.astimezone(UTC)
        return value.replace(tzinfo=None) if dialect.name == "sqlite" else value

    def process_result_value(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        del dialect
        if value is None:
            return None
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


orders = Table(
    "orders",
    metadata,
    Column("seq", SequenceId, primary_key=True, autoincrement=True),
    Column("order_id", Text, nullable=False, unique=True),
    Column("manufacturer", Text, nullable=False),
    Column("serial_number", Text, nullable=False),
    Column("status", Text, nullable=False),
    Column("reason", Text, nullable=False),
    Column("terminal", Boolean, nullable=False),
    Column("created_at", UtcDateTime, nullable=False),
    Column("updated_at", UtcDateTime, nullable=False),
    Column("request", JSON, nullable=False),
    Column("plan", JSON, nullable=False),
    Column("released_end", Integer, nullable=False),
    Column("update_id", BigInteger, nullable=False),
    Column("sent_update_id", BigInteger, nullable=True),
    Column("confirmed_update_id", BigInteger, nullable=True),
    Column("cancel_action_id", Text, nullable=True),
    Index("ix_orders_terminal_updated_at", "terminal", "updated_at"),
    Index("ix_orders_created_at", "created_at"),
    Index("ix_orders_vehicle_created_at", "manufacturer", "serial_number", "created_at"),
    Index("ix_orders_status_created_at", "status", "created_at"),
)

order_events = Table(
    "order_events",
    metadata,
    Column("seq", SequenceId, primary_key=True, autoincrement=True),
    Column("event_id", Text, nullable=False, unique=True),
    Column("order_id", Text, nullable=False),
    Column("time", UtcDateTime, nullable=False),
    Column("event", Text, nullable=False),
    Column("details", JSON, nullable=False),
    Index("ix_order_events_order_id_time", "order_id", "time"),
)

vehicles = Table(
    "vehicles",
    metadata,
    Column("manufacturer", Text, nullable=False),
    Column("serial_number", Text, nullable=False),
    Column("version", Text, nullable=True),
    Column("connection_state", Text, nullable=True),
    Column("factsheet", JSON(none_as_null=True), nullable=True),
    Column("first_seen", UtcDateTime, nullable=False),
    Column("last_seen", UtcDateTime, nullable=False),
    PrimaryKeyConstraint("manufacturer", "serial_number"),
)

header_counters = Table(
    "header_counters",
    metadata,
    Column("manufacturer", Text, nullable=False),
    Column("serial_number", Text, nullable=False),
    Column("topic", Text, nullable=False),
    Column("header_id", BigInteger, nullable=False),
    PrimaryKeyConstraint("manufacturer", "serial_number", "topic"),
)

zones = Table(
    "zones",
    metadata,
    Column("seq", SequenceId, primary_key=True, autoincrement=True),
    Column("zone_id", Text, nullable=False, unique=True),
    Column("document", JSON, nullable=False),
    Column("created_at", UtcDateTime, nullable=False),
)

out_of_service = Table(
    "out_of_service",
    metadata,
    Column("manufacturer", Text, nullable=False),
    Column("serial_number", Text, nullable=False),
    Column("note", Text, nullable=False),
    Column("since", UtcDateTime, nullable=False),
    PrimaryKeyConstraint("manufacturer", "serial_number"),
)

webhook_outbox = Table(
    "webhook_outbox",
    metadata,
    Column("seq", SequenceId, primary_key=True, autoincrement=True),
    Column("url", Text, nullable=False),
    Column("event_id", BigInteger, nullable=False),
    Column("body", Text, nullable=False),
    Column("created_at", UtcDateTime, nullable=False),
    Index("ix_webhook_outbox_url_event_id", "url", "event_id", unique=True),
)

webhook_counter = Table(
    "webhook_counter",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=False),
    Column("last_event_id", BigInteger, nullable=False),
)
