"""Vehicle alarms: what changed in a vehicle's errors and safety chain from one state to the
next (pure; docs/master.md, *Webhooks*).

VDA 5050 gives an error no id (§6.10.5): a vehicle lists the errors active now in every state
and drops one when it is resolved. Here an error is *the same* while its ``errorType``, its
``errorLevel`` (a 3.0 robot's own, below) and its ``errorReferences`` (in any order) stay the
same: a WARNING that
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
from datetime import datetime
from typing import Final

from pydantic import JsonValue

from vda5050.clock import format_timestamp
from vda5050.models import Error, EStop, SafetyState
from vda5050.topics import AgvId

#: What makes two listed errors the same error (see the module docstring).
ErrorKey = tuple[str, str, frozenset[tuple[str, str]]]

#: The 3.0 levels that 2.x cannot hold, as :func:`vda_master.wire3.error_from_v3` prefixes them.
_V3_LEVELS: Final = ("URGENT", "CRITICAL")


def error_key(error: Error, *, v3: bool = False) -> ErrorKey:
    """Type, level as the vehicle sent it (:func:`reported_level`) and references."""
    references = frozenset(
        (r.reference_key, r.reference_value) for r in error.error_references or ()
    )
    return (error.error_type, reported_level(error, v3=v3), references)


@dataclass(frozen=True, slots=True)
class ErrorChange:
    """Errors that appeared and errors that went, each in the order the vehicle listed them."""

    raised: tuple[Error, ...]
    cleared: tuple[Error, ...]


def error_change(
    before: Sequence[Error], after: Sequence[Error], *, v3: bool = False
) -> ErrorChange | None:
    """What changed from ``before`` (the errors of the vehicle's last state; empty for its
    first) to ``after`` (``v3``: a 3.0 robot's); None when nothing did."""
    if not before and not after:
        return None
    old = {error_key(e, v3=v3): e for e in before}
    new = {error_key(e, v3=v3): e for e in after}
    raised = tuple(e for k, e in new.items() if k not in old)
    cleared = tuple(e for k, e in old.items() if k not in new)
    if not raised and not cleared:
        return None
    return ErrorChange(raised, cleared)


def is_stopped(safety: SafetyState) -> bool:
    """An emergency stop is active or a protective field is violated (§6.10.6)."""
    return safety.e_stop is not EStop.NONE or safety.field_violation


def safety_changed(before: SafetyState | None, after: SafetyState) -> bool:
    """Whether ``after`` says something new: a different eStop or fieldViolation than
    ``before`` (None: the vehicle's first state, new only when not clear)."""
    if before is None:
        return is_stopped(after)
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


#: The order ``GET /alarms`` lists alarms in: FATAL errors, then broken connections (what the
#: vehicle does is unknown), then stops of the safety chain, then a 3.0 robot's CRITICAL and
#: URGENT errors, then WARNINGs; oldest first within each.
_RANK: Final = {
    "FATAL": 0,
    "CONNECTIONBROKEN": 1,
    "SAFETY": 2,
    "CRITICAL": 3,
    "URGENT": 4,
    "WARNING": 5,
}
#: The connection state that is an alarm (§6.14: the broker's last will, an unexpected loss;
#: OFFLINE is a vehicle that said goodbye).
_BROKEN: Final = "CONNECTIONBROKEN"


@dataclass(frozen=True, slots=True)
class Alarm:
    """Something wrong with a vehicle now: an error it lists (``error``), its safety chain
    stopped (``safety``), or its connection broken (neither); ``since``: the first message that
    showed it to master control."""

    agv: AgvId
    since: datetime
    level: str
    error: Error | None = None
    safety: SafetyState | None = None


class AlarmBoard:
    """What is wrong with each vehicle now, and since when (``GET /alarms``). Mutable on
    purpose: it follows every state of a vehicle with errors."""

    __slots__ = ("_broken", "_errors", "_safety")

    def __init__(self) -> None:
        self._errors: dict[AgvId, dict[ErrorKey, Alarm]] = {}
        self._safety: dict[AgvId, Alarm] = {}
        self._broken: dict[AgvId, Alarm] = {}

    def note_errors(self, agv: AgvId, errors: Sequence[Error], now: datetime, *, v3: bool) -> None:
        """The errors ``agv`` lists now; an error listed before keeps its ``since`` (and takes
        its newest description)."""
        before = self._errors.get(agv, {})
        current: dict[ErrorKey, Alarm] = {}
        for error in errors:
            key = error_key(error, v3=v3)
            since = before[key].since if key in before else now
            current[key] = Alarm(agv, since, key[1], error=error)
        if current:
            self._errors[agv] = current
        else:
            self._errors.pop(agv, None)

    def note_safety(self, agv: AgvId, safety: SafetyState, now: datetime) -> None:
        """``agv``'s safety chain changed to ``safety``."""
        if is_stopped(safety):
            self._safety[agv] = Alarm(agv, now, "SAFETY", safety=safety)
        else:
            self._safety.pop(agv, None)

    def note_connection(self, agv: AgvId, connection_state: str, now: datetime) -> None:
        """``agv``'s ``connection`` topic says ``connection_state`` (a change)."""
        if connection_state == _BROKEN:
            self._broken[agv] = Alarm(agv, now, _BROKEN)
        else:
            self._broken.pop(agv, None)

    def alarms_of(self, agv: AgvId) -> list[Alarm]:
        """``agv``'s alarms, most severe first, oldest first among equals."""
        found = list(self._errors.get(agv, {}).values())
        for kind in (self._safety, self._broken):
            alarm = kind.get(agv)
            if alarm is not None:
                found.append(alarm)
        return sorted(found, key=_severity)

    def alarms(self, manufacturer: str | None = None) -> list[Alarm]:
        """Every alarm (of one manufacturer's vehicles), most severe first, oldest first among
        equals."""
        found = [a for by_key in self._errors.values() for a in by_key.values()]
        found.extend(self._safety.values())
        found.extend(self._broken.values())
        if manufacturer is not None:
            found = [a for a in found if a.agv.manufacturer == manufacturer]
        return sorted(found, key=_severity)


def _severity(alarm: Alarm) -> tuple[int, datetime]:
    return (_RANK.get(alarm.level, len(_RANK)), alarm.since)


def alarm_document(alarm: Alarm) -> dict[str, JsonValue]:
    """One alarm as ``GET /alarms`` lists it."""
    document: dict[str, JsonValue] = {
        "manufacturer": alarm.agv.manufacturer,
        "serialNumber": alarm.agv.serial_number,
        "since": format_timestamp(alarm.since),
    }
    if alarm.error is not None:
        document["kind"] = "error"
        document["error"] = error_document(alarm.error, v3=alarm.level in _V3_LEVELS)
    elif alarm.safety is not None:
        document["kind"] = "safety"
        document["safety"] = {
            "eStop": alarm.safety.e_stop.value,
            "fieldViolation": alarm.safety.field_violation,
        }
    else:
        document["kind"] = "connection"
        document["connection"] = {"connectionState": alarm.level}
    return document
