"""Whether a vehicle answers every order and instant action it is sent (pure; R93, R27-R29,
R79, R80; docs/inspect.md).

§6.10: a vehicle publishes a state promptly when it receives an order or an update (R93). That
state carries the order (``orderId``, ``orderUpdateId``) when the vehicle took it, or an error
naming it when the vehicle refused it (R27-R29). An instant action likewise shows in the
state's action states (3.0: ``instantActionStates``) by its ``actionId``, or an error names
that id (a stateRequest's answer is that state, R79). A listener sees both sides: a message
still without such a state after ``within_s`` was neither taken nor refused as far as master
control can tell. A resend counts from its last send. A factsheetRequest that shows FINISHED must
have brought a factsheet (R80) within ``within_s``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from vda5050.models import State, v3
from vda_inspect.action_rules import FINISHED, Listed, listed

OrderKey = tuple[str, int]


@dataclass
class OrderAnswers:
    within_s: float
    #: (orderId, orderUpdateId) → when it was (last) sent
    pending: dict[OrderKey, float] = field(default_factory=dict)
    #: instant actionId → (its actionType, when it was (last) sent)
    actions: dict[str, tuple[str, float]] = field(default_factory=dict)
    #: factsheetRequest actionId → when it was sent; then, once a state shows it FINISHED
    #: with no factsheet since, when that state came (R80)
    factsheet_requests: dict[str, float] = field(default_factory=dict)
    factsheet_due: dict[str, float] = field(default_factory=dict)
    #: when the vehicle's latest factsheet came
    factsheet_at: float | None = None

    def sent(self, order_id: str, update_id: int, now: float) -> None:
        self.pending[order_id, update_id] = now

    def sent_actions(self, actions: list[tuple[str, str]], now: float) -> None:
        """(actionId, actionType) of an instantActions message."""
        for action_id, action_type in actions:
            self.actions[action_id] = (action_type, now)
            if action_type == "factsheetRequest":
                self.factsheet_requests[action_id] = now

    def factsheet(self, now: float) -> None:
        """The vehicle published its factsheet: every request finished so far is answered."""
        self.factsheet_at = now
        self.factsheet_due.clear()

    def state(self, state: State | v3.State, now: float = 0.0) -> None:
        """Clear the orders this state answers: it carries them (the same orderId at that
        update or a later one), or it has an error whose references name the orderId. A
        factsheetRequest it shows FINISHED must have brought a factsheet (R80)."""
        if not self.pending and not self.actions and not self.factsheet_requests:
            return
        shown = listed(state)
        if self.factsheet_requests:
            self._factsheet_requests_finished(shown, now)
        named = {
            (reference.reference_key, reference.reference_value)
            for error in state.errors
            for reference in error.error_references or ()
        }
        if self.actions:
            for action_id in list(self.actions):
                if action_id in shown or ("actionId", action_id) in named:
                    del self.actions[action_id]
        for key in list(self.pending):
            order_id, update_id = key
            carried = state.order_id == order_id and state.order_update_id >= update_id
            if carried or ("orderId", order_id) in named:
                del self.pending[key]

    def _factsheet_requests_finished(self, shown: Listed, now: float) -> None:
        finished = [
            action_id
            for action_id, (status, _) in shown.items()
            if action_id in self.factsheet_requests and status == FINISHED
        ]
        for action_id in finished:
            sent = self.factsheet_requests.pop(action_id)
            if self.factsheet_at is None or self.factsheet_at < sent:
                self.factsheet_due[action_id] = now

    def missing_factsheets(self, now: float) -> list[tuple[str, float]]:
        """factsheetRequests FINISHED longer than ``within_s`` ago with no factsheet since
        (actionId, how long); forgotten once reported."""
        late = [(a, now - at) for a, at in self.factsheet_due.items() if now - at > self.within_s]
        for action_id, _ in late:
            del self.factsheet_due[action_id]
        return late

    def overdue(self, now: float) -> list[tuple[OrderKey, float]]:
        """The orders unanswered for longer than ``within_s``, with how long; they are
        forgotten (each is reported once)."""
        late = [(key, now - at) for key, at in self.pending.items() if now - at > self.within_s]
        for key, _ in late:
            del self.pending[key]
        return late

    def overdue_actions(self, now: float) -> list[tuple[str, str, float]]:
        """(actionId, actionType, how long) of the instant actions unanswered for longer than
        ``within_s``; forgotten once reported."""
        late = [
            (action_id, action_type, now - at)
            for action_id, (action_type, at) in self.actions.items()
            if now - at > self.within_s
        ]
        for action_id, _, _ in late:
            del self.actions[action_id]
        return late
