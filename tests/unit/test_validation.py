"""The order semantic check (digest R21-R26), as a pure function returning VDA 5050 errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.spec_files import VERSIONS, example_files, needs_examples
from vda5050.codec import decode_as
from vda5050.models import BlockingType, ErrorLevel, Order
from vda5050.testing import make_action, make_order
from vda5050.topics import Topic
from vda5050.validation import check_order


def descriptions(order: Order, **kwargs: int) -> list[str]:
    errors = check_order(order, **kwargs)
    for error in errors:
        assert error.error_type == "validationError"
        assert error.error_level is ErrorLevel.WARNING
        keys = {ref.reference_key for ref in error.error_references or []}
        assert {"orderId", "orderUpdateId", "headerId", "topic"} <= keys
    return [error.error_description or "" for error in errors]


def with_nodes(order: Order, **changes: object) -> Order:
    return order.model_copy(update=changes)


def test_well_formed_order_passes() -> None:
    """A base-and-horizon order with correct sequenceIds and endpoints has no errors."""
    assert check_order(make_order(["a", "b", "c", "d"], released=2)) == []
    assert check_order(make_order(["a"])) == []


def test_empty_nodes_is_rejected() -> None:
    """R21: an order needs at least one node."""
    assert descriptions(with_nodes(make_order(["a"]), nodes=[], edges=[]))[0].startswith("R21")


def test_edge_count_must_be_nodes_minus_one() -> None:
    """R22: len(edges) == len(nodes) - 1."""
    order = make_order(["a", "b", "c"])
    found = descriptions(with_nodes(order, edges=order.edges[:1]))
    assert any(d.startswith("R22") and "needs 2 edges, got 1" in d for d in found)


def test_released_edge_with_unreleased_end_node_is_rejected() -> None:
    """R23: an edge may be released only if both its nodes are released."""
    order = make_order(["a", "b", "c"], released=1)
    edges = [order.edges[0].model_copy(update={"released": True}), order.edges[1]]
    assert any(d.startswith("R23") for d in descriptions(with_nodes(order, edges=edges)))


def test_released_after_unreleased_is_rejected() -> None:
    """R24: the released elements form a prefix of the order."""
    order = make_order(["a", "b", "c"], released=1)
    nodes = [order.nodes[0], order.nodes[1], order.nodes[2].model_copy(update={"released": True})]
    assert any(d.startswith("R24") for d in descriptions(with_nodes(order, nodes=nodes)))


def test_unreleased_first_node_is_rejected() -> None:
    """R24 (derived): an order without a base is a validation error."""
    found = descriptions(make_order(["a", "b"], released=0))
    assert any("first node must be released" in d for d in found)


@pytest.mark.derived
def test_sequence_ids_must_alternate_from_zero() -> None:
    """R25: a new order numbers node, edge, node ... 0, 1, 2, ..."""
    order = make_order(["a", "b", "c"])
    nodes = [*order.nodes[:2], order.nodes[2].model_copy(update={"sequence_id": 6})]
    found = descriptions(with_nodes(order, nodes=nodes))
    assert any(d.startswith("R25") and "expected 4" in d for d in found)
    assert any(
        "must have sequenceId 0" in d
        for d in descriptions(make_order(["a", "b"], first_sequence_id=2), first_sequence_id=0)
    )


@pytest.mark.derived
def test_update_continues_numbering_from_the_stitching_node() -> None:
    """R25: an update starts at the decision point's sequenceId and counts on from there."""
    update = make_order(["g", "b", "h"], order_update_id=1, first_sequence_id=4)
    assert check_order(update, first_sequence_id=4) == []
    assert any(
        "must be even" in d for d in descriptions(make_order(["g", "b"], first_sequence_id=3))
    )


@pytest.mark.derived
def test_edge_endpoints_must_match_neighbouring_nodes() -> None:
    """R26: edges[i] runs from nodes[i] to nodes[i+1]."""
    order = make_order(["a", "b", "c"])
    edges = [order.edges[0], order.edges[1].model_copy(update={"end_node_id": "a"})]
    found = descriptions(with_nodes(order, edges=edges))
    assert any(d.startswith("R26") and "'b-c'" in d for d in found)


def test_duplicate_action_ids_are_rejected() -> None:
    """actionIds are unique within an order (§6.6.6)."""
    beep = make_action("beep", "x", BlockingType.NONE)
    order = make_order(["a", "b"], node_actions={"a": [beep], "b": [beep]})
    assert any("'x' is used more than once" in d for d in descriptions(order))


EXPECTED_RULE = {
    "order_edgecount_mismatch.json": "R22",
    "order_released_after_unreleased.json": "R24",
    "order_released_edge_unreleased_endnode.json": "R23",
    "order_bad_sequenceIds.json": "R25",
    "order_edge_endpoints_mismatch.json": "R26",
    # Stitches at (d, 2) and jumps to 6: R25 fails on its own; the vehicle's decision also
    # checks the decision point (vehicle tests).
    "order_update_bad_stitch.json": "R25",
}


@needs_examples
@pytest.mark.parametrize(
    "path",
    [p for v in VERSIONS for p in example_files(v, "semantic_invalid") if p.name in EXPECTED_RULE],
    ids=lambda p: f"{p.parent.parent.name}/{p.name}",
)
def test_semantic_invalid_examples_fail_naming_the_rule(path: Path) -> None:
    """Each schema-valid but semantically invalid example order fails the check naming its rule."""
    order = decode_as(Order, Topic.ORDER, path.read_bytes())
    assert isinstance(order, Order)
    first = 0 if order.order_update_id == 0 else None
    found = descriptions(order, **({"first_sequence_id": first} if first is not None else {}))
    assert any(d.startswith(EXPECTED_RULE[path.name]) for d in found), found


@needs_examples
@pytest.mark.parametrize("version", VERSIONS)
def test_resend_example_is_well_formed_on_its_own(version: str) -> None:
    """The duplicate-update example is a valid order: discarding it is the vehicle's decision."""
    (path,) = [
        p
        for p in example_files(version, "semantic_invalid")
        if p.name == "order_update_same_id_resend.json"
    ]
    order = decode_as(Order, Topic.ORDER, path.read_bytes())
    assert isinstance(order, Order)
    assert check_order(order) == []
