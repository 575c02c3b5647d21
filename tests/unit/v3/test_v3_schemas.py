"""schemas/3.0.0 is generated from the 3.0 models; the models agree with the official 3.0.0
schemas on random documents, and what the factories build passes both schemas."""

from __future__ import annotations

import json
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from jsonschema import Draft202012Validator, FormatChecker
from pydantic import ValidationError

from tests.spec_files import needs_official_schemas, official_schema
from tests.unit.v3.official_documents import documents
from vda5050 import schemas
from vda5050.codec import MODEL_BY_TOPIC_V3, encode
from vda5050.models import v3
from vda5050.testing import (
    make_action_v3,
    make_connection_v3,
    make_factsheet_v3,
    make_instant_action_v3,
    make_instant_actions_v3,
    make_order_v3,
    make_responses_v3,
    make_state_v3,
    make_stitching_update_v3,
    make_visualization_v3,
    make_zone_set_v3,
    make_zone_v3,
)
from vda5050.topics import V3_TOPICS, Topic

TOPICS = sorted(V3_TOPICS, key=list(Topic).index)
RANDOM = settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def official(topic: Topic) -> Draft202012Validator:
    return Draft202012Validator(
        official_schema("3.0.0", topic.value), format_checker=FormatChecker()
    )


def test_a_3_0_0_schema_per_topic_without_2x_markers() -> None:
    """T02: schemas/3.0.0 holds one schema per 3.0 topic, valid Draft 2020-12, with no 2.1-only
    marker and with the 3.0 header required everywhere (T10)."""
    for topic in TOPICS:
        schema = schemas.load_schema(f"3.0.0/{topic.value}.schema.json")
        Draft202012Validator.check_schema(schema)
        assert "x-vda5050-since" not in json.dumps(schema)
        required = schema["required"]
        assert isinstance(required, list)
        assert {"headerId", "timestamp", "version", "manufacturer", "serialNumber"} <= set(required)


def factory_messages() -> dict[Topic, v3.V3Message]:
    order = make_order_v3(
        ["a", "b", "c"],
        released=2,
        deviation=v3.AllowedDeviationXY(a=0.5, b=0.2, theta=0.3),
        node_actions={1: [make_action_v3("pick", "p", v3.BlockingType.HARD, retriable=True)]},
    )
    return {
        Topic.ORDER: make_stitching_update_v3(
            order, ["d"], decision_point_actions=[make_action_v3("beep", "b")]
        ),
        Topic.INSTANT_ACTIONS: make_instant_actions_v3(
            make_instant_action_v3("cancelOrder", "c", orderId="order-1")
        ),
        Topic.STATE: make_state_v3(),
        Topic.VISUALIZATION: make_visualization_v3(7),
        Topic.CONNECTION: make_connection_v3(v3.ConnectionState.HIBERNATING),
        Topic.FACTSHEET: make_factsheet_v3(supported_zones=[v3.ZoneType.SPEED_LIMIT]),
        Topic.ZONE_SET: make_zone_set_v3(
            make_zone_v3("slow", v3.ZoneType.SPEED_LIMIT, maximum_speed=0.3),
            make_zone_v3(
                "door", v3.ZoneType.RELEASE, release_loss_behavior=v3.ZoneReleaseLossBehavior.STOP
            ),
        ),
        Topic.RESPONSES: make_responses_v3(("r1", v3.GrantType.QUEUED)),
    }


@needs_official_schemas
@pytest.mark.parametrize("topic", TOPICS)
def test_factory_messages_pass_both_schemas(topic: Topic) -> None:
    """What the 3.0 factories build passes our schema and the official 3.0.0 schema."""
    document = json.loads(encode(factory_messages()[topic]))
    ours = schemas.validator(f"3.0.0/{topic.value}.schema.json")
    assert not list(ours.iter_errors(document))
    errors = list(official(topic).iter_errors(document))
    assert not errors, errors[0].message


@needs_official_schemas
@pytest.mark.parametrize("topic", TOPICS)
def test_models_accept_what_the_official_schema_accepts(topic: Topic) -> None:
    """Any document the official schema accepts (within the documented text-over-schema
    tightenings, docs/vda5050-3.md §A) decodes with our 3.0 model and passes our schema."""
    schema = official_schema("3.0.0", topic.value)
    validator = official(topic)
    ours = schemas.validator(f"3.0.0/{topic.value}.schema.json")
    model = MODEL_BY_TOPIC_V3[topic]

    @RANDOM
    @given(documents(schema))
    def check(document: Any) -> None:
        assert not list(validator.iter_errors(document)), "generator drew an invalid document"
        model.model_validate_json(json.dumps(document), strict=True)
        assert not list(ours.iter_errors(document))

    check()


def _leaves(value: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    found = [prefix] if prefix else []
    if isinstance(value, dict):
        for key, item in value.items():
            found += _leaves(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            found += _leaves(item, (*prefix, index))
    return found


def _other_type(value: Any) -> Any:
    if isinstance(value, bool):
        return "true"
    if isinstance(value, int | float):
        return str(value)
    if isinstance(value, str):
        return 7
    if isinstance(value, list):
        return {"not": "a list"}
    return ["not", "an object"]


def _mutated(document: Any, path: tuple[Any, ...], delete: bool) -> Any:
    copy = json.loads(json.dumps(document))
    parent = copy
    for step in path[:-1]:
        parent = parent[step]
    if delete and isinstance(parent, dict):
        del parent[path[-1]]
    else:
        parent[path[-1]] = _other_type(parent[path[-1]])
    return copy


@needs_official_schemas
@pytest.mark.parametrize("topic", TOPICS)
def test_models_reject_what_the_official_schema_rejects(topic: Topic) -> None:
    """A valid document with one value of the wrong JSON type, or one field removed, that the
    official schema rejects is rejected by our model too (we are never looser, except for
    null, which the models read as an absent optional field)."""
    schema = official_schema("3.0.0", topic.value)
    validator = official(topic)
    model = MODEL_BY_TOPIC_V3[topic]

    @RANDOM
    @given(documents(schema), st.data(), st.booleans())
    def check(document: Any, data: st.DataObject, delete: bool) -> None:
        paths = _leaves(document)
        path = data.draw(st.sampled_from(paths))
        broken = _mutated(document, path, delete)
        if not list(validator.iter_errors(broken)):
            return  # the official schema still accepts it: nothing to compare
        with pytest.raises(ValidationError):
            model.model_validate_json(json.dumps(broken), strict=True)

    check()
