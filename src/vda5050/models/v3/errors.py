"""Errors in the 3.0 state message: levels, the predefined error types and their levels
(§6.6.5, Table 9, §7.8 ``error``)."""

from __future__ import annotations

from collections.abc import Mapping
from enum import StrEnum
from types import MappingProxyType
from typing import Final

from vda5050.models.state import ErrorReference
from vda5050.models.v3.base import V3WireModel

__all__ = [
    "PREDEFINED_ERROR_LEVELS",
    "Error",
    "ErrorLevel",
    "ErrorReference",
    "ErrorType",
    "Translation",
    "predefined_error",
]


class ErrorLevel(StrEnum):
    """How serious an error is (§6.6.5.1). No level makes the robot clear its order."""

    WARNING = "WARNING"
    URGENT = "URGENT"
    CRITICAL = "CRITICAL"
    FATAL = "FATAL"

    @property
    def stops_driving(self) -> bool:
        """CRITICAL and FATAL: the robot cannot go on with its current order."""
        return self in {ErrorLevel.CRITICAL, ErrorLevel.FATAL}

    @property
    def blocks_new_orders(self) -> bool:
        """FATAL: the robot takes neither order updates nor new orders until a person acts."""
        return self is ErrorLevel.FATAL


class ErrorType(StrEnum):
    """The predefined error types (Table 9, plus the two list-overflow types of §7.8).

    ``errorType`` is an extensible enum: a robot may report vendor types, so
    :attr:`Error.error_type` is a plain string and these are the values it knows. The type list
    of §7.8 writes ``INVALID_ORDER`` where Table 9 says ``INVALID_ORDER_ACTION``; the table
    (which also gives level and reference) is taken.
    """

    UNSUPPORTED_PARAMETER = "UNSUPPORTED_PARAMETER"
    NO_ORDER_TO_CANCEL = "NO_ORDER_TO_CANCEL"
    VALIDATION_FAILURE = "VALIDATION_FAILURE"
    INVALID_ORDER_ACTION = "INVALID_ORDER_ACTION"
    INVALID_INSTANT_ACTION = "INVALID_INSTANT_ACTION"
    OUTDATED_ORDER_UPDATE = "OUTDATED_ORDER_UPDATE"
    SAME_ORDER_UPDATE_ID = "SAME_ORDER_UPDATE_ID"
    ORDER_UPDATE_FOLLOWING_CANCEL = "ORDER_UPDATE_FOLLOWING_CANCEL"
    OUTSIDE_OF_CORRIDOR = "OUTSIDE_OF_CORRIDOR"
    INSUFFICIENT_MEMORY = "INSUFFICIENT_MEMORY"
    DUPLICATE_MAP = "DUPLICATE_MAP"
    BLOCKED_ZONE_VIOLATION = "BLOCKED_ZONE_VIOLATION"
    DUPLICATE_ZONE_SET = "DUPLICATE_ZONE_SET"
    RELEASE_LOST = "RELEASE_LOST"
    ZONE_ACTION_CONFLICT = "ZONE_ACTION_CONFLICT"
    NODE_UNREACHABLE = "NODE_UNREACHABLE"
    LOCALIZATION_ERROR = "LOCALIZATION_ERROR"
    NO_ROUTE_TO_TARGET = "NO_ROUTE_TO_TARGET"
    OTHER_ORDER_ACTIVE = "OTHER_ORDER_ACTIVE"
    START_NODE_OUT_OF_RANGE = "START_NODE_OUT_OF_RANGE"
    MOBILE_ROBOT_NOT_AVAILABLE = "MOBILE_ROBOT_NOT_AVAILABLE"
    UNKNOWN_MAP_ID = "UNKNOWN_MAP_ID"
    INSTANT_ACTION_STATES_FULL = "INSTANT_ACTION_STATES_FULL"
    ZONE_ACTION_STATES_FULL = "ZONE_ACTION_STATES_FULL"


_W, _U, _C, _F = ErrorLevel.WARNING, ErrorLevel.URGENT, ErrorLevel.CRITICAL, ErrorLevel.FATAL

#: The level each predefined error type is reported with (Table 9; §7.8 for the two *_FULL).
PREDEFINED_ERROR_LEVELS: Final[Mapping[ErrorType, ErrorLevel]] = MappingProxyType(
    {
        ErrorType.UNSUPPORTED_PARAMETER: _C,
        ErrorType.NO_ORDER_TO_CANCEL: _W,
        ErrorType.VALIDATION_FAILURE: _W,
        ErrorType.INVALID_ORDER_ACTION: _W,
        ErrorType.INVALID_INSTANT_ACTION: _W,
        ErrorType.OUTDATED_ORDER_UPDATE: _W,
        ErrorType.SAME_ORDER_UPDATE_ID: _W,
        ErrorType.ORDER_UPDATE_FOLLOWING_CANCEL: _W,
        ErrorType.OUTSIDE_OF_CORRIDOR: _C,
        ErrorType.INSUFFICIENT_MEMORY: _U,
        ErrorType.DUPLICATE_MAP: _W,
        ErrorType.BLOCKED_ZONE_VIOLATION: _C,
        ErrorType.DUPLICATE_ZONE_SET: _W,
        ErrorType.RELEASE_LOST: _C,
        ErrorType.ZONE_ACTION_CONFLICT: _C,
        ErrorType.NODE_UNREACHABLE: _C,
        ErrorType.LOCALIZATION_ERROR: _F,
        ErrorType.NO_ROUTE_TO_TARGET: _W,
        ErrorType.OTHER_ORDER_ACTIVE: _W,
        ErrorType.START_NODE_OUT_OF_RANGE: _W,
        ErrorType.MOBILE_ROBOT_NOT_AVAILABLE: _W,
        ErrorType.UNKNOWN_MAP_ID: _W,
        ErrorType.INSTANT_ACTION_STATES_FULL: _U,
        ErrorType.ZONE_ACTION_STATES_FULL: _U,
    }
)


class Translation(V3WireModel):
    """A text in another language; ``translationKey`` is an ISO 639-1 code (§6.6.5.3)."""

    translation_key: str
    translation_value: str


class Error(V3WireModel):
    """An active error (§7.8 ``error``). ``error_type`` is a predefined :class:`ErrorType` value
    or a vendor-defined string."""

    error_type: str
    error_references: list[ErrorReference] | None = None
    error_description: str | None = None
    error_description_translations: list[Translation] | None = None
    error_hint: str | None = None
    error_hint_translations: list[Translation] | None = None
    error_level: ErrorLevel

    @property
    def known_type(self) -> ErrorType | None:
        """The predefined type, or None for a vendor-defined one."""
        try:
            return ErrorType(self.error_type)
        except ValueError:
            return None

    def reference(self, key: str) -> str | None:
        """The value of errorReference ``key``, or None."""
        for reference in self.error_references or ():
            if reference.reference_key == key:
                return reference.reference_value
        return None


def predefined_error(
    error_type: ErrorType,
    *references: tuple[str, str],
    description: str | None = None,
    hint: str | None = None,
) -> Error:
    """An error of a predefined type at the level Table 9 gives it, with ``references`` as
    (referenceKey, referenceValue) pairs."""
    return Error(
        error_type=error_type,
        error_level=PREDEFINED_ERROR_LEVELS[error_type],
        error_references=[
            ErrorReference(reference_key=key, reference_value=value) for key, value in references
        ]
        or None,
        error_description=description,
        error_hint=hint,
    )
