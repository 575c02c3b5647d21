"""Property-based tests: the codec never raises, and every failure has a reason."""

from __future__ import annotations

import json

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vda5050.codec import DecodeFailure, decode, encode
from vda5050.testing import make_order, make_state
from vda5050.topics import AgvId, Topic, TopicAddress

SEEDS = {
    Topic.ORDER: json.loads(encode(make_order(["a", "b", "c"], released=2))),
    Topic.STATE: json.loads(encode(make_state())),
}
ADDRESS = TopicAddress("uagv", 2, AgvId("acme", "robot_0"), Topic.STATE)

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda children: (
        st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=5), children, max_size=3)
    ),
    max_leaves=10,
)


def check(result: object) -> None:
    if isinstance(result, DecodeFailure):
        assert result.problems
        assert all(p.reason and p.path.startswith("$") for p in result.problems)
        assert result.summary()


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(list(Topic)), st.binary(max_size=300))
def test_random_bytes_never_raise(topic: Topic, raw: bytes) -> None:
    """Arbitrary bytes decode to a model or to a failure with reasons, never an exception."""
    check(decode(topic, raw, address=ADDRESS))


def _paths(value: object, prefix: tuple[object, ...] = ()) -> list[tuple[object, ...]]:
    found = [prefix]
    if isinstance(value, dict):
        for key, item in value.items():
            found += _paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            found += _paths(item, (*prefix, index))
    return found


def _replace(value: object, path: tuple[object, ...], new: object) -> object:
    if not path:
        return new
    head, rest = path[0], path[1:]
    if isinstance(value, dict):
        return {**value, head: _replace(value[head], rest, new)}
    if isinstance(value, list) and isinstance(head, int):
        copy = list(value)
        copy[head] = _replace(copy[head], rest, new)
        return copy
    return value


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(list(SEEDS)), st.data(), json_values)
def test_mutated_valid_messages_never_raise(topic: Topic, data: st.DataObject, new: object) -> None:
    """Replacing any part of a valid message with any JSON value decodes or fails with reasons."""
    seed = SEEDS[topic]
    path = data.draw(st.sampled_from(_paths(seed)))
    mutated = _replace(seed, path, new)
    raw = json.dumps(mutated, allow_nan=True).encode()
    result = decode(topic, raw, address=ADDRESS)
    check(result)
    if not isinstance(result, DecodeFailure):
        # Whatever decodes re-encodes to JSON that decodes to the same model.
        assert decode(topic, encode(result)) == result


@settings(max_examples=200)
@given(st.sampled_from(list(SEEDS)), st.data())
def test_truncated_messages_fail_with_reasons(topic: Topic, data: st.DataObject) -> None:
    """Any strict prefix of a valid message is a failure naming why."""
    raw = encode(make_order(["a", "b"])) if topic is Topic.ORDER else encode(make_state())
    cut = data.draw(st.integers(min_value=0, max_value=len(raw) - 1))
    result = decode(topic, raw[:cut])
    assert isinstance(result, DecodeFailure)
    check(result)
