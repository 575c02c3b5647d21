"""The store writer: the async shell piece between master control and its store.

- :meth:`StoreWriter.submit` queues a batch and returns at once; queued batches are merged
  (:class:`~vda_master.store.batch.PendingWrites`) and written together by :meth:`flush_loop`
  within ``flush_interval_s``, or at once when ``flush_at_records`` are pending (in a burst of
  write-aheads, later: below).
- :meth:`StoreWriter.write_ahead` returns only once its batch is committed: master control calls
  it before it publishes an order's first message, so a crash between the two loses nothing. A
  write-ahead that finds the writer idle takes everything queued into its transaction. In a burst
  (write-aheads queue behind a write in progress) they go first: the next transaction holds the
  write-aheads alone, and the rest waits until the burst is over or has waited
  ``queued_wait_max_s`` (docs/performance.md, lever 51). The orders go out sooner, and the
  records that wait merge (an order accepted and then running is one row written, not two).
- :meth:`StoreWriter.close` writes what is still queued, then stops the loop.

When the database is unavailable the writer keeps the records in memory and retries with capped
exponential backoff; it logs ``store.write_failed`` once per outage and ``store.recovered`` when a
write succeeds again. Orders, vehicles and counters merge by key, so only events can pile up:
past ``max_pending_events`` the oldest queued events are dropped and said so
(``store.events_dropped``). A record the database refuses outright is written apart from the
others and, if refused again, dropped with ``store.record_dropped``; nothing is lost silently.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterable
from dataclasses import dataclass, field

import structlog

from vda_master.store.batch import (
    PendingWrites,
    RecordKey,
    WriteBatch,
    event_key,
    merge_batches,
    split_batch,
)
from vda_master.store.errors import StoreUnavailableError, StoreWriteRejectedError
from vda_master.store.interface import Store

log = structlog.get_logger()
#: How many ids a log line lists at most.
_LOGGED_IDS = 20


@dataclass(frozen=True, slots=True)
class WriterSettings:
    """Batching, retry and memory bounds of the writer; seconds."""

    #: How long a submitted batch may wait for others to share its transaction.
    flush_interval_s: float = 0.05
    #: Write at once when this many records are queued.
    flush_at_records: int = 1000
    #: How long queued records may wait while write-aheads go first (module docstring).
    queued_wait_max_s: float = 1.0
    #: Queued events kept while the database is unavailable; the oldest go beyond this.
    max_pending_events: int = 100_000
    retry_initial_s: float = 0.1
    retry_max_s: float = 5.0


@dataclass(eq=False, slots=True)
class _Waiter:
    """Someone waiting for every submission up to ``seq`` to be committed: of the write-ahead
    lane alone (``ahead``), or of both lanes."""

    seq: int
    keys: frozenset[RecordKey]
    future: asyncio.Future[None]
    ahead: bool


@dataclass(slots=True)
class _Trouble:
    """An outage or overflow in progress: what to say once, and what to sum up at its end."""

    since: float
    reason: str = ""
    failed_attempts: int = 0
    dropped_events: int = 0
    dropped_event_orders: set[str] = field(default_factory=set)


class StoreWriter:
    """Batches, write-ahead and retries in front of a :class:`Store` (see the module docstring).

    Run :meth:`flush_loop` as a task of the service's TaskGroup; without it, :meth:`flush` and
    :meth:`write_ahead` write themselves.
    """

    def __init__(self, store: Store, settings: WriterSettings | None = None) -> None:
        self._store = store
        self._settings = settings or WriterSettings()
        self._pending = PendingWrites()  # queued by submit()
        self._ahead = PendingWrites()  # queued by write_ahead(); a _pending record of the same key
        # is newer (write_ahead() discards the older ones)
        self._submitted = 0  # sequence number of the latest submission (both lanes)
        self._committed = 0  # every submission up to here is written (or dropped and logged)
        self._ahead_submitted = 0  # the same for the write-ahead lane alone
        self._ahead_committed = 0
        self._queued_since: float | None = None  # when the oldest record of _pending came
        self._burst = False  # a write-ahead came while a write was in progress
        self._waiters: list[_Waiter] = []
        self._lost: set[RecordKey] = set()  # dropped from the queue since the last write
        self._wake = asyncio.Event()  # something is queued
        self._urgent = asyncio.Event()  # write it now
        self._lock = asyncio.Lock()  # one write at a time
        self._loop_running = False
        self._closed = False
        self._abandoned = False  # close() gave up: stop retrying
        self._trouble: _Trouble | None = None

    @property
    def pending_records(self) -> int:
        """Records queued and not yet written."""
        return len(self._pending) + len(self._ahead)

    @property
    def unavailable_reason(self) -> str | None:
        """Why the last write failed, while the database is unavailable; else None."""
        return self._trouble.reason or None if self._trouble else None

    def submit(self, batch: WriteBatch) -> None:
        """Queue ``batch``; it is written within ``flush_interval_s`` (never blocks)."""
        if self._closed:
            msg = "the store writer is closed"
            raise RuntimeError(msg)
        if batch.empty:
            return
        self._pending.add(batch)
        self._submitted += 1
        if self._queued_since is None:
            self._queued_since = time.monotonic()
        self._bound_events()
        self._wake.set()
        if len(self._pending) >= self._settings.flush_at_records:
            self._urgent.set()

    async def write_ahead(self, batch: WriteBatch, *, timeout_s: float | None = None) -> None:
        """Write ``batch`` (with everything queued when the writer is idle, see the module
        docstring); return once committed.

        Raises:
            StoreWriteRejectedError: the database refused a record of ``batch`` (it is dropped).
            StoreUnavailableError: not committed within ``timeout_s``; the batch stays queued and
                is written when the database is back.
        """
        if self._closed:
            msg = "the store writer is closed"
            raise RuntimeError(msg)
        keys = batch.keys()
        self._pending.discard_superseded(batch)  # written after this batch they would win
        self._ahead.add(batch)
        self._submitted += 1
        self._ahead_submitted += 1
        if self._lock.locked():
            self._burst = True
        await self._committed_up_to(self._ahead_submitted, keys, timeout_s, ahead=True)

    async def flush(self, *, timeout_s: float | None = None) -> None:
        """Return once everything submitted so far is written (see :meth:`write_ahead`)."""
        await self._committed_up_to(self._submitted, frozenset(), timeout_s, ahead=False)

    async def flush_loop(self) -> None:
        """Write queued batches until :meth:`close` (a forever-coroutine for the TaskGroup)."""
        self._loop_running = True
        try:
            while not self._closed:
                await self._wake.wait()
                if not self._urgent.is_set():
                    await _wait_at_most(self._urgent, self._settings.flush_interval_s)
                self._wake.clear()
                self._urgent.clear()
                await self._write_until_done()
        finally:
            self._loop_running = False

    async def close(self, *, timeout_s: float = 5.0) -> None:
        """Write what is queued (retrying for up to ``timeout_s``) and stop :meth:`flush_loop`.

        What cannot be written in time is logged with ``store.writes_lost``.
        """
        self._closed = True
        self._wake.set()
        self._urgent.set()
        try:
            async with asyncio.timeout(timeout_s):
                await self._write_until_done()
        except TimeoutError:
            self._abandoned = True
            self._report_lost()

    async def _committed_up_to(
        self, seq: int, keys: frozenset[RecordKey], timeout_s: float | None, *, ahead: bool
    ) -> None:
        if seq <= (self._ahead_committed if ahead else self._committed):
            return
        waiter = _Waiter(seq, keys, asyncio.get_running_loop().create_future(), ahead)
        self._waiters.append(waiter)
        try:
            async with asyncio.timeout(timeout_s):
                if self._loop_running and not self._closed:
                    self._urgent.set()
                    self._wake.set()
                else:
                    await self._write_until_done()
                await waiter.future
        except TimeoutError:
            reason = self.unavailable_reason or "the database is slow"
            msg = (
                f"the store did not commit within {timeout_s} s ({reason}); the batch stays queued"
            )
            raise StoreUnavailableError(msg) from None
        finally:
            if waiter in self._waiters:
                self._waiters.remove(waiter)

    async def _write_until_done(self) -> None:
        """Write what is queued, retrying with backoff while the database is unavailable."""
        attempt = 0
        while True:
            try:
                await self._write_once()
            except StoreUnavailableError as exc:
                if self._abandoned:
                    self._report_lost()
                    return
                delay = min(self._settings.retry_max_s, self._settings.retry_initial_s * 2**attempt)
                attempt += 1
                self._note_failure(exc, delay)
                await asyncio.sleep(delay)
                continue
            self._note_success()
            return

    async def _write_once(self) -> None:
        async with self._lock:
            everything = self._everything_due()
            self._burst = False
            seq, ahead_seq = self._submitted, self._ahead_submitted
            ahead = self._ahead.take()
            queued, queued_since = WriteBatch(), self._queued_since
            lost: set[RecordKey] = set()
            if everything:
                queued, self._queued_since = self._pending.take(), None
                lost, self._lost = self._lost, set()
            batch = merge_batches(ahead, queued)  # queued records are the newer per key
            if batch.empty:
                self._resolve(seq if everything else None, ahead_seq, lost)
                return
            try:
                dropped = await self._write(batch)
            except BaseException:  # unavailable or cancelled: put it back, older than the rest
                self._ahead.add_older(ahead)
                self._pending.add_older(queued)
                if not queued.empty:
                    self._queued_since = queued_since
                self._lost |= lost
                raise
            self._resolve(seq if everything else None, ahead_seq, dropped | lost)
            if not everything and len(self._pending) > 0:
                self._wake.set()  # the rest follows once the burst is over

    def _everything_due(self) -> bool:
        """Whether the next write takes the queued records too, not only the write-aheads."""
        if not self._burst or self._closed or len(self._ahead) == 0:
            return True
        if any(not waiter.ahead for waiter in self._waiters):
            return True  # flush() waits for everything
        since = self._queued_since
        return since is not None and time.monotonic() - since >= self._settings.queued_wait_max_s

    async def _write(self, batch: WriteBatch) -> set[RecordKey]:
        """Write ``batch``; if the database refuses it, write its records one by one and drop
        those refused again. The keys dropped."""
        try:
            await self._store.write(batch)
        except StoreWriteRejectedError as exc:
            log.warning("store.batch_rejected", reason=str(exc), records=batch.size)
        else:
            return set()
        dropped: set[RecordKey] = set()
        for key, single in split_batch(batch):
            try:
                await self._store.write(single)
            except StoreWriteRejectedError as exc:
                log.error("store.record_dropped", record=list(key), reason=str(exc))  # noqa: TRY400
                dropped.add(key)
        return dropped

    def _resolve(self, seq: int | None, ahead_seq: int, dropped: set[RecordKey]) -> None:
        """Submissions up to ``seq`` (None: of neither lane) and write-aheads up to
        ``ahead_seq`` are done: wake their waiters, failing those whose records were dropped."""
        if seq is not None:
            self._committed = max(self._committed, seq)
        self._ahead_committed = max(self._ahead_committed, ahead_seq)
        waiting: list[_Waiter] = []
        for waiter in self._waiters:
            if waiter.seq > (self._ahead_committed if waiter.ahead else self._committed):
                waiting.append(waiter)
            elif not waiter.future.done():
                refused = sorted(waiter.keys & dropped)
                if refused:
                    msg = f"the store dropped {len(refused)} record(s) of this batch: {refused[:3]}"
                    waiter.future.set_exception(StoreWriteRejectedError(msg))
                else:
                    waiter.future.set_result(None)
        self._waiters = waiting

    def _bound_events(self) -> None:
        if self._pending.event_count <= self._settings.max_pending_events:
            return
        dropped = self._pending.drop_oldest_events(self._settings.max_pending_events)
        self._lost.update(event_key(e) for e in dropped)
        trouble = self._trouble_started()
        first = trouble.dropped_events == 0
        trouble.dropped_events += len(dropped)
        trouble.dropped_event_orders.update(e.order_id for e in dropped)
        if first:
            log.error(
                "store.events_dropped",
                reason=f"more than {self._settings.max_pending_events} order events queued",
                what="the oldest queued order events; orders, vehicles and counters are kept",
                order_ids=_some(e.order_id for e in dropped),
            )

    def _trouble_started(self) -> _Trouble:
        if self._trouble is None:
            self._trouble = _Trouble(since=time.monotonic())
        return self._trouble

    def _note_failure(self, exc: StoreUnavailableError, retry_in_s: float) -> None:
        trouble = self._trouble_started()
        trouble.failed_attempts += 1
        if not trouble.reason:
            trouble.reason = str(exc)
            log.error(
                "store.write_failed",
                reason=trouble.reason,
                pending_records=len(self._pending),
                retry_in_s=retry_in_s,
            )
        else:
            log.debug("store.write_retry_failed", reason=str(exc), retry_in_s=retry_in_s)

    def _note_success(self) -> None:
        trouble, self._trouble = self._trouble, None
        if trouble is None:
            return
        outage_s = time.monotonic() - trouble.since
        log.info(
            "store.recovered",
            outage_s=round(outage_s, 3),
            failed_attempts=trouble.failed_attempts,
            dropped_events=trouble.dropped_events,
            dropped_event_orders=_some(trouble.dropped_event_orders),
        )

    def _report_lost(self) -> None:
        lost = merge_batches(self._ahead.take(), self._pending.take())
        self._lost.clear()
        for waiter in self._waiters:
            if not waiter.future.done():
                waiter.future.set_exception(StoreUnavailableError("the store writer closed"))
        self._waiters.clear()
        if lost.empty:
            return
        log.error(
            "store.writes_lost",
            reason=self.unavailable_reason or "closed before the database answered",
            orders=_some(o.order_id for o in lost.orders),
            events=len(lost.events),
            vehicles=len(lost.vehicles),
            counters=len(lost.counters),
        )


async def _wait_at_most(event: asyncio.Event, seconds: float) -> None:
    try:
        async with asyncio.timeout(seconds):
            await event.wait()
    except TimeoutError:
        pass


def _some(ids: Iterable[str]) -> list[str]:
    """Up to ``_LOGGED_IDS`` distinct ids, sorted, for a log line."""
    return sorted(set(ids))[:_LOGGED_IDS]
