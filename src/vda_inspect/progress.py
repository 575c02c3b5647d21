"""Whether a vehicle's states report its order as it was sent (pure; R97, R98, R99, R62, R55;
docs/inspect.md).

A listener sees the orders master control sends and the states the vehicle answers with, so it
can hold each state that carries an order against that order:

- R98 (§6.10.1): ``nodeStates`` and ``edgeStates`` list exactly the elements not traversed yet,
  base and horizon, each with the ``sequenceId``, id and ``released`` of the order (an update
  replaces everything from its first node on, §6.6.2);
- R97 (§6.10.2): a traversal is reported in one state: nothing at or before
  ``lastNodeSequenceId`` is still listed;
- R55 (§6.6.2): the vehicle drives only its base: the node at ``lastNodeSequenceId`` was
  released;
- R62 (§6.6.3): once a ``cancelOrder`` shows FINISHED, both lists are empty and the orderId is
  the cancelled one (while it runs, the vehicle stopping, the lists are not judged);
- R99 (§6.10.6): ``orderId`` stays reported until a new order is accepted: it does not change
  to an id that was never sent to the vehicle, nor to ``""``, within one session (a vehicle
  ONLINE again after OFFLINE may be a restarted one).

Its action states are judged by :mod:`vda_inspect.action_rules` (R60, R68-R77).

A state is judged only against the order and update it names, and only once its
``lastNodeId`` is a node of that order at ``lastNodeSequenceId``: a vehicle that has not reached
the order's first node yet may still report the last node of its previous order. Nor while it
still lists the first node at that node's own sequenceId: its ``lastNode*`` may be left from
before and only look like the first node's (vda-5050-lib's virtual AGV on its start node, whose
``lastNodeSequenceId`` is 0, lists the first node until it has "reached" it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final

from vda5050.models import ActionStatus, InstantActions, Order, State, v3
from vda_inspect.action_rules import (
    FINAL,
    FINISHED,
    INIT_POSITION,
    WAITING,
    Listed,
    OrderActions,
    after_cancel_problems,
    blocking_problems,
    effect_problems,
    final_problems,
    listed,
    order_action_problems,
    order_actions,
)
from vda_inspect.map_rules import MapRequest, ended_problems, map_problems, map_request, maps_of
from vda_inspect.severity import Problem, Severity

VIOLATION: Final = Severity.VIOLATION
NOTICE: Final = Severity.NOTICE

#: Updates per order kept to judge states by (a vehicle may run an older one after rejecting
#: the newest).
KEPT_UPDATES: Final = 4
#: Order ids sent to one vehicle that are remembered for R99.
KEPT_ORDER_IDS: Final = 64
#: Instant actions sent to one vehicle whose type is remembered (R76, R77).
KEPT_INSTANT_ACTIONS: Final = 256

#: sequenceId → (kind, id, released)
Elements = dict[int, tuple[str, str, bool]]


@dataclass
class OrderProgress:
    """The orders one vehicle was sent, and what its states must say about them."""

    order_id: str | None = None
    #: The sequenceId of the order's first node
    first_sequence_id: int = 0
    #: orderUpdateId → the order's elements as that update left them
    updates: dict[int, Elements] = field(default_factory=dict)
    #: actionIds of the cancelOrder instant actions sent for the current order
    cancels: set[str] = field(default_factory=set)
    #: cancelOrder actionIds states showed FINISHED during the current order, and during
    #: earlier ones (a vehicle may list those until its next order)
    cancels_shown: set[str] = field(default_factory=set)
    earlier_cancels: set[str] = field(default_factory=set)
    sent_ids: list[str] = field(default_factory=list)
    #: The orderId of the vehicle's last state in this session (None: none yet)
    reported_id: str | None = None
    #: orderUpdateId → the order's actions as that update left them
    update_actions: dict[int, OrderActions] = field(default_factory=dict)
    #: actionType of the instant actions sent (the newest KEPT_INSTANT_ACTIONS)
    instant_types: dict[str, str] = field(default_factory=dict)
    #: The last status each action showed, this order and session (R69, R76, R77)
    statuses: dict[str, str] = field(default_factory=dict)
    #: The parameters of the initPosition instant actions sent (R78)
    init_positions: dict[str, dict[str, object]] = field(default_factory=dict)
    #: pick or drop actionId → the number of loads reported while it waited (R81)
    waiting_loads: dict[str, int] = field(default_factory=dict)
    #: The maps of the last state (map id and version → status; R89, R91)
    maps: dict[tuple[str, str], str] = field(default_factory=dict)
    #: The map actions sent, until they end (R87-R91)
    map_requests: dict[str, MapRequest] = field(default_factory=dict)

    def order(self, order: Order | v3.Order) -> None:
        """An order or an update was sent to the vehicle."""
        elements = _elements(order)
        if order.order_id != self.order_id:
            self.order_id = order.order_id
            self.updates = {order.order_update_id: elements}
            self.update_actions = {order.order_update_id: order_actions(order)}
            self.statuses, self.waiting_loads = {}, {}
            self.first_sequence_id = min(n.sequence_id for n in order.nodes) if order.nodes else 0
            self.earlier_cancels = self.cancels | self.cancels_shown
            self.cancels, self.cancels_shown = set(), set()
            self.sent_ids = [*self.sent_ids[-KEPT_ORDER_IDS + 1 :], order.order_id]
            return
        if order.order_update_id in self.updates or not self.updates:
            return
        latest = self.updates[max(self.updates)]
        stitch = min(elements, default=0)
        merged = {seq: e for seq, e in latest.items() if seq < stitch} | elements
        self.updates[order.order_update_id] = merged
        kept = self.update_actions[max(self.update_actions)]
        self.update_actions[order.order_update_id] = {
            action_id: where for action_id, where in kept.items() if where[0] < stitch
        } | order_actions(order)
        while len(self.updates) > KEPT_UPDATES:
            del self.updates[min(self.updates)]
            del self.update_actions[min(self.update_actions)]

    def instant_actions(self, message: InstantActions | v3.InstantActions) -> None:
        self.cancels.update(a.action_id for a in message.actions if a.action_type == "cancelOrder")
        self.instant_types.update((a.action_id, a.action_type) for a in message.actions)
        while len(self.instant_types) > KEPT_INSTANT_ACTIONS:
            del self.instant_types[next(iter(self.instant_types))]
        for sent in message.actions:
            parameters: dict[str, object] = {p.key: p.value for p in sent.action_parameters or ()}
            if sent.action_type in INIT_POSITION:
                self.init_positions[sent.action_id] = parameters
            request = map_request(sent.action_type, parameters, self.maps)
            if request is not None:
                self.map_requests[sent.action_id] = request
        for kept in (self.init_positions, self.map_requests):
            while len(kept) > KEPT_INSTANT_ACTIONS:
                del kept[next(iter(kept))]

    def new_session(self) -> None:
        """The vehicle came ONLINE again: it may have restarted and forgotten its order."""
        self.reported_id = None
        self.statuses = {}
        self.waiting_loads = {}

    def state(self, state: State | v3.State) -> list[Problem]:
        """What ``state`` gets wrong about the vehicle's order."""
        found = self._order_id_kept(state)
        shown = listed(state)
        before = dict(self.statuses)
        found += self._action_statuses(state, shown)
        found += map_problems(state, self.maps, shown)
        self.maps = maps_of(state)
        if state.order_id != self.order_id:
            return found
        actions = self.update_actions.get(state.order_update_id, {})
        cancel = self._cancel_shown(shown)
        if cancel is ActionStatus.FINISHED:
            if state.node_states or state.edge_states:
                listed_now = len(state.node_states) + len(state.edge_states)
                text = f"{listed_now} node/edge state(s) still listed after cancelOrder FINISHED"
                found.append(("R62", text, VIOLATION))
            found += after_cancel_problems(actions, shown, before)
        if cancel is not None:  # while stopping, the lists shrink to nothing or the next node
            return found
        elements = self.updates.get(state.order_update_id)
        if elements is None:
            return found
        last = state.last_node_sequence_id
        if not _node_at(elements, last, state.last_node_id):
            return found  # not at the order's first node yet: its last node is the old one
        if last == self.first_sequence_id and any(n.sequence_id == last for n in state.node_states):
            return found  # the first node still to be reached (its lastNode* from before)
        if not elements[last][2]:
            text = f"node {state.last_node_id!r} (sequenceId {last}) traversed on the horizon"
            found.append(("R55", text + ": it was never released", VIOLATION))
        found.extend(_listing_problems(elements, _reported(state), last))
        found.extend(order_action_problems(actions, elements, shown, last))
        found.extend(blocking_problems(actions, shown, last, driving=state.driving))
        return found

    def _action_statuses(self, state: State | v3.State, shown: Listed) -> list[Problem]:
        """R69 against the statuses shown before; R76-R78, R81 for actions the listener saw
        sent that show FINISHED for the first time."""
        found = final_problems(self.statuses, shown)
        current = self.update_actions.get(max(self.update_actions, default=-1), {})
        loads = None if state.loads is None else len(state.loads)
        for action_id, (status, action_type) in shown.items():
            sent_type = self.instant_types.get(action_id) or current.get(action_id, (0, ""))[1]
            kind = action_type or sent_type
            if status == WAITING and kind in ("pick", "drop") and loads is not None:
                self.waiting_loads[action_id] = loads
            if status in FINAL and action_id in self.map_requests:
                found += ended_problems(self.map_requests.pop(action_id), status, state)
            if status != FINISHED or self.statuses.get(action_id) == FINISHED or not sent_type:
                continue
            found += effect_problems(
                kind,
                state,
                parameters=self.init_positions.get(action_id),
                loads_before=self.waiting_loads.pop(action_id, None),
            )
        self.statuses.update((action_id, status) for action_id, (status, _) in shown.items())
        return found

    def _order_id_kept(self, state: State | v3.State) -> list[Problem]:
        before, self.reported_id = self.reported_id, state.order_id
        if before is None or state.order_id == before or state.order_id in self.sent_ids:
            return []
        if not state.order_id:
            return [("R99", f'orderId {before!r} cleared to "" without a new order', VIOLATION)]
        # the listener may have missed the order (QoS 0): a notice only
        text = f"orderId changed from {before!r} to {state.order_id!r}, an order not seen sent"
        return [("R99", text, NOTICE)]

    def _cancel_shown(self, shown: Listed) -> ActionStatus | None:
        """The status of a cancelOrder of the current order the state shows (FINISHED before
        any other): one sent for it, or one the state names by its actionType (the listener
        may not have been able to read the message that carried it, as vda-5050-lib's 2.0
        instantActions dialect). A cancel of an earlier order still listed does not count,
        nor one that FAILED (there was nothing to cancel)."""
        cancels = {
            action_id: ActionStatus(status)
            for action_id, (status, action_type) in shown.items()
            if (action_id in self.cancels or action_type == "cancelOrder")
            and action_id not in self.earlier_cancels
            and status != ActionStatus.FAILED.value
        }
        self.cancels_shown.update(cancels)
        statuses = set(cancels.values())
        if ActionStatus.FINISHED in statuses:
            return ActionStatus.FINISHED
        return next(iter(statuses), None)


def _elements(order: Order | v3.Order) -> Elements:
    elements: Elements = {n.sequence_id: ("node", n.node_id, n.released) for n in order.nodes}
    elements.update({e.sequence_id: ("edge", e.edge_id, e.released) for e in order.edges})
    return elements


def _node_at(elements: Elements, sequence_id: int, node_id: str) -> bool:
    found = elements.get(sequence_id)
    return found is not None and found[0] == "node" and found[1] == node_id


def _reported(state: State | v3.State) -> Elements:
    reported: Elements = {n.sequence_id: ("node", n.node_id, n.released) for n in state.node_states}
    reported.update({e.sequence_id: ("edge", e.edge_id, e.released) for e in state.edge_states})
    return reported


def _listing_problems(elements: Elements, reported: Elements, last: int) -> list[Problem]:
    """R97 and R98: the reported lists against the order's elements after ``last``."""
    found: list[Problem] = []
    passed = sorted(seq for seq in reported if seq <= last)
    if passed:
        kind, element_id, _ = reported[passed[0]]
        text = f"{kind} {element_id!r} (sequenceId {passed[0]}) still listed at lastNodeSequenceId"
        found.append(("R97", f"{text} {last}", VIOLATION))
    expected = {seq: e for seq, e in elements.items() if seq > last}
    missing = sorted(set(expected) - set(reported))
    if missing:
        kind, element_id, _ = expected[missing[0]]
        more = f", and {len(missing) - 1} more" if len(missing) > 1 else ""
        text = f"{kind} {element_id!r} (sequenceId {missing[0]}) not traversed but not listed"
        found.append(("R98", text + more, VIOLATION))
    for seq in sorted(set(reported) & set(expected)):
        if reported[seq] != expected[seq]:
            found.append(("R98", _differs(seq, reported[seq], expected[seq]), VIOLATION))
            break
    unknown = sorted(seq for seq in reported if seq > last and seq not in elements)
    if unknown:
        kind, element_id, _ = reported[unknown[0]]
        text = f"{kind} {element_id!r} listed with sequenceId {unknown[0]}, not in the order"
        found.append(("R98", text, VIOLATION))
    return found


def _differs(seq: int, reported: tuple[str, str, bool], expected: tuple[str, str, bool]) -> str:
    kind, element_id, released = expected
    if reported[:2] != expected[:2]:
        return (
            f"sequenceId {seq} listed as {reported[0]} {reported[1]!r}; the order has "
            f"{kind} {element_id!r} there"
        )
    return (
        f"{kind} {element_id!r} (sequenceId {seq}) listed as released={reported[2]}; the order "
        f"says released={released}"
    )
