"""The confirmation timeout follows measured confirmation latency, so load is not taken for loss."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from vda_master.confirmation import (
    CEILING_FACTOR,
    FACTOR,
    MAX_SAMPLES,
    PERCENTILE,
    WINDOW_S,
    ConfirmationTimer,
)


def test_quick_confirmations_keep_the_configured_timeout() -> None:
    """Latencies well under the configured timeout leave it as configured."""
    timer = ConfirmationTimer(2.0)
    for k in range(100):
        assert not timer.observe(0.02, now=float(k))
    assert timer.timeout_s == 2.0


def test_slow_confirmations_stretch_the_timeout() -> None:
    """When confirmations take 1.5 s (a loaded fleet), the timeout grows beyond them with margin,
    so an order confirmed late is not resent."""
    timer = ConfirmationTimer(2.0)
    assert timer.observe(1.5, now=0.0)
    assert timer.timeout_s == FACTOR * 1.5


def test_the_timeout_is_capped() -> None:
    """A pathological latency cannot stop resends for ever."""
    timer = ConfirmationTimer(1.0)
    timer.observe(1000.0, now=0.0)
    assert timer.timeout_s == CEILING_FACTOR * 1.0


def test_old_latencies_age_out() -> None:
    """Once the load is gone and its samples are older than the window, the floor is back."""
    timer = ConfirmationTimer(2.0)
    timer.observe(1.5, now=0.0)
    assert not timer.expire(now=WINDOW_S - 1)
    assert timer.expire(now=WINDOW_S)
    assert timer.timeout_s == 2.0


def test_a_few_outliers_do_not_stretch_it() -> None:
    """The 95th percentile: one slow confirmation among many quick ones changes nothing."""
    timer = ConfirmationTimer(2.0)
    for k in range(99):
        timer.observe(0.01, now=k * 0.01)
    timer.observe(5.0, now=1.0)
    assert timer.timeout_s == 2.0


def _reference_timeout(floor_s: float, samples: list[tuple[float, float]], now: float) -> float:
    """The timeout by its definition: the window's latencies sorted afresh."""
    recent = [latency for at, latency in samples[-MAX_SAMPLES:] if now - at < WINDOW_S]
    if not recent:
        return floor_s
    ordered = sorted(recent)
    high = ordered[min(len(ordered) - 1, int(PERCENTILE * len(ordered)))]
    return min(max(floor_s, FACTOR * high), CEILING_FACTOR * floor_s)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(0.0, 30.0), st.floats(-1.0, 20.0), st.booleans()),
        min_size=1,
        max_size=1200,
    )
)
def test_the_timeout_is_the_windows_percentile_whatever_the_sequence(
    steps: list[tuple[float, float, bool]],
) -> None:
    """Kept in order incrementally, the timeout equals the sorted window's percentile after
    every confirmation and expiry, also past MAX_SAMPLES samples."""
    timer = ConfirmationTimer(floor_s=2.0)
    seen: list[tuple[float, float]] = []
    now = 0.0
    for gap, latency, expire_only in steps:
        now += gap
        if expire_only:
            timer.expire(now)
        else:
            timer.observe(latency, now)
            seen.append((now, max(0.0, latency)))
        assert timer.timeout_s == _reference_timeout(2.0, seen, now)
