"""Webhook events not yet delivered, and the last eventId given out.

Revision ID: 0004
Revises: 0003
Created: 2026-12-03
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

_TIME = sa.DateTime(timezone=True)
#: BIGINT autoincrement primary keys; SQLite only auto-increments INTEGER PRIMARY KEY.
_SEQUENCE = sa.BigInteger().with_variant(sa.Integer(), "sqlite")


def upgrade() -> None:
    op.create_table(
        "webhook_outbox",
        sa.Column("seq", _SEQUENCE, primary_key=True, autoincrement=True),
        sa.Column("url", sa.Text, nullable=False),
        sa.Column("event_id", sa.BigInteger, nullable=False),
        sa.Column("body", sa.Text, nullable=False),
        sa.Column("created_at", _TIME, nullable=False),
        sa.PrimaryKeyConstraint("seq", name="pk_webhook_outbox"),
    )
    op.create_index(
        "ix_webhook_outbox_url_event_id", "webhook_outbox", ["url", "event_id"], unique=True
    )
    op.create_table(
        "webhook_counter",
        sa.Column("id", sa.Integer, autoincrement=False, nullable=False),
        sa.Column("last_event_id", sa.BigInteger, nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_webhook_counter"),
    )


def downgrade() -> None:
    op.drop_table("webhook_counter")
    op.drop_index("ix_webhook_outbox_url_event_id", table_name="webhook_outbox")
    op.drop_table("webhook_outbox")
