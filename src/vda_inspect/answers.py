"""Whether a vehicle answers every order it is sent (pure; R93, R27-R29; docs/inspect.md).

§6.10: a vehicle publishes a state promptly when it receives an order or an update (R93). That
state carries the order (``orderId``, ``orderUpdateId``) when the vehicle took it, or an error
naming it when the vehicle refused it (R27-R29). A listener sees both sides: an order still
without such a state after ``within_s`` was neither taken nor refused as far as master control
can tell. A resend of the same order counts from its last send.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from vda5050.models import State, v3

OrderKey = tuple[str, int]


@dataclass
class OrderAnswers:
    within_s: float
    #: (orderId, orderUpdateId) → when it was (last) sent
    pending: dict[OrderKey, float] = field(default_factory=dict)

    def sent(self, order_id: str, update_id: int, now: float) -> None:
        self.pending[order_id, update_id] = now

    def state(self, state: State | v3.State) -> None:
        """Clear the orders this state answers: it carries them (the same orderId at that
        update or a later one), or it has an error whose references name the orderId."""
        if not self.pending:
            return
        named = {
            reference.reference_value
            for error in state.errors
            for reference in error.error_references or ()
            if reference.reference_key == "orderId"
        }
        for key in list(self.pending):
            order_id, update_id = key
            carried = state.order_id == order_id and state.order_update_id >= update_id
            if carried or order_id in named:
                del self.pending[key]

    def overdue(self, now: float) -> list[tuple[OrderKey, float]]:
        """The orders unanswered for longer than ``within_s``, with how long; they are
        forgotten (each is reported once)."""
        late = [(key, now - at) for key, at in self.pending.items() if now - at > self.within_s]
        for key, _ in late:
            del self.pending[key]
        return late
