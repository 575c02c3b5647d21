"""Static checks of 3.0 orders (validation3) and the 3.0 order factories they rely on."""

from __future__ import annotations

import pytest

from vda5050.models import v3
from vda5050.testing import make_action_v3, make_order_v3, make_stitching_update_v3
from vda5050.validation3 import check_order


def descriptions(order: v3.Order, **kwargs: int) -> list[str]:
    errors = check_order(order, **kwargs)
    assert all(e.error_type == v3.ErrorType.VALIDATION_FAILURE for e in errors)
    assert all(e.error_level is v3.ErrorLevel.WARNING for e in errors)
    return [e.error_description or "" for e in errors]


def test_factory_orders_are_well_formed() -> None:
    """T17-T19: the factory builds orders that pass every static check, horizon or not."""
    assert check_order(make_order_v3(["a", "b", "c"]), first_sequence_id=0) == []
    assert check_order(make_order_v3(["a", "b", "c", "d"], released=2)) == []
    assert check_order(make_order_v3(["a"])) == []


def test_empty_order_is_rejected() -> None:
    """T17: an order needs at least one node."""
    order = make_order_v3(["a"]).model_copy(update={"nodes": [], "edges": []})
    assert descriptions(order) == ["T17: an order needs at least one node"]


def test_edge_count_must_be_node_count_minus_one() -> None:
    """T17: n nodes need n - 1 edges."""
    order = make_order_v3(["a", "b", "c"])
    short = order.model_copy(update={"edges": order.edges[:1]})
    assert any(
        d.startswith("T17: an order with 3 nodes needs 2 edges") for d in descriptions(short)
    )


def test_sequence_ids_must_run_continuously() -> None:
    """T18: sequenceIds alternate node, edge, node from the first node's (even) value."""
    order = make_order_v3(["a", "b", "c"])
    bumped = order.model_copy(
        update={"nodes": [*order.nodes[:2], order.nodes[2].model_copy(update={"sequence_id": 6})]}
    )
    assert any("nodeId 'c' has 6, expected 4" in d for d in descriptions(bumped))
    assert any(
        d.startswith("T18: the first node's sequenceId must be even")
        for d in descriptions(make_order_v3(["a", "b"], first_sequence_id=3))
    )
    assert any(
        d.startswith("T18: the first node must have sequenceId 0")
        for d in descriptions(make_order_v3(["a", "b"], first_sequence_id=2), first_sequence_id=0)
    )


def test_release_rules() -> None:
    """T19: the first node is released, released edges join released nodes, and nothing
    released follows the horizon."""
    order = make_order_v3(["a", "b", "c"], released=1)
    nodes = [node.model_copy(update={"released": False}) for node in order.nodes]
    assert any(
        "first node must be released" in d
        for d in descriptions(order.model_copy(update={"nodes": nodes}))
    )
    edge = order.edges[0].model_copy(update={"released": True})
    texts = descriptions(order.model_copy(update={"edges": [edge, order.edges[1]]}))
    assert any("released edge 'a-b' joins unreleased node 'b'" in d for d in texts)
    late = order.nodes[2].model_copy(update={"released": True})
    texts = descriptions(order.model_copy(update={"nodes": [*order.nodes[:2], late]}))
    assert any("released nodeId 'c'" in d and "follows an unreleased" in d for d in texts)


def test_duplicate_action_ids_are_rejected() -> None:
    """T20: actionIds are unique within an order."""
    order = make_order_v3(
        ["a", "b"],
        node_actions={0: [make_action_v3("beep", "x")], 1: [make_action_v3("beep", "x")]},
    )
    assert any("actionId 'x' is used more than once" in d for d in descriptions(order))


def test_errors_reference_the_order() -> None:
    """T20: a VALIDATION_FAILURE names headerId, topic, orderId and orderUpdateId."""
    order = make_order_v3(["a"], order_id="o-7", order_update_id=2).model_copy(
        update={"nodes": [], "edges": []}
    )
    (error,) = check_order(order)
    assert error.reference("orderId") == "o-7"
    assert error.reference("orderUpdateId") == "2"
    assert error.reference("topic") == "order"


def test_stitching_update_resends_the_decision_point_unchanged() -> None:
    """T39, T40: the update keeps orderId, raises orderUpdateId, starts with the unchanged
    decision point (its actions included) and continues its sequenceIds."""
    first = make_order_v3(
        ["a", "b", "c", "d"], released=3, node_actions={2: [make_action_v3("beep", "c1")]}
    )
    update = make_stitching_update_v3(first, ["x", "y"], released=1)
    decision = first.decision_point()
    assert update.nodes[0] == decision
    assert (update.order_id, update.order_update_id) == (first.order_id, 1)
    assert [n.sequence_id for n in update.nodes] == [4, 6, 8]
    assert [n.released for n in update.nodes] == [True, True, False]
    assert check_order(update, first_sequence_id=4) == []


def test_new_actions_at_the_decision_point_go_on_an_appended_node() -> None:
    """T41: actions for the decision point ride on a node with the same id and position and
    sequenceId + 2; the decision point itself is resent as it was."""
    first = make_order_v3(["a", "b"], node_actions={1: [make_action_v3("beep", "b1")]})
    update = make_stitching_update_v3(
        first, ["c"], decision_point_actions=[make_action_v3("pick", "p1", v3.BlockingType.HARD)]
    )
    stitch, appended = update.nodes[0], update.nodes[1]
    assert [a.action_id for a in stitch.actions] == ["b1"]
    assert (appended.node_id, appended.sequence_id) == ("b", stitch.sequence_id + 2)
    assert appended.node_position == stitch.node_position
    assert [a.action_id for a in appended.actions] == ["p1"]
    assert update.edges[0].sequence_id == stitch.sequence_id + 1
    assert check_order(update, first_sequence_id=2) == []


def test_stitching_needs_a_positioned_decision_point() -> None:
    """A factory misuse (nothing to stitch onto) raises at once."""
    order = make_order_v3(["a"]).model_copy(
        update={"nodes": [make_order_v3(["a"]).nodes[0].model_copy(update={"node_position": None})]}
    )
    with pytest.raises(ValueError, match="no released, positioned node"):
        make_stitching_update_v3(order, ["b"])
