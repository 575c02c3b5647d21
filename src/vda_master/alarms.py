"""Vehicle alarms: what changed in a vehicle's errors and safety chain from one state to the
next (pure; docs/master.md, *Webhooks*).

VDA 5050 gives an error no id (§6.10.5): a vehicle lists the errors active now in every state
and drops one when it is resolved. Here an error is *the same* while its ``errorType``, its
``errorLevel`` and its ``errorReferences`` (in any order) stay the same: a WARNING that
becomes FATAL is one error cleared and another raised, and a description that changes (a
counter, a progress text) raises nothing. Two entries with the same key are one error.

The safety chain (§6.10.6, ``safetyState``) changes when ``eStop`` or ``fieldViolation``
does. A vehicle's first state (master control starting, or the vehicle new) raises the errors
it lists and reports a safety chain that is not clear; a clear one says nothing new.

A 3.0 robot's URGENT and CRITICAL errors reach the master's core as WARNINGs whose description
starts with that level (:func:`vda_master.wire3.error_from_v3`); :func:`reported_level` gives
the level the robot sent back, so an alarm says what the robot said.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from pydantic import JsonValue

from vda5050.models import Error, EStop, SafetyState

#: What makes two listed errors the same error (see the module docstring).
ErrorKey = tuple[str, str, frozenset[tuple[str, str]]]

#: The 3.0 levels that 2.x cannot hold, as :func:`vda_master.wire3.error_from_v3` prefixes them.
_V3_LEVELS: Final = ("URGENT", "CRITICAL")


def error_key(error: Error) -> ErrorKey:
    references = frozenset(
        (r.reference_key, r.reference_value) for r in error.error_references or ()
    )
    return (error.error_type, error.error_level.value, references)


@dataclass(frozen=True, slots=True)
class ErrorChange:
    """Errors that appeared and errors that went, each in the order the vehicle listed them."""

    raised: tuple[Error, ...]
    cleared: tuple[Error, ...]


def error_change(before: Sequence[Error], after: Sequence[Error]) -> ErrorChange | None:
    """What changed from ``before`` (the errors of the vehicle's last state; empty for its
    first) to ``after``; None when nothing did."""
    if not before and not after:
        return None
    old = {error_key(e): e for e in before}
    new = {error_key(e): e for e in after}
    raised = tuple(e for k, e in new.items() if k not in old)
    cleared = tuple(e for k, e in old.items() if k not in new)
    if not raised and not cleared:
        return None
    return ErrorChange(raised, cleared)


def safety_changed(before: SafetyState | None, after: SafetyState) -> bool:
    """Whether ``after`` says something new: a different eStop or fieldViolation than
    ``before`` (None: the vehicle's first state, new only when not clear)."""
    if before is None:
        return after.e_stop is not EStop.NONE or after.field_violation
    return before.e_stop is not after.e_stop or before.field_violation != after.field_violation


def reported_level(error: Error, *, v3: bool) -> str:
    """The level the vehicle sent: a 3.0 robot's URGENT or CRITICAL, else ``errorLevel``."""
    description = error.error_description or ""
    if v3:
        for level in _V3_LEVELS:
            if description == level or description.startswith(f"{level}: "):
                return level
    return error.error_level.value


def error_document(error: Error, *, v3: bool) -> dict[str, JsonValue]:
    """One error as an alarm names it: type, level as reported, description (a 3.0 level
    prefix taken off again), hint and references."""
    level = reported_level(error, v3=v3)
    description = error.error_description
    if description is not None and level != error.error_level.value:
        description = description.removeprefix(level).removeprefix(": ") or None
    return {
        "errorType": error.error_type,
        "errorLevel": level,
        "errorDescription": description,
        "errorHint": error.error_hint,
        "errorReferences": [
            {"referenceKey": r.reference_key, "referenceValue": r.reference_value}
            for r in error.error_references or ()
        ],
    }
