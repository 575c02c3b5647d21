"""Initial schema: orders, their events, the fleet registry and headerId counters (issue 10).

Revision ID: 0001
Revises:
Created: 2026-11-01
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

_SEQ = sa.BigInteger().with_variant(sa.Integer(), "sqlite")
_TIME = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.create_table(
        "orders",
        sa.Column("seq", _SEQ, primary_key=True, autoincrement=True),
        sa.Column("order_id", sa.Text, nullable=False),
        sa.Column("manufacturer", sa.Text, nullable=False),
        sa.Column("serial_number", sa.Text, nullable=False),
        sa.Column("status", sa.Text, nullable=False),
        sa.Column("reason", sa.Text, nullable=False),
        sa.Column("terminal", sa.Boolean, nullable=False),
        sa.Column("created_at", _TIME, nullable=False),
        sa.Column("updated_at", _TIME, nullable=False),
        sa.Column("request", sa.JSON, nullable=False),
        sa.Column("plan", sa.JSON, nullable=False),
        sa.Column("released_end", sa.Integer, nullable=False),
        sa.Column("update_id", sa.BigInteger, nullable=False),
        sa.Column("sent_update_id", sa.BigInteger, nullable=True),
        sa.Column("confirmed_update_id", sa.BigInteger, nullable=True),
        sa.Column("cancel_action_id", sa.Text, nullable=True),
        sa.PrimaryKeyConstraint("seq", name="pk_orders"),
        sa.UniqueConstraint("order_id", name="uq_orders_order_id"),
    )
    op.create_index("ix_orders_terminal_updated_at", "orders", ["terminal", "updated_at"])
    op.create_index("ix_orders_created_at", "orders", ["created_at"])
    op.create_index(
        "ix_orders_vehicle_created_at", "orders", ["manufacturer", "serial_number", "created_at"]
    )
    op.create_index("ix_orders_status_created_at", "orders", ["status", "created_at"])
    op.create_table(
        "order_events",
        sa.Column("seq", _SEQ, primary_key=True, autoincrement=True),
        sa.Column("event_id", sa.Text, nullable=False),
        sa.Column("order_id", sa.Text, nullable=False),
        sa.Column("time", _TIME, nullable=False),
        sa.Column("event", sa.Text, nullable=False),
        sa.Column("details", sa.JSON, nullable=False),
        sa.PrimaryKeyConstraint("seq", name="pk_order_events"),
        sa.UniqueConstraint("event_id", name="uq_order_events_event_id"),
    )
    op.create_index("ix_order_events_order_id_time", "order_events", ["order_id", "time"])
    op.create_table(
        "vehicles",
        sa.Column("manufacturer", sa.Text, nullable=False),
        sa.Column("serial_number", sa.Text, nullable=False),
        sa.Column("version", sa.Text, nullable=True),
        sa.Column("connection_state", sa.Text, nullable=True),
        sa.Column("factsheet", sa.JSON, nullable=True),
        sa.Column("first_seen", _TIME, nullable=False),
        sa.Column("last_seen", _TIME, nullable=False),
        sa.PrimaryKeyConstraint("manufacturer", "serial_number", name="pk_vehicles"),
    )
    op.create_table(
        "header_counters",
        sa.Column("manufacturer", sa.Text, nullable=False),
        sa.Column("serial_number", sa.Text, nullable=False),
        sa.Column("topic", sa.Text, nullable=False),
        sa.Column("header_id", sa.BigInteger, nullable=False),
        sa.PrimaryKeyConstraint(
            "manufacturer", "serial_number", "topic", name="pk_header_counters"
        ),
    )


def downgrade() -> None:
    op.drop_table("header_counters")
    op.drop_table("vehicles")
    op.drop_index("ix_order_events_order_id_time", table_name="order_events")
    op.drop_table("order_events")
    for name in (
        "ix_orders_status_created_at",
        "ix_orders_vehicle_created_at",
        "ix_orders_created_at",
        "ix_orders_terminal_updated_at",
    ):
        op.drop_index(name, table_name="orders")
    op.drop_table("orders")
