"""Bytes ⇄ wire models, and the header stamper.

``decode`` never raises on hostile input: it returns the model, or a :class:`DecodeFailure` that
lists every problem with its JSON path and reason. The hot path is one pydantic
``model_validate_json`` call in strict mode (JSON booleans stay booleans, R19) plus a few header
comparisons; the JSON Schemas in ``schemas/`` are generated from the same models and serve
tooling and tests (see :mod:`vda5050.schemas`).

Two generations are spoken: 2.x (2.0.0, 2.1.0; :mod:`vda5050.models`) and 3.0
(:mod:`vda5050.models.v3`). The topic's ``v<major>`` picks the models (``decode``); the
payload's ``version`` must have the same major (R17, T12).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache
from typing import TYPE_CHECKING, Final, Generic, Literal, TypeVar, cast, overload

import orjson
from pydantic import BaseModel, JsonValue, ValidationError

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
    v3,
)
from vda5050.topics import AgvId, Topic, TopicAddress

if TYPE_CHECKING:
    from pydantic_core import ErrorDetails

#: The protocol versions this stack speaks (digest §0; 3.0.0 since issue 13).
SUPPORTED_VERSIONS: Final = ("2.0.0", "2.1.0", "3.0.0")
#: The 2.x major, the default generation of :func:`decode` without an address.
SUPPORTED_MAJOR: Final = 2
#: Every major version this stack speaks.
SUPPORTED_MAJORS: Final = (2, 3)
#: Default payload size limit. The spec sets none (§6.1.2); 1 MiB fits any sane order.
DEFAULT_MAX_BYTES: Final = 1_048_576

#: Every 2.x message model.
AnyMessage = Order | InstantActions | State | Visualization | Connection | Factsheet
#: Every 3.0 message model.
AnyMessageV3 = v3.AnyMessage
#: A message of any spoken version.
AnyVersionMessage = AnyMessage | AnyMessageV3
M = TypeVar("M", bound=WireModel)
H = TypeVar("H", bound=Message | LenientHeaderMessage)

#: The 2.x model of each 2.x topic.
MODEL_BY_TOPIC: Final[Mapping[Topic, type[AnyMessage]]] = {
    Topic.ORDER: Order,
    Topic.INSTANT_ACTIONS: InstantActions,
    Topic.STATE: State,
    Topic.VISUALIZATION: Visualization,
    Topic.CONNECTION: Connection,
    Topic.FACTSHEET: Factsheet,
}
#: The 3.0 model of each 3.0 topic.
MODEL_BY_TOPIC_V3: Final[Mapping[Topic, type[AnyMessageV3]]] = {
    Topic.ORDER: v3.Order,
    Topic.INSTANT_ACTIONS: v3.InstantActions,
    Topic.STATE: v3.State,
    Topic.VISUALIZATION: v3.Visualization,
    Topic.CONNECTION: v3.Connection,
    Topic.FACTSHEET: v3.Factsheet,
    Topic.ZONE_SET: v3.ZoneSetMessage,
    Topic.RESPONSES: v3.Responses,
}
#: The models of each major version, by topic.
MODELS_BY_MAJOR: Final[Mapping[int, Mapping[Topic, type[AnyVersionMessage]]]] = {
    2: MODEL_BY_TOPIC,
    3: MODEL_BY_TOPIC_V3,
}


def major_of(version: str) -> int:
    """The major of a ``Major.Minor.Patch`` version string; ValueError if it has none."""
    head = version.split(".", 1)[0]
    if not head.isdigit():
        msg = f"version {version!r} does not start with a major number"
        raise ValueError(msg)
    return int(head)


@overload
def model_for(topic: Topic, major_version: Literal[2]) -> type[AnyMessage]: ...
@overload
def model_for(topic: Topic, major_version: Literal[3]) -> type[AnyMessageV3]: ...
@overload
def model_for(topic: Topic, major_version: int) -> type[AnyVersionMessage]: ...
def model_for(topic: Topic, major_version: int) -> type[AnyVersionMessage]:
    """The wire model of ``topic`` in VDA 5050 ``major_version`` (2 or 3).

    Raises ValueError for a major this stack does not speak or a topic the major lacks
    (``zoneSet`` in 2.x). Typed callers that know the generation use the classes directly,
    e.g. ``decode_as(v3.State, ...)``.
    """
    models = MODELS_BY_MAJOR.get(major_version)
    if models is None:
        msg = f"VDA 5050 v{major_version} is not spoken; supported majors: {SUPPORTED_MAJORS}"
        raise ValueError(msg)
    model = models.get(topic)
    if model is None:
        msg = f"topic {topic.value!r} does not exist in VDA 5050 v{major_version}"
        raise ValueError(msg)
    return model


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
    major: int | None = None,
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> AnyVersionMessage | DecodeFailure:
    """Decode ``payload`` received on ``topic`` into its wire model.

    The generation is ``major`` if given, else the topic's ``v<major>`` from ``address``, else
    2. With ``address`` (the parsed topic the payload came on), the header must match it: the
    version's major equals the topic's ``v<major>`` and manufacturer/serialNumber equal the topic
    levels (R17, R18, T12, T13).
    """
    if major is None:
        major = SUPPORTED_MAJOR if address is None else address.major_version
    models = MODELS_BY_MAJOR.get(major)
    model = None if models is None else models.get(topic)
    if model is None:
        return DecodeFailure(topic, (_unspoken(topic, major),))
    return decode_as(model, topic, payload, address=address, max_bytes=max_bytes)


def _unspoken(topic: Topic, major: int) -> Problem:
    if major in MODELS_BY_MAJOR:
        return Problem("$", f"topic {topic.value!r} does not exist in VDA 5050 v{major}")
    return Problem("$", f"VDA 5050 v{major} is not spoken; supported majors: {SUPPORTED_MAJORS}")


def decode_as(
    model: type[M],
    topic: Topic,
    payload: bytes,
    *,
    address: TopicAddress | None = None,
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> M | DecodeFailure:
    """Typed variant of :func:`decode` for callers that know the model they expect.

    The payload's version must have the model's major (``model.vda_major``); with ``address``
    the topic's ``v<major>`` must match too.
    """
    if len(payload) > max_bytes:
        problem = Problem("$", f"payload is {len(payload)} bytes, over the {max_bytes} limit")
        return DecodeFailure(topic, (problem,), references=_head_references(payload))
    try:
        message = model.model_validate_json(payload, strict=True)
    except ValidationError as exc:
        return _failure_from_validation(topic, payload, exc, address, model.vda_major)
    if _header_fits(message, address, model.vda_major):
        return message
    header = _header_of(message)
    problems = _header_problems(header, address, model.vda_major)
    if problems:
        return DecodeFailure(topic, problems, header.get("headerId"), _references_of(message))  # type: ignore[arg-type]
    return message


#: The header fields of every message (§6.4); what differs between two vehicles' factsheets.
_HEADER_KEYS: Final = ("headerId", "timestamp", "version", "manufacturer", "serialNumber")
_HEADER_ATTRIBUTES: Final = ("header_id", "timestamp", "version", "manufacturer", "serial_number")


#: A compact JSON string (escapes kept as they are).
_JSON_STRING: Final = rb'"(?:[^"\\]|\\.)*"'
#: The five header fields first, compactly, in the models' order (codec.encode's output).
_HEADER_FIRST: Final = re.compile(
    rb'\{"headerId":\d+,"timestamp":%s,"version":%s,"manufacturer":%s,"serialNumber":%s,'
    % ((_JSON_STRING,) * 4)
)
#: The mark of a body keyed as written (a canonical body starts with "{").
_AS_WRITTEN: Final = b"\x00"
#: Every header key as written in JSON (written with a unicode escape, it has a ``\u``).
_HEADER_KEYS_QUOTED: Final = tuple(b'"%s"' % key.encode() for key in _HEADER_KEYS)


class SharedBodies(Generic[M]):
    """Decode once what many vehicles send alike: large messages whose body (everything but
    the header) is the same for every vehicle of a type, such as a factsheet (7 KB, ~150
    objects), are validated once per distinct body; a message whose body equals one already
    validated gets its own header validated and checked (R17, R18) and shares the rest.

    The body is compared as parsed JSON with sorted keys, and the validation of a body
    depends only on that value, so the result is what :func:`decode_as` would return (equal,
    and sharing the immutable sub-objects: 1000 factsheets of one type hold one set). Bodies
    are remembered up to ``limit`` (the oldest forgotten first).
    """

    def __init__(self, model: type[M], *, limit: int = 64) -> None:
        self._model = model
        self._header = Message if issubclass(model, Message) else LenientHeaderMessage
        self._limit = limit
        self._bodies: dict[bytes, M] = {}

    def __len__(self) -> int:
        return len(self._bodies)

    def decode(
        self,
        topic: Topic,
        payload: bytes,
        *,
        address: TopicAddress | None = None,
        max_bytes: int = DEFAULT_MAX_BYTES,
    ) -> M | DecodeFailure:
        """:func:`decode_as` with this cache's model, once per distinct body."""
        key = self._key(payload, max_bytes)
        if key is None:
            return decode_as(self._model, topic, payload, address=address, max_bytes=max_bytes)
        body, header = key
        known = self._bodies.get(body)
        if known is None:
            message = decode_as(self._model, topic, payload, address=address, max_bytes=max_bytes)
            if not isinstance(message, DecodeFailure) and _shareable(body):
                if len(self._bodies) >= self._limit:
                    del self._bodies[next(iter(self._bodies))]
                self._bodies[body] = message
            return message
        try:
            fields = self._header.model_validate_json(header, strict=True)
        except ValidationError as exc:
            return _failure_from_validation(topic, payload, exc, address, self._model.vda_major)
        update = {name: getattr(fields, name) for name in _HEADER_ATTRIBUTES}
        message = known.model_copy(update=update)
        if _header_fits(message, address, self._model.vda_major):
            return message
        problems = _header_problems(_header_of(message), address, self._model.vda_major)
        if problems:
            return DecodeFailure(topic, problems, fields.header_id)
        return message

    @staticmethod
    def _key(payload: bytes, max_bytes: int) -> tuple[bytes, bytes] | None:
        """(the body's key, the header as JSON), or None when the payload is not a JSON object
        of at most ``max_bytes`` (decode_as then says why).

        A payload that starts with the whole header, compactly and in the models' order (as
        this stack and most encoders write it), is keyed by the bytes after the header,
        without parsing (a factsheet takes ~45-75 µs to parse and write sorted, 2 µs so); see
        :func:`_shareable` for when such a body is kept. Any other payload is keyed by its
        body as canonical JSON (parsed, keys sorted)."""
        if len(payload) > max_bytes:
            return None
        header_first = _HEADER_FIRST.match(payload)
        if header_first is not None:
            end = header_first.end()
            return _AS_WRITTEN + payload[end:], payload[: end - 1] + b"}"
        raw = _loads_object(payload)
        if raw is None:
            return None
        header = {key: raw.pop(key) for key in _HEADER_KEYS if key in raw}
        try:
            return orjson.dumps(raw, option=orjson.OPT_SORT_KEYS), orjson.dumps(header)
        except TypeError:
            return None


def _shareable(key: bytes) -> bool:
    """Whether the body under ``key`` means the same whatever header comes before it: always
    for a canonical body; for one keyed as written, only when no header key can occur in it
    (a JSON object's later duplicate key wins, and a unicode escape could spell one). Checked
    once, when the body is first seen: a body that fails is decoded in full every time."""
    if not key.startswith(_AS_WRITTEN):
        return True
    return not any(name in key for name in _HEADER_KEYS_QUOTED) and b"\\u" not in key


class SharedBodyDumps:
    """JSON documents (``model_dump(mode="json", by_alias=True, exclude_none=True)``) of
    messages decoded through :class:`SharedBodies`: their body objects are the very same for
    every vehicle of a type, so the body is dumped once per distinct set of body objects and
    only the header per message. Nested parts of the result are shared: do not change them.
    """

    def __init__(self, *, limit: int = 64) -> None:
        self._limit = limit
        self._bodies: dict[tuple[int, ...], tuple[tuple[object, ...], dict[str, JsonValue]]] = {}

    def __len__(self) -> int:
        """Bodies remembered."""
        return len(self._bodies)

    def dump(self, message: BaseModel) -> dict[str, JsonValue]:
        names, header_keys = _body_fields(type(message))
        body = tuple(getattr(message, name) for name in names)
        key = tuple(map(id, body))
        known = self._bodies.get(key)
        if known is not None and all(a is b for a, b in zip(known[0], body, strict=True)):
            header = message.model_dump(
                mode="json", by_alias=True, exclude_none=True, include=set(_HEADER_ATTRIBUTES)
            )
            return {**header, **known[1]}
        whole: dict[str, JsonValue] = message.model_dump(
            mode="json", by_alias=True, exclude_none=True
        )
        if len(self._bodies) >= self._limit:
            self._bodies.clear()
        self._bodies[key] = (body, {k: v for k, v in whole.items() if k not in header_keys})
        return whole


@cache
def _body_fields(model: type[BaseModel]) -> tuple[tuple[str, ...], frozenset[str]]:
    """``model``'s body attributes, and its header's names as dumped (by alias)."""
    fields = model.model_fields
    body = tuple(name for name in fields if name not in _HEADER_ATTRIBUTES)
    header = frozenset(f.alias or n for n, f in fields.items() if n in _HEADER_ATTRIBUTES)
    return body, header


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
    topic: Topic,
    payload: bytes,
    exc: ValidationError,
    address: TopicAddress | None,
    expected_major: int,
) -> DecodeFailure:
    problems = [_problem_of(error) for error in exc.errors(include_url=False)]
    raw = _loads_object(payload)
    header_id = None
    references: tuple[tuple[str, str], ...] = ()
    if raw is not None:
        header_problems = _header_problems(raw, address, expected_major)
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


#: "2." and "3.": a version with this prefix has that major (the models check the pattern).
_MAJOR_PREFIX: Final = {major: f"{major}." for major in SUPPORTED_MAJORS}


def _header_fits(message: WireModel, address: TopicAddress | None, expected_major: int) -> bool:
    """The hot path of R17/R18: True when the header certainly matches; False means "look
    closer" (:func:`_header_problems` then explains or clears it)."""
    version = getattr(message, "version", None)
    if version is not None and not version.startswith(_MAJOR_PREFIX[expected_major]):
        return False
    if address is None:
        return True
    agv = address.agv
    return (
        address.major_version == expected_major
        and getattr(message, "manufacturer", None) in (agv.manufacturer, None)
        and getattr(message, "serial_number", None) in (agv.serial_number, None)
    )


def _header_of(message: WireModel) -> dict[str, object]:
    return {
        "headerId": getattr(message, "header_id", None),
        "version": getattr(message, "version", None),
        "manufacturer": getattr(message, "manufacturer", None),
        "serialNumber": getattr(message, "serial_number", None),
    }


def _header_problems(
    header: Mapping[str, object], address: TopicAddress | None, expected_major: int
) -> tuple[Problem, ...]:
    problems: list[Problem] = []
    version = header.get("version")
    if isinstance(version, str):
        problem = _version_problem(version, address, expected_major)
        if problem is not None:
            problems.append(problem)
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


def _version_problem(
    version: str, address: TopicAddress | None, expected_major: int
) -> Problem | None:
    """R17/T12: the version's major is the model's and the topic's."""
    major = version.split(".", 1)[0]
    if not major.isdigit():
        return None  # the model's pattern check reports it
    value = int(major)
    if address is not None and value != address.major_version:
        topic_major = address.major_version
        return Problem(
            "$.version",
            f"version {version} is not a {topic_major}.x version: its major does not match the "
            f"topic's v{topic_major}",
        )
    if value != expected_major:
        return Problem("$.version", f"version {version} is not a {expected_major}.x version")
    return None


def _references_of(message: WireModel) -> tuple[tuple[str, str], ...]:
    if isinstance(message, Order | v3.Order):
        return (("orderId", message.order_id), ("orderUpdateId", str(message.order_update_id)))
    if isinstance(message, InstantActions | v3.InstantActions):
        return tuple(("actionId", action.action_id) for action in message.actions)
    return ()


#: How much of an oversized payload is searched for its orderId (it is not parsed whole).
_HEAD_BYTES: Final = 4096
_HEAD_REFERENCE: Final = re.compile(
    rb'"(orderId|orderUpdateId)"\s*:\s*(?:"([^"\\]{0,256})"|(\d{1,10}))'
)


def _head_references(payload: bytes) -> tuple[tuple[str, str], ...]:
    """orderId and orderUpdateId as found in the head of a payload too large to parse (R30:
    the rejection still names the order, where the sender put them first, as usual)."""
    found: dict[str, str] = {}
    for match in _HEAD_REFERENCE.finditer(payload[:_HEAD_BYTES]):
        key = match.group(1).decode()
        text, number = match.group(2), match.group(3)
        found.setdefault(key, (number if text is None else text).decode(errors="replace"))
    return tuple((key, found[key]) for key in ("orderId", "orderUpdateId") if key in found)


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


@dataclass(frozen=True, slots=True)
class EncodedBody:
    """A message encoded without its header, once, for :meth:`HeaderStamper.encode_body`."""

    vda_major: int
    model_name: str
    #: The encoded object without the header's fields.
    fields: bytes

    @classmethod
    def of(cls, message: WireModel) -> EncodedBody:
        fields = message.__pydantic_serializer__.to_json(
            message, by_alias=True, exclude_none=True, exclude=set(_HEADER_ATTRIBUTES)
        )
        return cls(message.vda_major, type(message).__name__, fields)


class HeaderStamper:
    """The one place that writes message headers (§6.4, R14–R19; 3.0 §7.2, T10, T11).

    Keeps one headerId counter per topic, starting at 0 and wrapping after uint32's maximum,
    and stamps timestamp (UTC, milliseconds, ``Z``), version, manufacturer and serialNumber.
    The sender side owns one stamper per vehicle: a vehicle for its own topics, master control
    for the order and instantActions topics of each vehicle it addresses. A stamper for
    ``"3.0.0"`` stamps 3.0 models (:mod:`vda5050.models.v3`) only, one for 2.x 2.x models only.
    """

    def __init__(self, agv: AgvId, version: str, clock: Clock) -> None:
        self.agv = agv
        self.version = version
        self._clock = clock
        self._last: dict[Topic, int] = {}
        self._constant: tuple[tuple[str, AgvId], bytes] | None = None

    @property
    def version(self) -> str:
        """The version written into every header; one of :data:`SUPPORTED_VERSIONS`."""
        return self._version

    @version.setter
    def version(self, version: str) -> None:
        if version not in SUPPORTED_VERSIONS:
            msg = f"version must be one of {SUPPORTED_VERSIONS}, got {version!r}"
            raise ValueError(msg)
        self._version = version
        self._major = major_of(version)

    @property
    def major(self) -> int:
        """The major of :attr:`version` (2 or 3)."""
        return self._major

    def last_header_id(self, topic: Topic) -> int | None:
        """The headerId last stamped on ``topic``, or None before the first one (T79: a 3.0
        visualization names the state it belongs to by this)."""
        return self._last.get(topic)

    def continue_from(self, topic: Topic, last_header_id: int) -> None:
        """Go on after ``last_header_id`` on ``topic`` (a master restarted with its stored
        counters: headerIds keep increasing per topic, R15)."""
        if not 0 <= last_header_id <= UINT32_MAX:
            msg = f"a headerId is a uint32, got {last_header_id}"
            raise ValueError(msg)
        self._last[topic] = last_header_id

    def next_header_id(self, topic: Topic) -> int:
        """Take the next headerId of ``topic``."""
        value = (self._last.get(topic, -1) + 1) % (UINT32_MAX + 1)
        self._last[topic] = value
        return value

    def stamp(self, topic: Topic, message: H) -> H:
        """Return ``message`` with a fresh header for ``topic``.

        Raises ValueError if ``message`` is a model of another generation than the stamper's
        version (a 2.x order stamped "3.0.0" would be a malformed 3.0 message).
        """
        self._check_generation(message.vda_major, type(message).__name__)
        stamped = message.model_copy(
            update={
                "header_id": self.next_header_id(topic),
                "timestamp": format_timestamp(self._clock.now()),
                "version": self.version,
                "manufacturer": self.agv.manufacturer,
                "serial_number": self.agv.serial_number,
            }
        )
        return cast("H", stamped)  # model_copy keeps the class; mypy sees only the bound

    def encode_stamped(self, topic: Topic, message: WireModel) -> bytes:
        """``encode(self.stamp(topic, message))``, the same bytes, without the stamped copy:
        the message's fields are encoded without its header and a fresh header is written in
        front of them (:meth:`encode_body`)."""
        return self.encode_body(topic, EncodedBody.of(message))

    def encode_body(self, topic: Topic, body: EncodedBody) -> bytes:
        """``encode(self.stamp(topic, message))`` for the message ``body`` was taken from, the
        same bytes, for the cost of the header: for what is sent alike many times (a vehicle's
        ONLINE and last will at every connect, the factsheet a fleet shares)."""
        self._check_generation(body.vda_major, body.model_name)
        return self._header_before(topic, body.fields)

    def _header_before(self, topic: Topic, fields: bytes) -> bytes:
        """A fresh header in front of a header-less encoded object: a header comes first in
        every model, so these are the bytes of the stamped message."""
        header = b'{"headerId":%d,"timestamp":"%s",%s' % (
            self.next_header_id(topic),
            format_timestamp(self._clock.now()).encode(),
            self._constant_header(),
        )
        return header + b"}" if fields == b"{}" else header + b"," + fields[1:]

    def _check_generation(self, major: int, model_name: str) -> None:
        if major != self._major:
            msg = f"cannot stamp a {major}.x {model_name} with version {self._version}"
            raise ValueError(msg)

    def _constant_header(self) -> bytes:
        """``"version":…,"manufacturer":…,"serialNumber":…`` as the models encode them."""
        key = (self._version, self.agv)
        if self._constant is None or self._constant[0] != key:
            fields = LenientHeaderMessage(
                version=self._version,
                manufacturer=self.agv.manufacturer,
                serial_number=self.agv.serial_number,
            )
            self._constant = (key, encode(fields)[1:-1])
        return self._constant[1]
