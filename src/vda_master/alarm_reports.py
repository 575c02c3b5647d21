"""Telling people and a plant's systems about a vehicle's alarms: a log line for every error
raised or cleared and every change of the safety chain, and the ``vehicle.errors`` and
``vehicle.safety`` webhook events (what counts as a change: :mod:`vda_master.alarms`)."""

from __future__ import annotations

from collections.abc import Sequence

import structlog

from vda5050.models import Error, EStop, SafetyState, State
from vda5050.topics import AgvId
from vda_master.alarms import error_change, error_document, safety_changed
from vda_master.webhook_events import errors_event, safety_event
from vda_master.webhooks import Webhooks
from vda_master.wire3 import is_v3

log = structlog.get_logger()

#: The level of an error that needs nobody: logged as info, every other one as a warning.
_QUIET_LEVEL = "WARNING"


def report_alarms(webhooks: Webhooks, agv: AgvId, before: State | None, after: State) -> None:
    """Log and send what ``after`` changed in the errors and safety chain of ``before`` (the
    vehicle's last state; None for its first). Costs two attribute tests for a vehicle with
    no error and a clear safety chain."""
    previous_errors: Sequence[Error] = () if before is None else before.errors
    if after.errors or previous_errors:
        _report_errors(webhooks, agv, previous_errors, after)
    previous_safety = None if before is None else before.safety_state
    if safety_changed(previous_safety, after.safety_state):
        _report_safety(webhooks, agv, previous_safety, after)


def _report_errors(webhooks: Webhooks, agv: AgvId, before: Sequence[Error], after: State) -> None:
    change = error_change(before, after.errors)
    if change is None:
        return
    v3 = is_v3(after.version)
    raised = [error_document(e, v3=v3) for e in change.raised]
    cleared = [error_document(e, v3=v3) for e in change.cleared]
    order_id = after.order_id or None
    for document in raised:
        level = document["errorLevel"]
        emit = log.info if level == _QUIET_LEVEL else log.warning
        emit(
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
    if webhooks.enabled:
        current = [error_document(e, v3=v3) for e in after.errors]
        webhooks.emit(errors_event(agv, order_id, raised=raised, cleared=cleared, errors=current))


def _report_safety(
    webhooks: Webhooks, agv: AgvId, before: SafetyState | None, after: State
) -> None:
    safety = after.safety_state
    order_id = after.order_id or None
    stopped = safety.e_stop is not EStop.NONE or safety.field_violation
    (log.warning if stopped else log.info)(
        "vehicle.safety_changed",
        agv=str(agv),
        e_stop=safety.e_stop.value,
        field_violation=safety.field_violation,
        order_id=order_id,
    )
    previous = None if before is None else (before.e_stop.value, before.field_violation)
    webhooks.emit(
        safety_event(
            agv,
            order_id,
            e_stop=safety.e_stop.value,
            field_violation=safety.field_violation,
            previous=previous,
        )
    )
