"""How long master control waits for a state to confirm an order message before it sends the
message again (§6.2: QoS 0 messages may be lost; R45: a vehicle discards a copy it holds).

A confirmation can be late without anything being lost: under load (a burst of orders to a large
fleet) the vehicles take longer to answer and master control takes longer to read the answers.
A fixed timeout then mistakes load for loss, and every needless resend adds to the load. So the
timeout follows the measured confirmation latency (from the send to the state that confirms it,
as master control sees it): ``confirm_timeout_s`` is the floor, and the timeout is
:data:`FACTOR` times the :data:`PERCENTILE` of the latencies of the last :data:`WINDOW_S`
seconds, capped at :data:`CEILING_FACTOR` times the floor. A lost message has no latency, so loss
alone never raises the timeout; once the load is gone its samples age out and the floor is back.

Pure: the shell passes the times in.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Final

#: The timeout is this many times the high percentile of the recent latencies.
FACTOR: Final = 3.0
#: Which latency stands for "recent": the 95th percentile.
PERCENTILE: Final = 0.95
#: Latencies older than this (seconds) no longer count.
WINDOW_S: Final = 60.0
#: Latencies kept at most (the newest).
MAX_SAMPLES: Final = 512
#: The timeout never exceeds this many times the configured one.
CEILING_FACTOR: Final = 10.0


@dataclass
class ConfirmationTimer:
    """The confirmation timeout in force, from ``floor_s`` and the latencies observed."""

    floor_s: float
    #: (time, latency), oldest first, at most MAX_SAMPLES.
    _samples: deque[tuple[float, float]] = field(default_factory=deque)
    #: The same latencies in ascending order (the percentile is an index, not a sort).
    _sorted: list[float] = field(default_factory=list)
    _timeout_s: float = math.nan

    def __post_init__(self) -> None:
        self._timeout_s = self.floor_s

    @property
    def timeout_s(self) -> float:
        return self._timeout_s

    def observe(self, latency_s: float, now: float) -> bool:
        """A message sent ``latency_s`` ago was confirmed at ``now``; True when the timeout
        changed."""
        if len(self._samples) >= MAX_SAMPLES:
            self._forget_oldest()
        latency = max(0.0, latency_s)
        self._samples.append((now, latency))
        bisect.insort(self._sorted, latency)
        return self._recompute(now)

    def expire(self, now: float) -> bool:
        """Forget latencies older than :data:`WINDOW_S`; True when the timeout changed."""
        if not self._samples or now - self._samples[0][0] < WINDOW_S:
            return False
        return self._recompute(now)

    def _recompute(self, now: float) -> bool:
        while self._samples and now - self._samples[0][0] >= WINDOW_S:
            self._forget_oldest()
        timeout = self.floor_s
        if self._sorted:
            ordered = self._sorted
            high = ordered[min(len(ordered) - 1, int(PERCENTILE * len(ordered)))]
            timeout = min(max(self.floor_s, FACTOR * high), CEILING_FACTOR * self.floor_s)
        changed = timeout != self._timeout_s
        self._timeout_s = timeout
        return changed

    def _forget_oldest(self) -> None:
        _, latency = self._samples.popleft()
        del self._sorted[bisect.bisect_left(self._sorted, latency)]
