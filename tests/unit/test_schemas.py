"""schemas/ is generated from the models and agrees with the official schemas on the examples."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator, FormatChecker

from tests.spec_files import (
    VERSIONS,
    example_files,
    needs_examples,
    needs_official_schemas,
    official_schema,
    topic_of_example,
)
from vda5050 import schemas
from vda5050.codec import encode
from vda5050.models.base import SINCE_2_1
from vda5050.testing import make_order, make_state
from vda5050.topics import V2_TOPICS


def test_committed_schemas_are_up_to_date() -> None:
    """Every file under schemas/ equals what the models generate (run python -m vda5050.schemas)."""
    for name, schema in schemas.build_all().items():
        path = schemas.repository_schema_dir() / name
        assert path.is_file(), f"{name} is missing; run python -m vda5050.schemas"
        assert path.read_text(encoding="utf-8") == schemas.render(schema), (
            f"{name} is stale; run python -m vda5050.schemas"
        )


def test_check_mode_reports_stale_files(tmp_path: Path) -> None:
    """The generator's --check exits 1 on a stale tree and 0 once written."""
    assert schemas.main(["--check", "--out", str(tmp_path)]) == 1
    assert schemas.main(["--out", str(tmp_path)]) == 0
    assert schemas.main(["--check", "--out", str(tmp_path)]) == 0


def test_schemas_are_valid_draft_2020_12() -> None:
    """Each generated schema is itself a valid Draft 2020-12 schema."""
    for name in schemas.build_all():
        Draft202012Validator.check_schema(schemas.load_schema(name))


def test_2_0_schemas_leave_out_2_1_only_fields() -> None:
    """corridor, maps, errorHint and vehicleConfig exist in the 2.1.0 schemas only."""
    marker = next(iter(SINCE_2_1))
    for topic in V2_TOPICS:
        assert marker not in json.dumps(schemas.load_schema(f"2.0.0/{topic.value}.schema.json"))
    assert "vehicleConfig" in schemas.load_schema("2.1.0/factsheet.schema.json")["properties"]  # type: ignore[operator]
    assert "maps" in schemas.load_schema("2.1.0/state.schema.json")["properties"]  # type: ignore[operator]
    assert "maps" not in schemas.load_schema("2.0.0/state.schema.json")["properties"]  # type: ignore[operator]


@needs_examples
@pytest.mark.parametrize("version", VERSIONS)
def test_examples_validate_against_the_project_schemas(version: str) -> None:
    """Valid examples pass our schemas; schema-invalid examples fail them."""
    for path in example_files(version):
        validator = schemas.validator(f"{version}/{topic_of_example(path)}.schema.json")
        errors = list(validator.iter_errors(json.loads(path.read_bytes())))
        assert not errors, f"{path.name}: {errors[0].message}"
    for path in example_files(version, "schema_invalid"):
        validator = schemas.validator(f"{version}/{topic_of_example(path)}.schema.json")
        assert list(validator.iter_errors(json.loads(path.read_bytes()))), path.name


@needs_official_schemas
@pytest.mark.parametrize("version", VERSIONS)
def test_factory_messages_validate_against_the_official_schemas(version: str) -> None:
    """What our models emit is accepted by the official (patched) schemas."""
    samples = {
        "order": make_order(["a", "b", "c"], released=2, version=version),
        "state": make_state(version=version),
    }
    for topic, message in samples.items():
        validator = Draft202012Validator(
            official_schema(version, topic), format_checker=FormatChecker()
        )
        errors = list(validator.iter_errors(json.loads(encode(message))))
        assert not errors, f"{topic}: {errors[0].message}"


def test_graph_schema_describes_the_graph_file() -> None:
    """graph.schema.json accepts the documented format and rejects an unknown key."""
    validator = schemas.validator(schemas.GRAPH_SCHEMA)
    good = {
        "mapId": "demo",
        "nodes": [{"nodeId": "7", "x": 0.0, "y": 0.0, "theta": 0.0}],
        "edges": [{"edgeId": "17", "startNodeId": "7", "endNodeId": "1"}],
    }
    assert not list(validator.iter_errors(good))
    assert list(validator.iter_errors({**good, "nodes": [{"nodeId": "7", "x": 0, "y": 0, "z": 1}]}))
