"""Factsheet constraints on what master control sends (§6.1.1, §6.15; R112–R114)."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from vda5050.models import ActionScope, BlockingType
from vda_master import capabilities as caps
from vda_master.capabilities import ActionSpec
from vda_master.testing import make_factsheet


def test_unlisted_field_is_unsupported() -> None:
    """An optional field the factsheet does not list is not sent (R112)."""
    assert not caps.supports_field(make_factsheet(supported=[]), caps.EDGE_LENGTH)


def test_a_listed_sub_path_implies_its_parents_only() -> None:
    """``order.nodes.nodePosition.theta`` lists nodePosition too (the object that holds it);
    a longer name that merely starts with the same letters does not (R112)."""
    factsheet = make_factsheet(supported=[caps.NODE_THETA, "order.edges.lengthX"])
    assert caps.supports_field(factsheet, caps.NODE_THETA)
    assert caps.supports_field(factsheet, caps.NODE_POSITION)
    assert caps.supports_field(factsheet, "order.nodes")
    assert not caps.supports_field(factsheet, caps.NODE_DEVIATION_XY)
    assert not caps.supports_field(factsheet, caps.EDGE_LENGTH)


_PATHS = st.text(alphabet="ab.", min_size=1, max_size=6)


@given(listed=st.lists(_PATHS, max_size=5), asked=_PATHS)
def test_a_field_is_supported_when_it_or_a_sub_path_is_listed(
    listed: list[str], asked: str
) -> None:
    """R112 as the definition says it: supported when listed itself, or when a listed path
    continues it after a dot."""
    factsheet = make_factsheet(supported=listed)
    expected = any(p == asked or p.startswith(asked + ".") for p in listed)
    assert caps.supports_field(factsheet, asked) == expected


def test_each_factsheet_answers_for_itself() -> None:
    """Answers are kept per factsheet: a vehicle's new factsheet is read afresh."""
    narrow, wide = make_factsheet(supported=[]), make_factsheet(supported=[caps.EDGE_LENGTH])
    assert not caps.supports_field(narrow, caps.EDGE_LENGTH)
    assert caps.supports_field(wide, caps.EDGE_LENGTH)
    assert not caps.supports_field(narrow, caps.EDGE_LENGTH)


def test_factsheets_that_share_their_protocol_features_share_the_answer() -> None:
    """Vehicles of one type (factsheets decoded through SharedBodies hold one protocolFeatures
    object) get the same answers; a copy with other features is read afresh."""
    first = make_factsheet(supported=[caps.EDGE_LENGTH])
    second = first.model_copy(update={"serial_number": "another"})
    other = make_factsheet(supported=[])
    changed = first.model_copy(update={"protocol_features": other.protocol_features})
    assert caps.supports_field(first, caps.EDGE_LENGTH)
    assert caps.supports_field(second, caps.EDGE_LENGTH)
    assert not caps.supports_field(changed, caps.EDGE_LENGTH)
    assert caps.supports_field(first, caps.EDGE_LENGTH)


def test_without_factsheet_every_fillable_field_is_sent() -> None:
    """A factsheet narrows, it does not permit: without one, nodePosition and the other fields
    every vehicle can honour or ignore are sent; fields the master cannot fill are not."""
    assert caps.supports_field(None, caps.NODE_POSITION)
    assert caps.supports_field(None, caps.NODE_DEVIATION_XY)
    assert caps.supports_field(None, caps.EDGE_MAX_SPEED)
    assert not caps.supports_field(None, "order.edges.trajectory")


def test_without_factsheet_actions_are_sent_as_asked() -> None:
    """A vehicle without a factsheet gets the requested action with a sensible blocking type."""
    spec = ActionSpec("pick", parameters={"loadType": "EPAL"})
    resolved = caps.resolve_action(None, spec, ActionScope.NODE)
    assert resolved == (BlockingType.HARD, {"loadType": "EPAL"})


def test_without_factsheet_predefined_scopes_still_apply() -> None:
    """pick as an instant action is refused even without a factsheet (§6.8.1 scopes)."""
    problem = caps.resolve_action(None, ActionSpec("pick"), ActionScope.INSTANT)
    assert isinstance(problem, str)
    assert "not allowed as INSTANT" in problem


def test_required_fields_are_collected() -> None:
    """REQUIRED entries are reported so they are always filled in (R113)."""
    factsheet = make_factsheet(supported=[], required=[caps.EDGE_LENGTH])
    assert caps.required_fields(factsheet) == {caps.EDGE_LENGTH}
    assert caps.supports_field(factsheet, caps.EDGE_LENGTH)


def test_node_limit_takes_the_tighter_of_nodes_and_edges() -> None:
    """order.edges = 2 limits a message to three nodes even with order.nodes = 10 (R114)."""
    factsheet = make_factsheet(array_lens={"order.nodes": 10, "order.edges": 2})
    assert caps.max_order_nodes(factsheet) == 3


def test_zero_limit_means_no_limit() -> None:
    """A limit of 0 means no explicit limit (§6.15)."""
    assert caps.max_order_nodes(make_factsheet(array_lens={"order.nodes": 0})) is None


def test_min_order_interval_comes_from_timing() -> None:
    """minOrderInterval is read from protocolLimits.timing (R114)."""
    assert caps.min_order_interval_s(make_factsheet(min_order_interval=0.5)) == 0.5
    assert caps.min_order_interval_s(None) == 0.0


def test_message_size_limit() -> None:
    """A message over msgLen bytes is reported (R114)."""
    factsheet = make_factsheet(string_lens={"msgLen": 100})
    assert caps.message_size_problem(factsheet, 100) is None
    assert caps.message_size_problem(factsheet, 101) is not None


def test_instant_action_resolves_with_default_blocking() -> None:
    """A declared instant action without blockingType gets NONE and its parameters."""
    resolved = caps.resolve_action(make_factsheet(), ActionSpec("startPause"), ActionScope.INSTANT)
    assert resolved == (BlockingType.NONE, {})


def test_blocking_type_outside_the_declared_ones_is_refused() -> None:
    """A blockingType the 2.1 factsheet does not allow for the action is refused."""
    actions = [{"actionType": "beep", "actionScopes": ["INSTANT"], "blockingTypes": ["NONE"]}]
    spec = ActionSpec("beep", BlockingType.HARD)
    resolved = caps.resolve_action(make_factsheet(actions=actions), spec, ActionScope.INSTANT)
    assert isinstance(resolved, str)
    assert "does not allow blockingType HARD" in resolved


def test_default_blocking_type_follows_declared_ones() -> None:
    """When the default is not declared, the first declared blockingType is used."""
    actions = [{"actionType": "pick", "actionScopes": ["NODE"], "blockingTypes": ["SOFT"]}]
    resolved = caps.resolve_action(
        make_factsheet(actions=actions), ActionSpec("pick"), ActionScope.NODE
    )
    assert resolved == (BlockingType.SOFT, {})


def test_missing_mandatory_parameter_is_refused() -> None:
    """A declared parameter that is not optional must be given."""
    actions = [
        {
            "actionType": "waitForTrigger",
            "actionScopes": ["NODE"],
            "actionParameters": [{"key": "triggerType", "valueDataType": "STRING"}],
        }
    ]
    factsheet = make_factsheet(actions=actions)
    resolved = caps.resolve_action(factsheet, ActionSpec("waitForTrigger"), ActionScope.NODE)
    assert resolved == "action 'waitForTrigger' needs parameter 'triggerType'"
