"""How ``vda-probe`` judges what a vehicle answers to one step (pure; the steps:
:mod:`vda_inspect.probes`; docs/inspect.md). Each judge looks at the states that came since
the step's message went out and returns a verdict, or None while it cannot tell yet.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Final

from vda5050.models import ActionStatus, Error, State

#: The statuses an action ends with.
FINAL: Final = frozenset({ActionStatus.FINISHED, ActionStatus.FAILED})


class Outcome(StrEnum):
    PASS = "pass"  # noqa: S105 - an outcome, not a password
    #: Passed, but with something the standard recommends missing.
    WARN = "warn"
    FAIL = "fail"


@dataclass(frozen=True, slots=True)
class Verdict:
    outcome: Outcome
    text: str


@dataclass(frozen=True, slots=True)
class Seen:
    """What came from the vehicle since a step's message went out."""

    states: Sequence[State]
    #: The errors of the last state before it (a rejection is an error not among them).
    errors_before: frozenset[str]
    factsheets: int = 0


Judge = Callable[[Seen], Verdict | None]


Element = tuple[str, int, bool]  # (id, sequenceId, released)


def error_key(error: Error) -> str:
    """An error as one comparable string: type, references and description."""
    references = sorted((r.reference_key, r.reference_value) for r in error.error_references or ())
    return f"{error.error_type}|{references}|{error.error_description}"


def _listing(state: State) -> tuple[list[Element], list[Element]]:
    nodes = [(n.node_id, n.sequence_id, n.released) for n in state.node_states]
    edges = [(e.edge_id, e.sequence_id, e.released) for e in state.edge_states]
    return sorted(nodes, key=lambda e: e[1]), sorted(edges, key=lambda e: e[1])


def _naming(seen: Seen, order_id: str, key: str = "orderId") -> list[Error]:
    """New errors (not in the state before the step) that reference ``order_id`` (or another
    ``key``'s value)."""
    found: dict[str, Error] = {}
    for state in seen.states:
        for error in state.errors:
            text = error_key(error)
            refs = {(r.reference_key, r.reference_value) for r in error.error_references or ()}
            if text not in seen.errors_before and (key, order_id) in refs:
                found[text] = error
    return list(found.values())


def _refused(seen: Seen, action_id: str) -> Verdict | None:
    """A FAIL when a new error names instant action ``action_id``: it was not carried out."""
    for error in _naming(seen, action_id, "actionId"):
        text = f"refused with {error.error_type}: {error.error_description or ''}"
        details = [
            r.reference_value
            for r in error.error_references or ()
            if r.reference_key not in ("actionId", "actionType")
        ]
        return Verdict(Outcome.FAIL, text + (f" {details}" if details else ""))
    return None


def carries(
    order_id: str, update_id: int, horizon: list[Element], *, dropped: str | None = None
) -> Judge:
    """A state carries (``order_id``, ``update_id``) with exactly ``horizon`` left (the edges
    that lead to it included): accepted. An error naming the order: rejected. ``dropped``: an
    ended instant action of before that the new order's state must no longer list (R43)."""

    def judge(seen: Seen) -> Verdict | None:
        for state in seen.states:
            if (state.order_id, state.order_update_id) != (order_id, update_id):
                continue
            nodes, edges = _listing(state)
            # the first node may stay listed until the vehicle has "reached" it
            nodes = [n for n in nodes if n[1] > state.last_node_sequence_id]
            if nodes != horizon or len(edges) != len(horizon):
                continue
            if dropped is not None and any(a.action_id == dropped for a in state.action_states):
                text = f"carried, but the ended instant action {dropped!r} is still listed"
                return Verdict(Outcome.FAIL, text + " (R43)")
            return Verdict(Outcome.PASS, f"carried as update {update_id}")
        for error in _naming(seen, order_id):
            return Verdict(Outcome.FAIL, f"rejected: {error.error_type} {error.error_description}")
        return None

    return judge


def stays(order_id: str) -> Judge:
    """Nothing of the horizon driven: still at the first node, not driving."""

    def judge(seen: Seen) -> Verdict | None:
        for state in seen.states:
            if state.order_id != order_id:
                continue
            if state.last_node_sequence_id > 0:
                text = f"reported {state.last_node_id!r} (sequenceId {state.last_node_sequence_id})"
                return Verdict(Outcome.FAIL, text + " traversed: it was never released")
            if state.driving:
                return Verdict(Outcome.FAIL, "driving with nothing but its own node released")
        return None

    return judge


def unchanged(order_id: str, update_id: int) -> Judge:
    """The resent update neither errs nor changes what is held."""

    def judge(seen: Seen) -> Verdict | None:
        for error in _naming(seen, order_id):
            return Verdict(Outcome.FAIL, f"an error for a resend: {error.error_type}")
        for state in seen.states:
            if state.order_id != order_id or state.order_update_id != update_id:
                text = f"now carries {state.order_id!r} update {state.order_update_id}"
                return Verdict(Outcome.FAIL, text)
        return None

    return judge


def rejected(
    order_id: str,
    update_id: int,
    kept: tuple[str, int | None],
    *,
    absent_action: str | None = None,
) -> Judge:
    """Rejected: an error that references ``order_id`` (R30: and ``update_id``), and the
    vehicle still carries ``kept`` (orderId, and orderUpdateId unless None)."""

    def judge(seen: Seen) -> Verdict | None:
        for state in seen.states:
            if (state.order_id, state.order_update_id) == (order_id, update_id) and (
                order_id != kept[0] or update_id != kept[1]
            ):
                return Verdict(Outcome.FAIL, f"accepted: the state carries update {update_id}")
            if absent_action and any(a.action_id == absent_action for a in state.action_states):
                return Verdict(Outcome.FAIL, f"an action state for {absent_action!r} (R33)")
        errors = _naming(seen, order_id)
        if not errors:
            return None
        last = seen.states[-1]
        if last.order_id != kept[0] or (kept[1] is not None and last.order_update_id != kept[1]):
            text = f"rejected, but the vehicle now carries {last.order_id!r} update "
            return Verdict(Outcome.FAIL, text + f"{last.order_update_id}, not {kept[0]!r}")
        error = errors[0]
        refs = {r.reference_key: r.reference_value for r in error.error_references or ()}
        said = f"{error.error_type} ({error.error_level.value}): {error.error_description or ''}"
        if refs.get("orderUpdateId") != str(update_id):
            return Verdict(Outcome.WARN, f"rejected with {said}, without orderUpdateId {update_id}")
        return Verdict(Outcome.PASS, f"rejected with {said}")

    return judge


def _status_of(state: State, action_id: str) -> ActionStatus | None:
    return next((a.action_status for a in state.action_states if a.action_id == action_id), None)


def cancelled(order_id: str, cancel_id: str, *, failing: str | None = None) -> Judge:
    """The cancel FINISHED with nothing listed and the orderId kept; ``failing``: an action of
    the order that must have ended FAILED (R82)."""

    def judge(seen: Seen) -> Verdict | None:
        for state in seen.states:
            status = _status_of(state, cancel_id)
            if status is ActionStatus.FAILED:
                return Verdict(Outcome.FAIL, "cancelOrder FAILED with an order to cancel")
            if status is ActionStatus.FINISHED:
                return _after_cancel(state, order_id, failing)
        return _refused(seen, cancel_id)

    return judge


def _after_cancel(state: State, order_id: str, failing: str | None) -> Verdict:
    if state.node_states or state.edge_states:
        return Verdict(Outcome.FAIL, "cancelOrder FINISHED with nodes still listed")
    if state.order_id != order_id:
        return Verdict(Outcome.FAIL, f"orderId became {state.order_id!r}")
    if failing is not None and _status_of(state, failing) is not ActionStatus.FAILED:
        status = _status_of(state, failing)
        shown = "not listed" if status is None else status.value
        return Verdict(Outcome.FAIL, f"cancelOrder FINISHED, the order's {failing!r} {shown}")
    return Verdict(Outcome.PASS, "FINISHED, nothing listed")


def runs(order_id: str, action_id: str) -> Judge:
    """A state carries ``order_id`` with ``action_id`` started or waiting, not ended."""

    def judge(seen: Seen) -> Verdict | None:
        for state in seen.states:
            if state.order_id != order_id:
                continue
            status = _status_of(state, action_id)
            if status in FINAL:
                return Verdict(Outcome.FAIL, f"{action_id!r} {status.value} with no trigger")
            if status is ActionStatus.RUNNING:
                return Verdict(Outcome.PASS, f"taken, {action_id!r} RUNNING")
        for error in _naming(seen, order_id):
            return Verdict(Outcome.FAIL, f"rejected: {error.error_type} {error.error_description}")
        return None

    return judge


def kept_once(order_id: str, update_id: int, action_id: str, horizon: list[Element]) -> Judge:
    """R51: after an update stitched at the node whose action ``action_id`` runs, the state
    carries the update with ``horizon`` left and lists that action once, still RUNNING: the
    vehicle kept the original and neither ran it again nor added it twice."""

    def judge(seen: Seen) -> Verdict | None:
        for state in seen.states:
            if (state.order_id, state.order_update_id) != (order_id, update_id):
                continue
            listed = [a for a in state.action_states if a.action_id == action_id]
            if len(listed) != 1:
                shown = "no longer listed" if not listed else f"listed {len(listed)} times"
                return Verdict(Outcome.FAIL, f"carried, but {action_id!r} {shown} (R51)")
            status = listed[0].action_status
            if status is not ActionStatus.RUNNING:
                text = f"carried, but {action_id!r} {status.value} after the update"
                return Verdict(Outcome.FAIL, text + ": run again or ended (R51)")
            nodes, _ = _listing(state)
            if [n for n in nodes if n[1] > state.last_node_sequence_id] == horizon:
                return Verdict(
                    Outcome.PASS,
                    f"carried as update {update_id}, {action_id!r} RUNNING and listed once",
                )
        for error in _naming(seen, order_id):
            return Verdict(Outcome.FAIL, f"rejected: {error.error_type} {error.error_description}")
        return None

    return judge


def finished(action_id: str, *, factsheet: bool = False) -> Judge:
    def judge(seen: Seen) -> Verdict | None:
        for state in seen.states:
            status = _status_of(state, action_id)
            if status is ActionStatus.FAILED:
                return Verdict(Outcome.FAIL, "FAILED")
            if status is ActionStatus.FINISHED and (not factsheet or seen.factsheets):
                return Verdict(
                    Outcome.PASS, "FINISHED" + (", a factsheet came" if factsheet else "")
                )
        return _refused(seen, action_id)

    return judge


def naming(judge: Judge, name: str) -> Judge:
    """``judge``, whose pass becomes a warning when the error does not name ``name`` (R32:
    the rejection names the field it cannot honour)."""

    def named(seen: Seen) -> Verdict | None:
        verdict = judge(seen)
        if verdict is None or verdict.outcome is not Outcome.PASS or name in verdict.text:
            return verdict
        return Verdict(Outcome.WARN, f"{verdict.text} (without naming {name})")

    return named
