"""Semantic checks of an order that a JSON schema cannot express (§6.6.1, §6.6.2, §6.6.6).

Pure functions: they return VDA 5050 error objects (``validationError``, level WARNING, with
errorReferences) and never raise. Each description starts with the digest rule id it enforces.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

from vda5050.models import Edge, Error, ErrorLevel, ErrorReference, ErrorType, Node, Order
from vda5050.topics import Topic


def order_references(order: Order, *extra: tuple[str, str]) -> list[ErrorReference]:
    """errorReferences that point at ``order`` (§7.1): headerId, topic, orderId, orderUpdateId."""
    pairs = [
        ("headerId", str(order.header_id)),
        ("topic", Topic.ORDER.value),
        ("orderId", order.order_id),
        ("orderUpdateId", str(order.order_update_id)),
        *extra,
    ]
    return [ErrorReference(reference_key=key, reference_value=value) for key, value in pairs]


def validation_error(order: Order, description: str, *extra: tuple[str, str]) -> Error:
    """A ``validationError`` WARNING about ``order`` (§6.6.4.1)."""
    return Error(
        error_type=ErrorType.VALIDATION,
        error_level=ErrorLevel.WARNING,
        error_description=description,
        error_references=order_references(order, *extra),
    )


def check_order(order: Order, *, first_sequence_id: int | None = None) -> list[Error]:
    """Return every static rule ``order`` breaks; an empty list means it is well-formed.

    ``first_sequence_id`` is the sequenceId the first node must carry: 0 for a new order, the
    decision point's for an update. Without it the first node only has to carry an even number.
    """
    if not order.nodes:
        return [validation_error(order, "R21: an order needs at least one node")]
    errors: list[Error] = []
    if len(order.edges) != len(order.nodes) - 1:
        errors.append(
            validation_error(
                order,
                f"R22: an order with {len(order.nodes)} nodes needs {len(order.nodes) - 1} edges, "
                f"got {len(order.edges)}",
            )
        )
    if not order.nodes[0].released:
        errors.append(
            validation_error(
                order,
                "R24: the first node must be released (an order needs a base)",
                ("nodeId", order.nodes[0].node_id),
            )
        )
    errors.extend(_release_errors(order))
    errors.extend(_sequence_errors(order, first_sequence_id))
    errors.extend(_endpoint_errors(order))
    errors.extend(_duplicate_action_errors(order))
    return errors


def _elements(order: Order) -> Iterator[Node | Edge]:
    """node0, edge0, node1, edge1, ... in traversal order."""
    for index, node in enumerate(order.nodes):
        yield node
        if index < len(order.edges):
            yield order.edges[index]


def _reference(element: Node | Edge) -> tuple[str, str]:
    if isinstance(element, Node):
        return ("nodeId", element.node_id)
    return ("edgeId", element.edge_id)


def _release_errors(order: Order) -> list[Error]:
    errors: list[Error] = []
    horizon_started = False
    for element in _elements(order):
        if not element.released:
            horizon_started = True
        elif horizon_started:
            errors.append(
                validation_error(
                    order,
                    f"R24: released {_reference(element)[0]} {_reference(element)[1]!r} "
                    f"(sequenceId {element.sequence_id}) follows an unreleased element",
                    _reference(element),
                )
            )
    for index, edge in enumerate(order.edges):
        if not edge.released or index + 1 >= len(order.nodes):
            continue
        errors.extend(
            validation_error(
                order,
                f"R23: released edge {edge.edge_id!r} joins unreleased node {node.node_id!r}",
                ("edgeId", edge.edge_id),
                ("nodeId", node.node_id),
            )
            for node in (order.nodes[index], order.nodes[index + 1])
            if not node.released
        )
    return errors


def _sequence_errors(order: Order, first_sequence_id: int | None) -> list[Error]:
    first = order.nodes[0].sequence_id
    if first_sequence_id is not None and first != first_sequence_id:
        return [
            validation_error(
                order,
                f"R25: the first node must have sequenceId {first_sequence_id}, got {first}",
                ("nodeId", order.nodes[0].node_id),
            )
        ]
    if first % 2:
        return [
            validation_error(
                order,
                f"R25: the first node's sequenceId must be even, got {first}",
                ("nodeId", order.nodes[0].node_id),
            )
        ]
    errors = []
    for offset, element in enumerate(_elements(order)):
        if element.sequence_id != first + offset:
            errors.append(
                validation_error(
                    order,
                    f"R25: sequenceIds must run {first}, {first + 1}, {first + 2}, ... alternating "
                    f"node and edge; {_reference(element)[0]} {_reference(element)[1]!r} has "
                    f"{element.sequence_id}, expected {first + offset}",
                    _reference(element),
                )
            )
    return errors


def _endpoint_errors(order: Order) -> list[Error]:
    errors = []
    for index, edge in enumerate(order.edges[: len(order.nodes) - 1]):
        start, end = order.nodes[index].node_id, order.nodes[index + 1].node_id
        if (edge.start_node_id, edge.end_node_id) != (start, end):
            errors.append(
                validation_error(
                    order,
                    f"R26: edge {edge.edge_id!r} runs {edge.start_node_id!r} -> "
                    f"{edge.end_node_id!r} but lies between nodes {start!r} and {end!r}",
                    ("edgeId", edge.edge_id),
                )
            )
    return errors


def repeated_ids(ids: Iterable[str]) -> list[str]:
    """Every id that occurs again after its first occurrence, in order (actionIds are unique
    within an order, §6.6.6; 3.0 §7.3)."""
    seen: set[str] = set()
    repeated = []
    for ident in ids:
        if ident in seen:
            repeated.append(ident)
        seen.add(ident)
    return repeated


def _duplicate_action_errors(order: Order) -> list[Error]:
    ids = (action.action_id for element in _elements(order) for action in element.actions)
    return [
        validation_error(
            order, f"actionId {ident!r} is used more than once (§6.6.6)", ("actionId", ident)
        )
        for ident in repeated_ids(ids)
    ]
