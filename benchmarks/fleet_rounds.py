"""Several rounds of ``benchmarks/fleet.py`` summed up: figures as median [min-max] per stack,
and issue 12's targets at N = 1000 judged round by round (issue 12).

On a shared 2-core machine one side by side says little: the machine's speed moves between
minutes, and a target met in one round is missed in the next. ``fleet.py --rounds K`` runs
both stacks K times, alternating which goes first, prints each round's table and then this
summary. A target counts per round, ours against the peer of the same round, as the issue
sets them ("in the same run").

Pure: it reads the figures of finished rounds and formats text.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

#: Issue 12: every vehicle available at most this long after the vehicles' process started.
AVAILABLE_WITHIN_S = 2.0
#: Issue 12: ``POST /orders`` answered within this, p99, during the burst.
ORDER_CALL_P99_S = 0.1


class Figures(Protocol):
    """What a summary reads of one stack's run (``fleet.Result``)."""

    name: str
    available_s: float
    completion_s: float
    cpu_drive: dict[str, float]
    call_s: list[float]
    orders_sent_s: float
    observed: dict[str, object]


@dataclass(frozen=True, slots=True)
class Verdict:
    """One target of one round: met or not, and the figures that decided it."""

    target: str
    met: bool
    detail: str


def stack_total(per_process: dict[str, float]) -> float:
    """The sum over the stack's processes, the broker (``mosquitto``) left out."""
    return sum(v for k, v in per_process.items() if k != "mosquitto")


def stack_cpu_s(figures: Figures) -> float:
    """CPU-seconds of the stack's processes during the drive."""
    return stack_total(figures.cpu_drive)


def percentile(samples: Sequence[float], fraction: float) -> float:
    """The sample at ``fraction`` of the sorted samples (nan for none)."""
    if not samples:
        return math.nan
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(fraction * len(ordered)))]


def observed_figure(observed: dict[str, object], key: str) -> float:
    """One of the observer's figures as a number; nan when it did not report it."""
    value = observed.get(key)
    return float(value) if isinstance(value, (int, float)) else math.nan


def _count(figures: Figures, key: str) -> float:
    return observed_figure(figures.observed, key)


def verdicts(peer: Figures, ours: Figures, ideal_s: float) -> list[Verdict]:
    """Issue 12's targets for one round (ours against the peer of that round)."""
    cpu_ours, cpu_peer = stack_cpu_s(ours), stack_cpu_s(peer)
    ratio_ours, ratio_peer = ours.completion_s / ideal_s, peer.completion_s / ideal_s
    p99 = percentile(ours.call_s, 0.99)
    lost, resends = _count(ours, "lost_states"), _count(ours, "resends")
    return [
        Verdict("CPU-s <= the peer's", cpu_ours <= cpu_peer, f"{cpu_ours:.2f} vs {cpu_peer:.2f}"),
        Verdict(
            "completion <= the peer's",
            ratio_ours <= ratio_peer,
            f"{ratio_ours:.2f}x vs {ratio_peer:.2f}x",
        ),
        Verdict(
            f"available <= {AVAILABLE_WITHIN_S:.0f} s",
            ours.available_s <= AVAILABLE_WITHIN_S,
            f"{ours.available_s:.2f} s",
        ),
        Verdict("0 lost states", lost == 0, f"{lost:.0f}"),
        Verdict("0 resends", resends == 0, f"{resends:.0f}"),
        Verdict(
            f"POST p99 < {ORDER_CALL_P99_S * 1000:.0f} ms",
            p99 < ORDER_CALL_P99_S,
            f"{p99 * 1000:.0f} ms",
        ),
    ]


def _spread(values: Sequence[float], fmt: str) -> str:
    finite = [v for v in values if not math.isnan(v)]
    if not finite:
        return "-"
    low, mid, high = min(finite), statistics.median(finite), max(finite)
    return f"{format(mid, fmt)} [{format(low, fmt)}-{format(high, fmt)}]"


#: The summary's rows: label, the figure of one stack's run, its format.
_ROWS: tuple[tuple[str, Callable[[Figures, float], float], str], ...] = (
    ("vehicles available after (s)", lambda f, _: f.available_s, ".2f"),
    ("completion / ideal", lambda f, ideal: f.completion_s / ideal, ".2f"),
    ("CPU-s drive (stack)", lambda f, _: stack_cpu_s(f), ".2f"),
    ("order->accepting state p99 ms", lambda f, _: 1000 * _count(f, "accept_p99_s"), ".0f"),
    ("order call p99 ms", lambda f, _: 1000 * percentile(f.call_s, 0.99), ".0f"),
    ("all orders sent within (s)", lambda f, _: f.orders_sent_s, ".2f"),
    ("lost states", lambda f, _: _count(f, "lost_states"), ".0f"),
    ("resends", lambda f, _: _count(f, "resends"), ".0f"),
)


def summary(rounds: Sequence[tuple[Figures, Figures]], ideal_s: float) -> str:
    """Median [min-max] per stack over ``rounds`` (each a (peer, ours) pair), then per target
    the rounds that met it, with each round's deciding figures."""
    peers, ours = [p for p, _ in rounds], [o for _, o in rounds]
    names = (peers[0].name, ours[0].name)
    width = max(len(label) for label, _, _ in _ROWS)
    cells = [
        (label, _spread([get(f, ideal_s) for f in peers], fmt),
         _spread([get(f, ideal_s) for f in ours], fmt))
        for label, get, fmt in _ROWS
    ]  # fmt: skip
    left = max(len(names[0]), *(len(c[1]) for c in cells))
    lines = [
        f"\n{len(rounds)} rounds: median [min-max]",
        f"{' ' * width} | {names[0].ljust(left)} | {names[1]}",
        *(f"{label.ljust(width)} | {peer.ljust(left)} | {own}" for label, peer, own in cells),
        "",
        "issue 12's targets (set for N = 1000), ours against the peer of the same round:",
    ]
    judged = [verdicts(peer, own, ideal_s) for peer, own in rounds]
    for index, first in enumerate(judged[0]):
        met = sum(round_[index].met for round_ in judged)
        details = ", ".join(round_[index].detail for round_ in judged)
        lines.append(f"  {first.target}: met in {met} of {len(rounds)} ({details})")
    return "\n".join(lines)
