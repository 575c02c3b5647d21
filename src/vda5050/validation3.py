"""Semantic checks of a 3.0 order that a JSON schema cannot express (3.0 §6.1.1, §6.1.2, §7.3).

Pure functions: they return 3.0 error objects (``VALIDATION_FAILURE``, level WARNING, with
errorReferences, T20) and never raise. Each description starts with the rule id of
``docs/vda5050-3.md`` it enforces. 3.0 edges carry no start/end node ids: edge n joins the nodes
n-1 and n+1 by sequenceId (T18), so the 2.x endpoint check (R26) has no 3.0 counterpart.
"""

from __future__ import annotations

from collections.abc import Iterator

from vda5050.models import v3
from vda5050.topics import Topic
from vda5050.validation import repeated_ids


def order_references(order: v3.Order, *extra: tuple[str, str]) -> list[v3.ErrorReference]:
    """errorReferences that point at ``order`` (§6.6.5.2): headerId, topic, orderId,
    orderUpdateId."""
    pairs = [
        ("headerId", str(order.header_id)),
        ("topic", Topic.ORDER.value),
        ("orderId", order.order_id),
        ("orderUpdateId", str(order.order_update_id)),
        *extra,
    ]
    return [v3.ErrorReference(reference_key=key, reference_value=value) for key, value in pairs]


def validation_failure(order: v3.Order, description: str, *extra: tuple[str, str]) -> v3.Error:
    """A ``VALIDATION_FAILURE`` WARNING about ``order`` (§6.1.4.1, T20)."""
    return v3.Error(
        error_type=v3.ErrorType.VALIDATION_FAILURE,
        error_level=v3.PREDEFINED_ERROR_LEVELS[v3.ErrorType.VALIDATION_FAILURE],
        error_description=description,
        error_references=order_references(order, *extra),
    )


def check_order(order: v3.Order, *, first_sequence_id: int | None = None) -> list[v3.Error]:
    """Return every static rule ``order`` breaks; an empty list means it is well-formed.

    ``first_sequence_id`` is the sequenceId the first node must carry: 0 for a new order, the
    decision point's for an update. Without it the first node only has to carry an even number.
    """
    if not order.nodes:
        return [validation_failure(order, "T17: an order needs at least one node")]
    errors: list[v3.Error] = []
    if len(order.edges) != len(order.nodes) - 1:
        errors.append(
            validation_failure(
                order,
                f"T17: an order with {len(order.nodes)} nodes needs {len(order.nodes) - 1} edges, "
                f"got {len(order.edges)}",
            )
        )
    if not order.nodes[0].released:
        errors.append(
            validation_failure(
                order,
                "T19: the first node must be released",
                ("nodeId", order.nodes[0].node_id),
            )
        )
    errors.extend(_release_errors(order))
    errors.extend(_sequence_errors(order, first_sequence_id))
    errors.extend(_duplicate_action_errors(order))
    return errors


def _elements(order: v3.Order) -> Iterator[v3.Node | v3.Edge]:
    """node0, edge0, node1, edge1, ... in traversal order."""
    for index, node in enumerate(order.nodes):
        yield node
        if index < len(order.edges):
            yield order.edges[index]


def _reference(element: v3.Node | v3.Edge) -> tuple[str, str]:
    if isinstance(element, v3.Node):
        return ("nodeId", element.node_id)
    return ("edgeId", element.edge_id)


def _release_errors(order: v3.Order) -> list[v3.Error]:
    errors: list[v3.Error] = []
    horizon_started = False
    for element in _elements(order):
        key, value = _reference(element)
        if not element.released:
            horizon_started = True
        elif horizon_started:
            errors.append(
                validation_failure(
                    order,
                    f"T19: released {key} {value!r} (sequenceId {element.sequence_id}) follows "
                    "an unreleased element",
                    (key, value),
                )
            )
    for index, edge in enumerate(order.edges[: len(order.nodes) - 1]):
        if edge.released:
            errors.extend(
                validation_failure(
                    order,
                    f"T19: released edge {edge.edge_id!r} joins unreleased node {node.node_id!r}",
                    ("edgeId", edge.edge_id),
                    ("nodeId", node.node_id),
                )
                for node in (order.nodes[index], order.nodes[index + 1])
                if not node.released
            )
    return errors


def _sequence_errors(order: v3.Order, first_sequence_id: int | None) -> list[v3.Error]:
    first = order.nodes[0].sequence_id
    node_reference = ("nodeId", order.nodes[0].node_id)
    if first_sequence_id is not None and first != first_sequence_id:
        return [
            validation_failure(
                order,
                f"T18: the first node must have sequenceId {first_sequence_id}, got {first}",
                node_reference,
            )
        ]
    if first % 2:
        return [
            validation_failure(
                order, f"T18: the first node's sequenceId must be even, got {first}", node_reference
            )
        ]
    errors = []
    for offset, element in enumerate(_elements(order)):
        if element.sequence_id != first + offset:
            key, value = _reference(element)
            errors.append(
                validation_failure(
                    order,
                    f"T18: sequenceIds must run {first}, {first + 1}, {first + 2}, ... "
                    f"alternating node and edge; {key} {value!r} has {element.sequence_id}, "
                    f"expected {first + offset}",
                    (key, value),
                )
            )
    return errors


def _duplicate_action_errors(order: v3.Order) -> list[v3.Error]:
    ids = (action.action_id for element in _elements(order) for action in element.actions)
    return [
        validation_failure(
            order, f"T20: actionId {ident!r} is used more than once (§7.3)", ("actionId", ident)
        )
        for ident in repeated_ids(ids)
    ]
