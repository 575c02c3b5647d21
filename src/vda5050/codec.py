"""Bytes ⇄ wire models, and the header stamper.

``decode`` never raises on hostile input: it returns the model, or a :class:`DecodeFailure` that
lists every problem with its JSON path and reason. The hot path is one pydantic
``model_validate_json`` call in strict mode (JSON booleans stay booleans, R19) plus a few header
comparisons; the JSON Schemas in ``schemas/`` are generated from the same models and serve
tooling and tests (see :mod:`vda5050.schemas`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final, TypeVar

import orjson
from pydantic import ValidationError

from vda5050.clock import Clock, format_timestamp
from vda5050.models import (
    UINT32_MAX,
    Connection,
    Factsheet,
    InstantActions,
    LenientHeaderMessage,
    Message,
    Order,
    State,
    Visualization,
    WireModel,
)
from vda5050.topics import AgvId, Topic, TopicAddress

if TYPE_CHECKING:
    from pydantic_core import ErrorDetails

#: The protocol versions this stack speaks (digest §0).
SUPPORTED_VERSIONS: Final = ("2.0.0", "2.1.0")
SUPPORTED_MAJOR: Final = 2
#: Default payload size limit. The spec sets none (§6.1.2); 1 MiB fits any sane order.
DEFAULT_MAX_BYTES: Final = 1_048_576

AnyMessage = Order | InstantActions | State | Visualization | Connection | Factsheet
M = TypeVar("M", bound=WireModel)
H = TypeVar("H", Message, LenientHeaderMessage)

MODEL_BY_TOPIC: Final[Mapping[Topic, type[AnyMessage]]] = {
    Topic.ORDER: Order,
    Topic.INSTANT_ACTIONS: InstantActions,
    Topic.STATE: State,
    Topic.VISUALIZATION: Visualization,
    Topic.CONNECTION: Connection,
    Topic.FACTSHEET: Factsheet,
}


@dataclass(frozen=True, slots=True)
class Problem:
    """One thing wrong with a payload: where (a JSON path, ``$.nodes[1].actions``) and why."""

    path: str
    reason: str

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}"


@dataclass(frozen=True, slots=True)
class DecodeFailure:
    """Why a payload could not be decoded, with what could be read of it for error references."""

    topic: Topic
    problems: tuple[Problem, ...]
    header_id: int | None = None
    #: Identifiers read from the raw payload when it was JSON (orderId, orderUpdateId, ...).
    references: tuple[tuple[str, str], ...] = field(default=())

    def summary(self, limit: int = 5) -> str:
        """The problems as one line, at most ``limit`` of them."""
        shown = "; ".join(str(problem) for problem in self.problems[:limit])
        more = len(self.problems) - limit
        return f"{shown}; and {more} more" if more > 0 else shown


def decode(
    topic: Topic,
    payload: bytes,
    *,
    address: TopicAddress | None = None,
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> AnyMessage | DecodeFailure:
    """Decode ``payload`` received on ``topic`` into its wire model.

    With ``address`` (the parsed topic the payload came on), the header must match it: the
    version's major equals the topic's ``v<major>`` and manufacturer/serialNumber equal the topic
    levels (R17, R18).
    """
    return decode_as(MODEL_BY_TOPIC[topic], topic, payload, address=address, max_bytes=max_bytes)


def decode_as(
    model: type[M],
    topic: Topic,
    payload: bytes,
    *,
    address: TopicAddress | None = None,
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> M | DecodeFailure:
    """Typed variant of :func:`decode` for callers that know the model they expect."""
    if len(payload) > max_bytes:
        return DecodeFailure(
            topic, (Problem("$", f"payload is {len(payload)} bytes, over the {max_bytes} limit"),)
        )
    try:
        message = model.model_validate_json(payload, strict=True)
    except ValidationError as exc:
        return _failure_from_validation(topic, payload, exc, address)
    header = _header_of(message)
    problems = _header_problems(header, address)
    if problems:
        return DecodeFailure(topic, problems, header.get("headerId"), _references_of(message))  # type: ignore[arg-type]
    return message


def encode(message: WireModel) -> bytes:
    """Compact UTF-8 JSON with the standard's field names; unset optional fields are left out."""
    return message.__pydantic_serializer__.to_json(message, by_alias=True, exclude_none=True)


# -- failure details --------------------------------------------------------------------------


def _json_path(loc: tuple[int | str, ...]) -> str:
    return "$" + "".join(f"[{item}]" if isinstance(item, int) else f".{item}" for item in loc)


def _problem_of(error: ErrorDetails) -> Problem:
    reason = error["msg"]
    if error["type"] == "json_invalid":
        detail = error.get("ctx", {}).get("error", "")
        reason = f"not valid JSON ({detail})" if detail else "not valid JSON"
        if "expected value at line 1 column 1" in str(detail) or "invalid unicode" in str(detail):
            reason += "; the payload must be UTF-8 encoded JSON"
    elif error["type"] == "finite_number":
        reason = "NaN and Infinity are not allowed (§6.1.4)"
    return Problem(_json_path(tuple(error["loc"])), reason)


def _failure_from_validation(
    topic: Topic, payload: bytes, exc: ValidationError, address: TopicAddress | None
) -> DecodeFailure:
    problems = [_problem_of(error) for error in exc.errors(include_url=False)]
    raw = _loads_object(payload)
    header_id = None
    references: tuple[tuple[str, str], ...] = ()
    if raw is not None:
        header_problems = _header_problems(raw, address)
        problems = [*header_problems, *(p for p in problems if p not in header_problems)]
        value = raw.get("headerId")
        header_id = value if isinstance(value, int) and 0 <= value <= UINT32_MAX else None
        references = _raw_references(raw)
    return DecodeFailure(topic, tuple(problems), header_id, references)


def _loads_object(payload: bytes) -> dict[str, object] | None:
    try:
        value = orjson.loads(payload)
    except (orjson.JSONDecodeError, RecursionError):
        return None
    return value if isinstance(value, dict) else None


def _header_of(message: WireModel) -> dict[str, object]:
    return {
        "headerId": getattr(message, "header_id", None),
        "version": getattr(message, "version", None),
        "manufacturer": getattr(message, "manufacturer", None),
        "serialNumber": getattr(message, "serial_number", None),
    }


def _header_problems(
    header: Mapping[str, object], address: TopicAddress | None
) -> tuple[Problem, ...]:
    problems: list[Problem] = []
    version = header.get("version")
    if isinstance(version, str):
        major = version.split(".", 1)[0]
        if major.isdigit() and int(major) != SUPPORTED_MAJOR:
            problems.append(
                Problem("$.version", f"version {version} is not a 2.x version this stack speaks")
            )
        elif address is not None and major.isdigit() and int(major) != address.major_version:
            problems.append(
                Problem(
                    "$.version",
                    f"major of {version} does not match the topic's v{address.major_version}",
                )
            )
    if address is not None:
        for key, expected in (
            ("manufacturer", address.agv.manufacturer),
            ("serialNumber", address.agv.serial_number),
        ):
            value = header.get(key)
            if isinstance(value, str) and value != expected:
                problems.append(
                    Problem(f"$.{key}", f"{value!r} does not match the topic's {expected!r}")
                )
    return tuple(problems)


def _references_of(message: WireModel) -> tuple[tuple[str, str], ...]:
    if isinstance(message, Order):
        return (("orderId", message.order_id), ("orderUpdateId", str(message.order_update_id)))
    if isinstance(message, InstantActions):
        return tuple(("actionId", action.action_id) for action in message.actions)
    return ()


def _raw_references(raw: Mapping[str, object]) -> tuple[tuple[str, str], ...]:
    references = [
        (key, str(raw[key]))
        for key in ("orderId", "orderUpdateId")
        if isinstance(raw.get(key), str | int) and not isinstance(raw.get(key), bool)
    ]
    actions = raw.get("actions")
    if isinstance(actions, list):
        references.extend(
            ("actionId", action["actionId"])
            for action in actions
            if isinstance(action, dict) and isinstance(action.get("actionId"), str)
        )
    return tuple(references)


# -- header stamping --------------------------------------------------------------------------


class HeaderStamper:
    """The one place that writes message headers (§6.4, R14–R19).

    Keeps one headerId counter per topic, starting at 0 and wrapping after uint32's maximum,
    and stamps timestamp (UTC, milliseconds, ``Z``), version, manufacturer and serialNumber.
    The sender side owns one stamper per vehicle: a vehicle for its own topics, master control
    for the order and instantActions topics of each vehicle it addresses.
    """

    def __init__(self, agv: AgvId, version: str, clock: Clock) -> None:
        if version not in SUPPORTED_VERSIONS:
            msg = f"version must be one of {SUPPORTED_VERSIONS}, got {version!r}"
            raise ValueError(msg)
        self.agv = agv
        self.version = version
        self._clock = clock
        self._last: dict[Topic, int] = {}

    def next_header_id(self, topic: Topic) -> int:
        """Take the next headerId of ``topic``."""
        value = (self._last.get(topic, -1) + 1) % (UINT32_MAX + 1)
        self._last[topic] = value
        return value

    def stamp(self, topic: Topic, message: H) -> H:
        """Return ``message`` with a fresh header for ``topic``."""
        return message.model_copy(
            update={
                "header_id": self.next_header_id(topic),
                "timestamp": format_timestamp(self._clock.now()),
                "version": self.version,
                "manufacturer": self.agv.manufacturer,
                "serial_number": self.agv.serial_number,
            }
        )
