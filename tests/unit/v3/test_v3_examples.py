"""The hand-written 3.0.0 examples against the models, our generated schemas and the official
3.0.0 schemas: valid ones pass all three, invalid ones fail all three."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator, FormatChecker

from tests.spec_files import (
    needs_official_schemas,
    official_schema,
    topic_of_example,
    v3_example_files,
    v3_invalid_rules,
)
from vda5050 import schemas
from vda5050.codec import DecodeFailure, decode, encode
from vda5050.models import v3
from vda5050.topics import AgvId, Topic, TopicAddress

VALID = v3_example_files()
INVALID = v3_example_files("schema_invalid")


def address_of(path: Path) -> TopicAddress:
    return TopicAddress(
        "vda5050", 3, AgvId("ExampleCorp", "MR-0001"), Topic(topic_of_example(path))
    )


def official_validator(topic: str) -> Draft202012Validator:
    return Draft202012Validator(official_schema("3.0.0", topic), format_checker=FormatChecker())


def test_every_topic_has_valid_and_invalid_examples() -> None:
    """The example set covers each of the eight 3.0 topics with at least one valid and one
    invalid message."""
    assert {topic_of_example(p) for p in VALID} == {t.value for t in Topic}
    assert {topic_of_example(p) for p in INVALID} == {t.value for t in Topic}
    assert set(v3_invalid_rules()) == {p.name for p in INVALID}


@pytest.mark.parametrize("path", VALID, ids=lambda p: p.name)
def test_valid_examples_decode_and_reencode_to_equal_json(path: Path) -> None:
    """T10, T16: every valid example decodes on its v3 topic into the 3.0 model, and encoding it
    gives back the same JSON document."""
    raw = path.read_bytes()
    message = decode(Topic(topic_of_example(path)), raw, address=address_of(path))
    assert not isinstance(message, DecodeFailure), message.summary()
    assert message.vda_major == 3
    assert json.loads(encode(message)) == json.loads(raw)


@pytest.mark.parametrize("path", VALID, ids=lambda p: p.name)
def test_valid_examples_pass_our_schema(path: Path) -> None:
    """Each valid example passes the generated schemas/3.0.0 schema of its topic."""
    validator = schemas.validator(f"3.0.0/{topic_of_example(path)}.schema.json")
    errors = list(validator.iter_errors(json.loads(path.read_bytes())))
    assert not errors, errors[0].message


@needs_official_schemas
@pytest.mark.parametrize("path", VALID, ids=lambda p: p.name)
def test_valid_examples_pass_the_official_schema(path: Path) -> None:
    """Each valid example passes the official 3.0.0 schema of its topic."""
    errors = list(
        official_validator(topic_of_example(path)).iter_errors(json.loads(path.read_bytes()))
    )
    assert not errors, errors[0].message


@pytest.mark.parametrize("path", INVALID, ids=lambda p: p.name)
def test_invalid_examples_fail_decoding_at_the_named_path(path: Path) -> None:
    """Each invalid example fails decoding, and the failure names the JSON path _rules.json
    gives (the rule it breaks is cited there)."""
    rule = v3_invalid_rules()[path.name]
    result = decode(Topic(topic_of_example(path)), path.read_bytes(), address=address_of(path))
    assert isinstance(result, DecodeFailure), f"{path.name} decoded ({rule['rule']})"
    paths = [problem.path for problem in result.problems]
    assert rule["path"] in paths, (rule, paths)


@pytest.mark.parametrize("path", INVALID, ids=lambda p: p.name)
def test_invalid_examples_fail_our_schema(path: Path) -> None:
    """Each invalid example fails the generated 3.0.0 schema too."""
    validator = schemas.validator(f"3.0.0/{topic_of_example(path)}.schema.json")
    assert list(validator.iter_errors(json.loads(path.read_bytes())))


@needs_official_schemas
@pytest.mark.parametrize("path", INVALID, ids=lambda p: p.name)
def test_invalid_examples_fail_the_official_schema(path: Path) -> None:
    """Each invalid example also fails the official 3.0.0 schema, so none of them is a case
    where we are merely stricter than upstream."""
    document = json.loads(path.read_bytes())
    assert list(official_validator(topic_of_example(path)).iter_errors(document))


def test_stitching_example_follows_figure_7() -> None:
    """T40, T41: the update example resends the decision point g unchanged and appends g again
    with sequenceId + 2 carrying the new action."""
    initial = v3.Order.model_validate_json(
        (Path(VALID[0]).parent / "order_initial.json").read_bytes()
    )
    update = v3.Order.model_validate_json(
        (Path(VALID[0]).parent / "order_update_stitching.json").read_bytes()
    )
    decision = initial.decision_point()
    assert decision is not None
    assert update.nodes[0] == decision
    appended = update.nodes[1]
    assert (appended.node_id, appended.sequence_id) == (decision.node_id, decision.sequence_id + 2)
    assert appended.node_position == decision.node_position
    assert [a.action_id for a in appended.actions] == ["a-fine-1"]
