"""Injected time: the pure core never reads the clock itself."""

from __future__ import annotations

import time
from datetime import UTC, datetime, timedelta
from typing import Protocol


class Clock(Protocol):
    """A source of wall time (for timestamps) and monotonic time (for intervals)."""

    def now(self) -> datetime:
        """Current UTC wall time, timezone-aware."""
        ...

    def monotonic(self) -> float:
        """Seconds on a monotonic clock."""
        ...


class SystemClock:
    """The real clock."""

    def now(self) -> datetime:
        return datetime.now(UTC)

    def monotonic(self) -> float:
        return time.monotonic()


class FakeClock:
    """A clock that moves only when told to; for tests."""

    def __init__(self, start: datetime | None = None) -> None:
        self._wall = start or datetime(2026, 1, 1, tzinfo=UTC)
        self._mono = 0.0

    def now(self) -> datetime:
        return self._wall

    def monotonic(self) -> float:
        return self._mono

    def advance(self, seconds: float) -> None:
        """Move both clocks forward by ``seconds``."""
        self._mono += seconds
        self._wall += timedelta(seconds=seconds)


#: The minute a timestamp was last formatted in and its text up to the seconds
#: (``2026-01-01T12:00:``): one tuple, replaced whole, so threads never see a torn pair.
_minute_prefix: tuple[tuple[int, int, int, int, int], str] = ((0, 0, 0, 0, 0), "")


def format_timestamp(moment: datetime) -> str:
    """ISO 8601 UTC with milliseconds and ``Z``, e.g. ``2026-01-01T12:00:00.123Z`` (§6.4, R16).

    Milliseconds are cut, not rounded, as ``isoformat(timespec="milliseconds")`` cuts them.
    Every message header takes one, so the text up to the seconds is kept per minute: half
    the cost of a full ``isoformat``."""
    global _minute_prefix  # noqa: PLW0603 - a cache of the last minute, see above
    if moment.tzinfo is not UTC:
        moment = moment.astimezone(UTC)
    minute = (moment.year, moment.month, moment.day, moment.hour, moment.minute)
    cached = _minute_prefix
    if cached[0] != minute:
        # isoformat writes four-digit years (strftime's %Y does not below 1000)
        text = moment.replace(second=0, microsecond=0, tzinfo=None).isoformat()[:17]
        cached = _minute_prefix = (minute, text)
    return f"{cached[1]}{moment.second:02d}.{moment.microsecond // 1000:03d}Z"
