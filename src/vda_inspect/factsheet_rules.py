"""What master control sends, held against the factsheet the vehicle published (pure;
R112-R114; docs/inspect.md). 2.x messages; a 3.0 factsheet is read in its 2.x terms
(:func:`vda_master.wire3.factsheet_from_v3`), 3.0 orders are judged on R112 only.

- R112: no optional field the factsheet's ``optionalParameters`` does not list;
- R113: the fields it lists as REQUIRED are there (on the order, on every node or edge, on
  every nodePosition sent);
- R114: ``protocolLimits``: array sizes, id lengths and ``idNumericalOnly``, action parameter
  counts and name lengths, the message size, and ``minOrderInterval`` between two orders (by
  their own timestamps, judged at half of it).
"""

from __future__ import annotations

from collections.abc import Iterator

from vda5050.models import Factsheet, InstantActions, Order, v3
from vda_master import capabilities as caps
from vda_master.wire3 import V2_PARAMETER_OF
from vda_vehicle.capabilities import optional_fields_used

#: Where a REQUIRED field must be: its path prefix → the elements that carry it.
_PER_NODE = "order.nodes."
_PER_EDGE = "order.edges."


def order_problems(
    order: Order | v3.Order, factsheet: Factsheet, size: int
) -> Iterator[tuple[str, str]]:
    """(rule, text) for each way ``order`` breaks ``factsheet``."""
    used = list(optional_fields_used(order))
    allowed = caps.sendable_fields(factsheet)
    # a 3.0 order's paths in the 2.x terms of the factsheet's reading (renamed fields, T83)
    renamed = V2_PARAMETER_OF if isinstance(order, v3.Order) else {}
    for path, where in used:
        if renamed.get(path, path) not in allowed:
            yield "R112", f"{path} ({where}) is sent, but the factsheet does not list it"
    if isinstance(order, v3.Order):
        return
    yield from (("R113", text) for text in _missing_required(order, factsheet, used))
    yield from (("R114", text) for text in _limit_problems(order, factsheet, size))


def instant_actions_problems(
    message: InstantActions, factsheet: Factsheet, size: int
) -> Iterator[tuple[str, str]]:
    """(rule, text) for each limit an instantActions message breaks (R114)."""
    actions = message.actions
    problems = [
        *caps.array_problems(factsheet, {"instantActions": len(actions)}),
        *caps.action_limit_problems(factsheet, actions),
        *caps.id_problems(factsheet, (a.action_id for a in actions)),
    ]
    too_big = caps.message_size_problem(factsheet, size)
    if too_big is not None:
        problems.append(too_big)
    yield from (("R114", text) for text in problems)


def min_order_interval_s(factsheet: Factsheet) -> float:
    return caps.min_order_interval_s(factsheet)


def _missing_required(
    order: Order, factsheet: Factsheet, used: list[tuple[str, str]]
) -> Iterator[str]:
    present = set(used)
    for path in sorted(caps.required_fields(factsheet)):
        if path.startswith("order.nodes.nodePosition."):
            carriers = [f"node {n.node_id}" for n in order.nodes if n.node_position is not None]
        elif path.startswith(_PER_NODE) and "." not in path.removeprefix(_PER_NODE):
            carriers = [f"node {n.node_id}" for n in order.nodes]
        elif path.startswith(_PER_EDGE) and "." not in path.removeprefix(_PER_EDGE):
            carriers = [f"edge {e.edge_id}" for e in order.edges]
        elif path.count(".") == 1:
            carriers = ["order"]
        else:
            continue  # inside actions or deeper: not judged
        missing = [where for where in carriers if (path, where) not in present]
        if missing:
            yield f"{path} is REQUIRED by the factsheet but missing on {', '.join(missing[:3])}"


def _limit_problems(order: Order, factsheet: Factsheet, size: int) -> list[str]:
    actions = [a for n in order.nodes for a in n.actions] + [
        a for e in order.edges for a in e.actions
    ]
    counts = {
        "order.nodes": len(order.nodes),
        "order.edges": len(order.edges),
        "node.actions": max((len(n.actions) for n in order.nodes), default=0),
        "edge.actions": max((len(e.actions) for e in order.edges), default=0),
    }
    ids = [order.order_id, *(n.node_id for n in order.nodes), *(e.edge_id for e in order.edges)]
    ids += [a.action_id for a in actions]
    problems = [
        *caps.array_problems(factsheet, counts),
        *caps.id_problems(factsheet, ids),
        *caps.action_limit_problems(factsheet, actions),
    ]
    too_big = caps.message_size_problem(factsheet, size)
    if too_big is not None:
        problems.append(too_big)
    return problems
