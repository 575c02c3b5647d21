"""CPython's cyclic garbage collector tuned for a service that holds a large fleet.

A master that knows a thousand vehicles, or a process that simulates them, holds some 10^6
long-lived objects (factsheets, states, order plans). With the default thresholds (700, 10, 10)
the collector runs a young collection every 700 net allocations and, at moments decided by how
much survived, a full collection over the whole heap that takes ~0.35 s: during the 1000-order
burst of issue 12, 15-30% of the master's CPU per ``POST /orders`` (benchmarks/post_orders.py),
and a stall of whatever request or tick it hits.

While :func:`tuned_collector` is entered, what exists at that moment is frozen out of the
collector's sight (:func:`gc.freeze`), young collections run every 10,000 net allocations and
full collections never by themselves: the service runs one every :data:`FULL_COLLECTION_EVERY_S`
(``gc.collect()``), so cyclic garbage is still freed. Reference counting frees everything else
at once, as always.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Final

#: Seconds between the full collections a service with a tuned collector runs itself.
FULL_COLLECTION_EVERY_S: Final = 300.0
#: Young collections every 10,000 net allocations; generation 1 every 50 of them; never a full
#: collection by itself.
TUNED_THRESHOLDS: Final = (10_000, 50, 1_000_000)


class _Tuning:
    """Who uses the tuning now, and the thresholds to restore after the last one."""

    def __init__(self) -> None:
        self.users = 0
        self.saved: tuple[int, int, int] = gc.get_threshold()


_TUNING = _Tuning()


@contextmanager
def tuned_collector() -> Iterator[None]:
    """Freeze what exists, then collect with :data:`TUNED_THRESHOLDS` until the block ends.

    Overlapping uses (a master and simulated vehicles in one process, as in the tests) share
    one tuning: the first sets it up (one full collection first, so no garbage is frozen), the
    last restores the previous thresholds and unfreezes.
    """
    if _TUNING.users == 0:
        _TUNING.saved = gc.get_threshold()
        gc.collect()
        gc.freeze()
        gc.set_threshold(*TUNED_THRESHOLDS)
    _TUNING.users += 1
    try:
        yield
    finally:
        _TUNING.users -= 1
        if _TUNING.users == 0:
            gc.set_threshold(*_TUNING.saved)
            gc.unfreeze()
