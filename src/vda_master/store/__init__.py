"""The master's persistent store (issue 10): orders, their history, the fleet registry,
headerId counters, the zones added through the API and the webhook events not yet delivered,
on SQLite (the default, embedded) or
PostgreSQL. See ``docs/store.md``.

The seam for master control::

    async with open_store(config.database_url, config.data_dir) as store:
        open_orders = await store.load_open_orders()          # recovery
        writer = StoreWriter(store)
        tg.create_task(writer.flush_loop(), name="master.store_flush_loop")
        await writer.write_ahead(WriteBatch(orders=(record,), events=(created,)))  # then publish
        writer.submit(WriteBatch(events=(accepted,)))         # status changes, history, registry
        ...
        await writer.close()                                  # on shutdown: writes what is queued
"""

from vda_master.store.batch import WriteBatch, merge_batches
from vda_master.store.errors import StoreError, StoreUnavailableError, StoreWriteRejectedError
from vda_master.store.interface import Store
from vda_master.store.memory import MemoryStore
from vda_master.store.records import (
    HeaderCounter,
    JsonObject,
    JsonValue,
    OrderEvent,
    OrderEventKind,
    OrderRecord,
    OutOfServiceRecord,
    VehicleRecord,
    WebhookOutbox,
    WebhookRecord,
    ZoneRecord,
)
from vda_master.store.sql import SqlStore, open_store
from vda_master.store.urls import SQLITE_FILE_NAME, resolve_database_url
from vda_master.store.writer import StoreWriter, WriterSettings

__all__ = [
    "SQLITE_FILE_NAME",
    "HeaderCounter",
    "JsonObject",
    "JsonValue",
    "MemoryStore",
    "OrderEvent",
    "OrderEventKind",
    "OrderRecord",
    "OutOfServiceRecord",
    "SqlStore",
    "Store",
    "StoreError",
    "StoreUnavailableError",
    "StoreWriteRejectedError",
    "StoreWriter",
    "VehicleRecord",
    "WebhookOutbox",
    "WebhookRecord",
    "WriteBatch",
    "WriterSettings",
    "ZoneRecord",
    "merge_batches",
    "open_store",
    "resolve_database_url",
]
