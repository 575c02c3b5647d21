"""How much of a route is released, and when the base is extended (§6.6.2; R56–R58).

The release strategy is not standardised (digest §9). This one keeps a window of
``window_nodes`` released nodes ahead of the last node the vehicle reported; the rest of the
route is sent as horizon. Whenever the vehicle passes a node, or asks with ``newBaseRequest``,
the window slides forward with an order update that stitches at the decision point, so a vehicle
on a long route never has to stop (§6.6.2: "extend the base early enough").
"""

from __future__ import annotations

from dataclasses import dataclass

from vda5050.models import State
from vda_master.order_builder import OrderPlan


@dataclass(frozen=True, slots=True)
class ReleasePolicy:
    """``window_nodes`` released nodes ahead of the vehicle; 0 releases the whole route at once."""

    window_nodes: int = 3

    def __post_init__(self) -> None:
        if self.window_nodes < 0:
            msg = f"window_nodes must not be negative, got {self.window_nodes}"
            raise ValueError(msg)


def release_end(policy: ReleasePolicy, last_index: int, progress: int) -> int:
    """The last node index to release when the vehicle's last node has index ``progress``."""
    if policy.window_nodes == 0:
        return last_index
    return min(last_index, progress + policy.window_nodes)


def progress_index(plan: OrderPlan, state: State) -> int | None:
    """Index in ``plan`` of the node the vehicle last traversed, if it runs this order (§6.10.2)."""
    if state.order_id != plan.order_id or state.last_node_sequence_id % 2:
        return None
    index = state.last_node_sequence_id // 2
    if index > plan.last_index or plan.nodes[index].node_id != state.last_node_id:
        return None
    return index


def decide_release(
    policy: ReleasePolicy,
    *,
    last_index: int,
    released_end: int,
    progress: int,
    new_base_request: bool,
) -> int | None:
    """The new base end if the base should be extended now, else None.

    The base only ever grows (R66): the result is always beyond ``released_end``. A
    ``newBaseRequest`` (§6.10.3) extends by at least one node even when the window is full.
    """
    if released_end >= last_index:
        return None
    target = release_end(policy, last_index, progress)
    if new_base_request:
        target = max(target, min(last_index, released_end + max(1, policy.window_nodes)))
    return target if target > released_end else None
