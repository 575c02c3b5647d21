"""Telling people and a plant's systems about a vehicle's alarms: a log line for every error
raised or cleared and every change of the safety chain, the ``vehicle.errors`` and
``vehicle.safety`` webhook events, and the board behind ``GET /alarms`` (what counts as a
change: :mod:`vda_master.alarms`)."""

from __future__ import annotations

from collections.abc import Sequence

import structlog

from vda5050.clock import Clock
from vda5050.models import Error, SafetyState, State
from vda5050.topics import AgvId
from vda_master.alarms import (
    AlarmBoard,
    error_change,
    error_document,
    is_stopped,
    safety_changed,
)
from vda_master.webhook_events import errors_event, safety_event
from vda_master.webhooks import Webhooks
from vda_master.wire3 import is_v3

log = structlog.get_logger()

#: The level of an error that needs nobody: logged as info, every other one as a warning.
_QUIET_LEVEL = "WARNING"


class AlarmReports:
    """Follows every vehicle's states (:meth:`observe`) and reports what changed."""

    def __init__(self, webhooks: Webhooks, clock: Clock) -> None:
        self._webhooks = webhooks
        self._clock = clock
        self.board = AlarmBoard()

    def observe(self, agv: AgvId, before: State | None, after: State) -> None:
        """``after`` is ``agv``'s newest state, ``before`` its last one (None: its first).
        Costs two attribute tests for a vehicle with no error and a clear safety chain."""
        previous_errors: Sequence[Error] = () if before is None else before.errors
        if after.errors or previous_errors:
            self._errors(agv, previous_errors, after)
        previous_safety = None if before is None else before.safety_state
        if safety_changed(previous_safety, after.safety_state):
            self._safety(agv, previous_safety, after)

    def connection_changed(self, agv: AgvId, connection_state: str) -> None:
        """``agv``'s connection topic says something new (its event is sent by the service)."""
        self.board.note_connection(agv, connection_state, self._clock.now())

    def _errors(self, agv: AgvId, before: Sequence[Error], after: State) -> None:
        v3 = is_v3(after.version)
        self.board.note_errors(agv, after.errors, self._clock.now(), v3=v3)
        change = error_change(before, after.errors, v3=v3)
        if change is None:
            return
        raised = [error_document(e, v3=v3) for e in change.raised]
        cleared = [error_document(e, v3=v3) for e in change.cleared]
        order_id = after.order_id or None
        for document in raised:
            level = document["errorLevel"]
            (log.info if level == _QUIET_LEVEL else log.warning)(
                "vehicle.error_raised",
                agv=str(agv),
                error_type=document["errorType"],
                level=level,
                description=document["errorDescription"],
                order_id=order_id,
            )
        for document in cleared:
            log.info(
                "vehicle.error_cleared",
                agv=str(agv),
                error_type=document["errorType"],
                level=document["errorLevel"],
            )
        if self._webhooks.enabled:
            current = [error_document(e, v3=v3) for e in after.errors]
            self._webhooks.emit(
                errors_event(agv, order_id, raised=raised, cleared=cleared, errors=current)
            )

    def _safety(self, agv: AgvId, before: SafetyState | None, after: State) -> None:
        safety = after.safety_state
        self.board.note_safety(agv, safety, self._clock.now())
        order_id = after.order_id or None
        (log.warning if is_stopped(safety) else log.info)(
            "vehicle.safety_changed",
            agv=str(agv),
            e_stop=safety.e_stop.value,
            field_violation=safety.field_violation,
            order_id=order_id,
        )
        previous = None if before is None else (before.e_stop.value, before.field_violation)
        self._webhooks.emit(
            safety_event(
                agv,
                order_id,
                e_stop=safety.e_stop.value,
                field_violation=safety.field_violation,
                previous=previous,
            )
        )
