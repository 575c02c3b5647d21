"""VDA 5050 error objects the vehicle raises (§6.10.5, §7.1), built in one place.

errorType is a free string in 2.x. Order problems use the 2.x prose names and, where 2.1 names
none, the 2.0 Figure 8 names (digest §11 item 6). ``actionError`` (an action that fails, is
unknown, or is used outside its scope) is this vehicle's own name. An undecodable message on
``order`` or ``instantActions`` is a ``validationError`` (§6.6.4.1). Every error here is a
WARNING: the vehicle stays operational (§6.10.5), but for ``batteryLowError`` (FATAL).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Final

from vda5050.access import AccessProblem
from vda5050.codec import DecodeFailure, Problem
from vda5050.models import (
    Action,
    Error,
    ErrorLevel,
    ErrorReference,
    ErrorType,
    InstantActions,
    Order,
)
from vda5050.topics import Topic
from vda5050.validation import order_references

#: A failed or refused action (this vehicle's name; errorType is free in 2.x).
ACTION_ERROR: Final = "actionError"
#: The broker refuses a subscription or a publication of this vehicle (its ACL, probably).
BROKER_ACCESS_DENIED: Final = "brokerAccessDenied"
#: Keep at most this many warnings; the oldest go first so a flood of bad messages cannot grow
#: the state without bound (protocolLimits maxArrayLens "state.errors").
MAX_ERRORS: Final = 20


def references(pairs: Iterable[tuple[str, str]]) -> list[ErrorReference]:
    return [ErrorReference(reference_key=key, reference_value=value) for key, value in pairs]


def warning(error_type: str, description: str, pairs: Iterable[tuple[str, str]]) -> Error:
    return Error(
        error_type=error_type,
        error_level=ErrorLevel.WARNING,
        error_description=description,
        error_references=references(pairs),
    )


def order_error(order: Order, error_type: str, description: str, *extra: tuple[str, str]) -> Error:
    """A WARNING about a rejected order with headerId, topic, orderId, orderUpdateId (R30)."""
    return Error(
        error_type=error_type,
        error_level=ErrorLevel.WARNING,
        error_description=description,
        error_references=order_references(order, *extra),
    )


def action_error(action: Action, description: str, *extra: tuple[str, str]) -> Error:
    """A WARNING about one action, referencing its actionId (§7.1)."""
    pairs = [("actionId", action.action_id), ("actionType", action.action_type), *extra]
    return warning(ACTION_ERROR, description, pairs)


#: The battery is too low to drive (vda-5050-lib's virtual AGV uses the same name and level).
BATTERY_LOW: Final = "batteryLowError"
#: A vehicle stopped for a low battery drives again once charged this much above the limit.
BATTERY_RESUME_MARGIN_PCT: Final = 10.0


def battery_low(charge_pct: float) -> Error:
    """FATAL: the vehicle stops until it is charged (§6.10.5: it needs an operator, who sends
    startCharging or brings it to a charger)."""
    return Error(
        error_type=BATTERY_LOW,
        error_level=ErrorLevel.FATAL,
        error_description=f"stopped: the battery is at {charge_pct:.1f} %; charge it to drive on",
        error_references=references([("batteryState.batteryCharge", f"{charge_pct:.1f}")]),
    )


#: downloadMap of a map the vehicle holds already (§6.7.3, R87; 3.0 DUPLICATE_MAP, T97).
DUPLICATE_MAP: Final = "duplicateMap"


def duplicate_map(action: Action, map_id: str, map_version: str) -> Error:
    """R87, T97: the map is on the vehicle already; it is not downloaded again."""
    description = f"map {map_id!r} version {map_version!r} is already on the vehicle"
    pairs = [("actionId", action.action_id), ("mapId", map_id), ("mapVersion", map_version)]
    return warning(DUPLICATE_MAP, description, pairs)


def no_order_to_cancel(action: Action) -> Error:
    """§6.6.3.2, R64: cancelOrder without an order to cancel."""
    return warning(
        ErrorType.NO_ORDER_TO_CANCEL,
        "cancelOrder received but there is no order to cancel",
        [("actionId", action.action_id)],
    )


def decode_error(failure: DecodeFailure) -> Error:
    """A validationError for a message that could not be used (§6.6.4.1, R27, issue item 7)."""
    pairs: list[tuple[str, str]] = [("topic", failure.topic.value)]
    if failure.header_id is not None:
        pairs.insert(0, ("headerId", str(failure.header_id)))
    pairs.extend(failure.references)
    return warning(ErrorType.VALIDATION, failure.summary(), pairs)


def broker_access_error(problem: AccessProblem) -> Error:
    """A WARNING for what the broker refuses this vehicle (issue 14: denials are loud); it is
    reported while the problem lasts, whatever R29 clears."""
    return warning(BROKER_ACCESS_DENIED, problem.description, [("topic", problem.topic)])


def over_limits(message: InstantActions, problems: list[str]) -> DecodeFailure:
    """An instantActions message beyond the declared protocolLimits, as a refused input: none
    of its actions runs (§6.15, R36 for instant actions)."""
    return DecodeFailure(
        Topic.INSTANT_ACTIONS,
        tuple(Problem("$.actions", problem) for problem in problems[:3]),
        message.header_id,
    )


def with_errors(current: tuple[Error, ...], *new: Error) -> tuple[Error, ...]:
    """``current`` plus ``new``, keeping the newest :data:`MAX_ERRORS`."""
    return (*current, *new)[-MAX_ERRORS:]
