"""Store benchmark (issue 10): write throughput and write-ahead latency, SQLite and PostgreSQL.

1. Direct writes: one transaction per batch (an order upsert with a 20-node plan and two
   events), as the store sees it without the writer: batches/s and events/s.
2. Through the writer: the same batches submitted as fast as master control could, merged and
   flushed by the flush loop: batches/s and events/s.
3. write_ahead latency (an order record plus its "created" event, committed before returning),
   with the flush loop running: p50 and p99.

Both backends commit durably: SQLite in WAL mode with synchronous=FULL; PostgreSQL with fsync
on (a private server in a temporary folder unless --postgres-url names one).

Run: python benchmarks/store.py [--batches N] [--write-aheads N] [--postgres-url URL]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import structlog

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for tests.postgres

from tests.postgres import postgres_bin_dir, run_postgres, session_database
from vda_master.store import (
    Store,
    StoreWriter,
    WriteBatch,
    WriterSettings,
    open_store,
)
from vda_master.store.testing import at, make_event, make_order_record, sample_plan

EVENTS_PER_BATCH = 2


def batches(count: int, prefix: str) -> list[WriteBatch]:
    """``count`` batches over ``count // 10`` orders: each an upsert plus two events."""
    orders = max(1, count // 10)
    plans = [sample_plan(f"{prefix}-{i}", nodes=20) for i in range(orders)]
    out = []
    for step in range(count):
        order_id = f"{prefix}-{step % orders}"
        record = make_order_record(
            order_id, status="RUNNING", updated_at=at(step), plan=plans[step % orders]
        )
        events = tuple(
            make_event(order_id, "node_passed", at(step), nodeId=f"n{k}")
            for k in range(EVENTS_PER_BATCH)
        )
        out.append(WriteBatch(orders=(record,), events=events))
    return out


async def direct(store: Store, count: int) -> tuple[float, float]:
    work = batches(count, "direct")
    start = time.perf_counter()
    for batch in work:
        await store.write(batch)
    elapsed = time.perf_counter() - start
    return count / elapsed, count * EVENTS_PER_BATCH / elapsed


async def through_writer(store: Store, count: int) -> tuple[float, float]:
    work = batches(count, "writer")
    writer = StoreWriter(store, WriterSettings())
    async with asyncio.TaskGroup() as tg:
        tg.create_task(writer.flush_loop(), name="bench.store_flush_loop")
        start = time.perf_counter()
        for i, batch in enumerate(work):
            writer.submit(batch)
            if i % 50 == 0:
                await asyncio.sleep(0)  # let the loop run, as the master's loop would
        await writer.flush()
        elapsed = time.perf_counter() - start
        await writer.close()
    return count / elapsed, count * EVENTS_PER_BATCH / elapsed


async def write_ahead_latency(store: Store, count: int) -> tuple[float, float]:
    writer = StoreWriter(store, WriterSettings())
    latencies = []
    async with asyncio.TaskGroup() as tg:
        tg.create_task(writer.flush_loop(), name="bench.store_flush_loop")
        for i in range(count):
            order_id = f"ahead-{i}"
            batch = WriteBatch(
                orders=(make_order_record(order_id, plan=sample_plan(order_id, nodes=20)),),
                events=(make_event(order_id, "created"),),
            )
            start = time.perf_counter()
            await writer.write_ahead(batch)
            latencies.append((time.perf_counter() - start) * 1000)
        await writer.close()
    cuts = statistics.quantiles(latencies, n=100)
    return cuts[49], cuts[98]


async def run(name: str, url: str | None, data_dir: Path, args: argparse.Namespace) -> None:
    async with open_store(url, data_dir) as store:
        batches_s, events_s = await direct(store, args.batches)
        print(f"{name:10} direct        {batches_s:9.0f} batches/s {events_s:9.0f} events/s")
        batches_s, events_s = await through_writer(store, args.batches)
        print(f"{name:10} writer        {batches_s:9.0f} batches/s {events_s:9.0f} events/s")
        p50, p99 = await write_ahead_latency(store, args.write_aheads)
        print(f"{name:10} write_ahead   p50 {p50:6.2f} ms   p99 {p99:6.2f} ms")


@contextlib.contextmanager
def postgres_url(given: str | None) -> Iterator[str | None]:
    if given:
        yield given
    elif postgres_bin_dir() is None:
        yield None
    else:
        with run_postgres(durable=True) as server, session_database(server) as url:
            yield url


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, default=2000)
    parser.add_argument("--write-aheads", type=int, default=300)
    parser.add_argument("--postgres-url", help="a database to write into (default: a private one)")
    args = parser.parse_args()
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(30))  # warnings+
    with tempfile.TemporaryDirectory() as folder:
        asyncio.run(run("sqlite", None, Path(folder), args))
    with postgres_url(args.postgres_url) as url:
        if url is None:
            print("postgresql skipped: no initdb/pg_ctl found and no --postgres-url given")
        else:
            asyncio.run(run("postgresql", url, Path(tempfile.gettempdir()), args))


if __name__ == "__main__":
    main()
