"""Hypothesis strategies for documents that an official VDA 5050 3.0.0 schema accepts.

A small generator for the JSON-schema subset the official files use (``$ref`` into
``definitions``, ``type`` (also lists), ``properties``/``required``, ``items``/``minItems``,
``enum``/``const``, ``minimum``/``maximum``, ``format: date-time``, and the zone set's
``allOf`` of ``if``/``then`` on a constant). Optional properties are drawn half the time.

Where the text is stricter than the schema and the models follow the text (docs/vda5050-3.md
§A), the drawn documents are tightened the same way, so a failure always means a real
disagreement: integers are uint32; ``version`` is ``3.x.y``; ``eta`` and ``leaseExpiry`` are
timestamps like ``timestamp``; a control point ``weight`` is > 0; load dimensions are >= 0.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from hypothesis import strategies as st

from vda5050.models import UINT32_MAX

Schema = dict[str, Any]
Path = tuple[str, ...]

_TIMESTAMP_KEYS = frozenset({"timestamp", "eta", "leaseExpiry"})
_SCALARS = (
    st.booleans()
    | st.integers(-5, 5)
    | st.floats(allow_nan=False, allow_infinity=False, width=32)
    | st.text(max_size=4)
)


def documents(schema: Schema) -> st.SearchStrategy[Any]:
    """Documents the official ``schema`` accepts, tightened as the module docstring says."""
    return _node(schema, schema, ())


def timestamps() -> st.SearchStrategy[str]:
    """RFC 3339 UTC timestamps with milliseconds and ``Z``."""
    # hypothesis wants naive bounds; the drawn moments are made UTC below.
    low, high = datetime(2000, 1, 1), datetime(2100, 1, 1)  # noqa: DTZ001
    moments = st.datetimes(min_value=low, max_value=high)
    return moments.map(
        lambda m: m.replace(tzinfo=UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")
    )


def _node(node: Schema, root: Schema, path: Path) -> st.SearchStrategy[Any]:
    if "$ref" in node:
        name = node["$ref"].removeprefix("#/definitions/")
        return _node(root["definitions"][name], root, path)
    if "const" in node:
        return st.just(node["const"])
    if "enum" in node:
        return st.sampled_from(node["enum"])
    kind = node.get("type", "object")
    if isinstance(kind, list):
        return st.one_of(*(_typed(node, root, path, k) for k in kind))
    return _typed(node, root, path, kind)


def _typed(  # noqa: PLR0911 - one return per JSON type
    node: Schema, root: Schema, path: Path, kind: str
) -> st.SearchStrategy[Any]:
    key = path[-1] if path else ""
    if kind == "object":
        if "properties" not in node:
            return st.dictionaries(st.text(max_size=4), _SCALARS, max_size=2)
        return _object(node, root, path)
    if kind == "array":
        if "items" not in node:
            return st.lists(_SCALARS, max_size=2)
        low = node.get("minItems", 0)
        return st.lists(_node(node["items"], root, path), min_size=low, max_size=max(low, 2))
    if kind == "string":
        return _string(node, key)
    if kind == "integer":
        low = max(node.get("minimum", 0), 0)
        return st.integers(low, min(node.get("maximum", UINT32_MAX), UINT32_MAX))
    if kind == "number":
        return _number(node, path)
    if kind == "boolean":
        return st.booleans()
    msg = f"schema type {kind!r} at {'.'.join(path)} is not supported by this generator"
    raise NotImplementedError(msg)


def _string(node: Schema, key: str) -> st.SearchStrategy[str]:
    if key in _TIMESTAMP_KEYS or node.get("format") == "date-time":
        return timestamps()
    if key == "version":
        return st.sampled_from(["3.0.0", "3.0.1", "3.1.0"])
    return st.text(max_size=6)


def _number(node: Schema, path: Path) -> st.SearchStrategy[float]:
    low = node.get("minimum")
    exclusive = False
    if low is None and path[-1:] == ("weight",):
        low, exclusive = 0.0, True  # text: ]0.0 ... float64.max]
    if low is None and path[-2:-1] == ("loadDimensions",):
        low = 0.0  # text: as loads[] in the state message, whose schema bounds them by 0
    return st.floats(
        min_value=low,
        max_value=node.get("maximum"),
        exclude_min=exclusive,
        allow_nan=False,
        allow_infinity=False,
    )


def _object(node: Schema, root: Schema, path: Path) -> st.SearchStrategy[dict[str, Any]]:
    properties: dict[str, Schema] = node["properties"]
    required = set(node.get("required", ()))

    @st.composite
    def build(draw: st.DrawFn) -> dict[str, Any]:
        document: dict[str, Any] = {}
        for name, schema in properties.items():
            if name in required or draw(st.booleans()):
                document[name] = draw(_node(schema, root, (*path, name)))
        for clause in node.get("allOf", ()):
            condition = clause["if"]["properties"]
            if all(document.get(k) == v["const"] for k, v in condition.items()):
                then = clause["then"]
                for name in then.get("required", ()):
                    schema = then.get("properties", {}).get(name) or properties.get(name, {})
                    document[name] = draw(_node(schema, root, (*path, name)))
        return document

    return build()
