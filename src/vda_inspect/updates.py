"""Whether master control updates an order as the standard says (pure; R56, R57, R58;
docs/inspect.md). Judged on the orders a listener sees sent to one vehicle:

- R57 (§6.6.2): ``orderUpdateId`` goes up with every update of an ``orderId``. The same id
  again is a resend only when its content is the same (a vehicle discards it silently, R45,
  so a changed one is lost); a lower one after a higher is a violation;
- R56 (§6.6.2): an update starts at the order's decision point, the last released node of
  what was sent before, with its ``nodeId`` and ``sequenceId``, and sends nothing before it;
- R58 (§6.6.2; 3.0 says it in as many words): the stitching node is resent with exactly the
  content first sent for it.

A listener may miss a message (QoS 0) or start listening in the middle of an order: an update
whose id skips one the listener did not see is judged by R56 only as a notice, and the first
message of an ``orderId`` heard is not held to any earlier one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final

import orjson
from pydantic import BaseModel

from vda5050.models import Order, v3
from vda_inspect.severity import Problem, Severity

VIOLATION: Final = Severity.VIOLATION
NOTICE: Final = Severity.NOTICE
#: Updates of the current order whose content is remembered (for resends of older ones).
KEPT_UPDATES: Final = 8


@dataclass
class UpdateDiscipline:
    """What master control sent one vehicle of its current order."""

    order_id: str | None = None
    #: orderUpdateId → the message's content, without its header
    updates: dict[int, bytes] = field(default_factory=dict)
    #: sequenceId → a released node's content as first sent (R58)
    released_nodes: dict[int, bytes] = field(default_factory=dict)
    #: (nodeId, sequenceId) of the last released node sent: the next update's first node
    decision_point: tuple[str, int] | None = None
    #: Whether an earlier orderId was heard (then a new one should start at update 0)
    heard_before: bool = False

    def sent(self, order: Order | v3.Order) -> list[Problem]:
        """The problems of ``order`` (an order or update master control sent) against what
        it sent before; then remembered."""
        content = _content(order)
        update_id = order.order_update_id
        if order.order_id != self.order_id:
            found = self._new_order(order)
        else:
            latest = max(self.updates, default=None)
            if latest is not None and update_id <= latest:
                return self._again(update_id, latest, content)
            found = self._update(order, update_id, latest)
        self.updates[update_id] = content
        while len(self.updates) > KEPT_UPDATES:
            del self.updates[min(self.updates)]
        self._remember_released(order)
        return found

    def _new_order(self, order: Order | v3.Order) -> list[Problem]:
        found: list[Problem] = []
        if self.heard_before and order.order_update_id != 0:
            text = (
                f"new orderId {order.order_id!r} begins at orderUpdateId "
                f"{order.order_update_id}, not 0"
            )
            found.append(("R57", text, NOTICE))
        self.order_id, self.heard_before = order.order_id, True
        self.updates, self.released_nodes, self.decision_point = {}, {}, None
        return found

    def _again(self, update_id: int, latest: int, content: bytes) -> list[Problem]:
        """An orderUpdateId at or below the latest sent: only a resend is fine."""
        before = self.updates.get(update_id)
        if before == content:
            if update_id == latest:
                return []  # a resend of the latest
            text = f"orderUpdateId {update_id} sent again after {latest}"
            return [("R57", text, NOTICE)]  # an older resend: odd, but nothing changes
        if update_id == latest:
            text = f"orderUpdateId {update_id} sent again with other content (a vehicle drops it)"
            return [("R57", text, VIOLATION)]
        return [("R57", f"orderUpdateId went back from {latest} to {update_id}", VIOLATION)]

    def _update(self, order: Order | v3.Order, update_id: int, latest: int | None) -> list[Problem]:
        if self.decision_point is None or not order.nodes:
            return []
        by_sequence = {n.sequence_id: n for n in order.nodes}
        first = by_sequence[min(by_sequence)]
        node_id, sequence_id = self.decision_point
        if (first.node_id, first.sequence_id) != (node_id, sequence_id):
            gap = latest is not None and update_id > latest + 1
            text = (
                f"update {update_id} starts at node {first.node_id!r} (sequenceId "
                f"{first.sequence_id}), not at the decision point {node_id!r} (sequenceId "
                f"{sequence_id})"
            )
            if gap:
                text += f" of update {latest} (an update in between was not heard)"
            return [("R56", text, NOTICE if gap else VIOLATION)]
        before = self.released_nodes.get(sequence_id)
        if before is not None and _node_content(first) != before:
            text = (
                f"update {update_id} resends the stitching node {node_id!r} (sequenceId "
                f"{sequence_id}) with other content than first sent"
            )
            return [("R58", text, VIOLATION)]
        return []

    def _remember_released(self, order: Order | v3.Order) -> None:
        released = [n for n in order.nodes if n.released]
        for node in released:
            self.released_nodes.setdefault(node.sequence_id, _node_content(node))
        if released:
            last = max(released, key=lambda n: n.sequence_id)
            self.decision_point = (last.node_id, last.sequence_id)


def _content(order: Order | v3.Order) -> bytes:
    """The order without its header: what makes a resend the same message."""
    return orjson.dumps(
        order.model_dump(
            mode="json",
            exclude={"header_id", "timestamp", "version", "manufacturer", "serial_number"},
        ),
        option=orjson.OPT_SORT_KEYS,
    )


def _node_content(node: BaseModel) -> bytes:
    """A node as sent (2.x or 3.0), in a form two sends can be compared by."""
    return orjson.dumps(node.model_dump(mode="json"), option=orjson.OPT_SORT_KEYS)
