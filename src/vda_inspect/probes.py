"""Active probes of one vehicle's order handling (pure; docs/inspect.md, *vda-probe*).

A listener cannot judge what a vehicle does with orders a conforming master control never
sends (R30-R54). ``vda-probe`` takes master control's place for one vehicle and sends them: a
new order while one is held, updates that repeat, go back, skip ids or do not stitch, updates
to an ended order, an order that starts out of reach or carries an action that cannot be in
it, a cancel, the two requests. Each step is judged by the states (and errors) that follow it
(the judges: :mod:`vda_inspect.probe_judges`):

- R42 (R38 from a temporary node, R39 from ``lastNodeId``): an order accepted when idle, its
  horizon listed as sent;
- R55: nothing of the horizon driven; R45: the same update again changes nothing;
- R46, R52: an update at the decision point replaces the horizon; R53: also when its id
  skips; R54: one without a horizon leaves none; R48: one to an ended order at its last node
  is taken;
- R44, R47, R49, R40, R37, R31 (with R33), R83: a lower update, one that does not stitch (to a
  running or an ended order), a new orderId while busy, a first node out of reach, an unknown
  action type, an instant-only action on a node: rejected with an error that references the
  orderId (R30; the orderUpdateId too, or a warning), the current order going on;
- R35, R36 when the vehicle lists its maps / its factsheet limits ``order.nodes``, R32 when a
  2.x factsheet is known, R34 when the factsheet says DIFF: an order on a map it does not hold,
  one node over the limit, an optional field the factsheet does not list, an edge orientation
  across a differential drive's axis: rejected likewise (R32: naming the field);
- R59, R62: ``cancelOrder`` ends FINISHED with nothing listed; R43 (2.x): its state is gone
  once a new order is taken; R79, R80: the two requests;
- R51, R41, R82 when the factsheet offers ``waitForTrigger`` on nodes: an update stitched at
  the node where one runs keeps it running and listed once, a new order while it runs is
  rejected, and a cancel ends it FAILED.

Only the vehicle's own position is released, but for first nodes it must reject (R37's, 5 m
ahead; R47's and R49's, on the horizon); every other node lies on the horizon, 1 m from where
it stands. A conforming vehicle does not move during the probe; one that breaks R55, R37, R47
or R49 may, so run it where 5 m of travel ahead is safe (the prober sends ``cancelOrder`` as
soon as a failed step leaves the vehicle driving).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Final

from vda5050.models import (
    Action,
    ActionParameter,
    BlockingType,
    Edge,
    Factsheet,
    InstantActions,
    Node,
    NodePosition,
    OperatingMode,
    Order,
    OrientationType,
    State,
)
from vda_inspect.probe_judges import (
    FINAL,
    Judge,
    Outcome,
    Seen,
    Verdict,
    cancelled,
    carries,
    error_key,
    finished,
    kept_once,
    naming,
    rejected,
    runs,
    stays,
    unchanged,
)

#: The id of the temporary first node when the vehicle reports no lastNodeId (§6.6.3.1).
TEMPORARY_NODE: Final = "vda-probe-start"
#: An actionType no vehicle supports (R31).
UNKNOWN_ACTION: Final = "vdaProbeUnknownAction"
#: How far the "out of reach" first node lies (R37): beyond any allowed deviation, within
#: most maps (a node off the vehicle's map is rejected too, for another reason).
FAR_M: Final = 5.0
#: A message's header before the prober's stamper writes it.
UNSTAMPED: Final[dict[str, object]] = {
    "header_id": 0,
    "timestamp": "1970-01-01T00:00:00.000Z",
    "version": "2.0.0",
    "manufacturer": "",
    "serial_number": "",
}
#: A mapId no vehicle holds (R35).
NO_MAP: Final = "vda-probe-no-such-map"
#: R36 is probed only below this many nodes (the order's message stays small).
MAX_PROBED_NODES: Final = 2000
#: Optional edge fields R32 may be probed with (the first the factsheet does not list), with
#: a value that asks nothing of a vehicle that honours it.
UNSUPPORTED_CANDIDATES: Final[dict[str, dict[str, object]]] = {
    "order.edges.minHeight": {"min_height": 0.0},
    "order.edges.direction": {"direction": "forward"},
    "order.edges.maxHeight": {"max_height": 2.0},
    "order.edges.maxSpeed": {"max_speed": 1.0},
}
AHEAD: Final = "vda-probe-ahead"
LEFT: Final = "vda-probe-left"
#: A step that waits for nothing to happen waits this long.
QUIET_S: Final = 1.5


@dataclass(frozen=True, slots=True)
class Start:
    """Where the vehicle stands: the probe's orders begin there."""

    node_id: str
    x: float
    y: float
    theta: float
    map_id: str

    def around(self, k: int, n: int) -> NodePosition:
        """The ``k``-th of ``n`` points on a circle of 1 m around the vehicle."""
        angle = 2 * math.pi * k / n
        return self.at(math.cos(angle), math.sin(angle))

    def at(self, ahead_m: float, left_m: float = 0.0) -> NodePosition:
        """A position ``ahead_m`` in front of the vehicle and ``left_m`` to its left."""
        cos, sin = math.cos(self.theta), math.sin(self.theta)
        return NodePosition(
            x=self.x + ahead_m * cos - left_m * sin,
            y=self.y + ahead_m * sin + left_m * cos,
            map_id=self.map_id,
        )


def start_of(state: State) -> Start | str:
    """Where ``state`` says the vehicle stands, or why it cannot be probed now."""
    if state.operating_mode not in (OperatingMode.AUTOMATIC, OperatingMode.SEMIAUTOMATIC):
        return f"the vehicle is in {state.operating_mode.value}, not AUTOMATIC"
    if state.node_states or state.edge_states:
        return f"the vehicle still holds order {state.order_id!r}: let it finish or cancel it"
    running = [a.action_id for a in state.action_states if a.action_status not in FINAL]
    if running:
        return f"actions {running} have not ended yet"
    pose = state.agv_position
    if pose is None or not pose.position_initialized:
        return "the vehicle reports no initialized agvPosition: the probe starts where it stands"
    node = state.last_node_id or TEMPORARY_NODE
    return Start(node, pose.x, pose.y, pose.theta, pose.map_id)


@dataclass(frozen=True, slots=True)
class Step:
    """One message to the vehicle and how to judge what follows. ``judge`` returns None while
    it cannot tell yet; at the deadline an undecided step passes when ``quiet`` (nothing was
    to happen) and fails otherwise."""

    title: str
    rules: tuple[str, ...]
    message: Order | InstantActions | None
    judge: Judge
    within_s: float = 2.0
    quiet: bool = False
    #: When it fails, the steps after it (which build on it) are not run.
    essential: bool = False


@dataclass
class ProbePlan:
    """The steps for a vehicle standing at ``start``; ``run_id`` keeps orderIds unique."""

    start: Start
    run_id: str
    #: Whether the vehicle's state lists ``maps`` (then an unknown mapId is probed, R35).
    maps_reported: bool = False
    #: The factsheet's ``maxArrayLens`` for ``order.nodes`` (then one more is probed, R36).
    max_order_nodes: int | None = None
    #: A 3.0 vehicle (its instant actions stay listed across orders).
    v3: bool = False
    #: An optional edge field (of ``UNSUPPORTED_CANDIDATES``) the factsheet does not list: an
    #: order carrying it must be rejected (R32).
    unsupported_field: str | None = None
    #: The parameters for ``waitForTrigger`` when the factsheet offers it on nodes (its
    #: required ones, filled in): then an order holds one running where the vehicle stands
    #: (R41, R82). None: not offered.
    trigger_parameters: dict[str, object] | None = None
    #: A differential-drive vehicle (factsheet ``agvKinematic`` DIFF): an edge orientation
    #: across its axis of travel must be rejected (R34).
    differential: bool = False
    steps: list[Step] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.steps = self._steps()

    def order_id(self, n: int) -> str:
        return f"vda-probe-{self.run_id}-{n}"

    @property
    def cancel_id(self) -> str:
        return f"vda-probe-{self.run_id}-cancel"

    def _optional_steps(self) -> list[Step]:
        """R35 for a vehicle that reports its maps, R36 for one whose factsheet limits the
        nodes of an order to at most ``MAX_PROBED_NODES``."""
        first = self._first()
        steps = []
        if self.maps_reported:
            elsewhere = first.model_copy(
                update={"node_position": self.start.at(0.0).model_copy(update={"map_id": NO_MAP})}
            )
            steps.append(
                Step(
                    "an order on a map the vehicle does not hold is rejected",
                    ("R35", "R30"),
                    self._order(7, 0, [elsewhere]),
                    rejected(self.order_id(7), 0, (self.order_id(1), None)),
                )
            )
        if self.unsupported_field is not None:
            steps.append(self._unsupported_field_step(self.unsupported_field))
        if self.differential:
            steps.append(self._sideways_step())
        limit = self.max_order_nodes
        if limit is not None and limit < MAX_PROBED_NODES:
            ring = [
                self._horizon(f"vda-probe-ring-{k}", 2 * k, self.start.around(k, limit))
                for k in range(1, limit + 1)
            ]
            steps.append(
                Step(
                    f"an order of {limit + 1} nodes, over the factsheet's {limit}, is rejected",
                    ("R36", "R30"),
                    self._order(8, 0, [first, *ring]),
                    rejected(self.order_id(8), 0, (self.order_id(1), None)),
                )
            )
        return steps

    def _first(self) -> Node:
        start = self.start
        return Node(
            node_id=start.node_id,
            sequence_id=0,
            released=True,
            node_position=start.at(0.0),
            actions=[],
        )

    def _order(
        self, n: int, update: int, nodes: list[Node], *, edges: list[Edge] | None = None
    ) -> Order:
        if edges is None:
            edges = [
                Edge(
                    edge_id=f"{a.node_id}->{b.node_id}",
                    sequence_id=a.sequence_id + 1,
                    released=b.released,
                    start_node_id=a.node_id,
                    end_node_id=b.node_id,
                    actions=[],
                )
                for a, b in itertools.pairwise(nodes)
            ]
        return Order.model_validate(
            {
                **UNSTAMPED,
                "order_id": self.order_id(n),
                "order_update_id": update,
                "nodes": nodes,
                "edges": edges,
            }
        )

    def _horizon(self, node_id: str, sequence_id: int, position: NodePosition) -> Node:
        return Node(
            node_id=node_id,
            sequence_id=sequence_id,
            released=False,
            node_position=position,
            actions=[],
        )

    def _steps(self) -> list[Step]:
        return [*self._update_steps(), *self._idle_update_steps(), *self._new_order_steps()]

    def _update_steps(self) -> list[Step]:
        """An order held with a horizon; updates that must be taken and ones that must not."""
        s = self.start
        first = self._first()
        ahead = self._horizon(AHEAD, 2, s.at(1.0))
        left = self._horizon(LEFT, 2, s.at(0.0, 1.0))
        o1, o2 = self.order_id(1), self.order_id(2)
        accepted = self._order(1, 0, [first, ahead])
        kept = (o1, 1)
        start_rule = "R38" if s.node_id == TEMPORARY_NODE else "R39"
        return [
            Step(
                "a new order while idle is accepted, its horizon listed",
                ("R42", start_rule),
                accepted,
                carries(o1, 0, [(AHEAD, 2, False)]),
                essential=True,
            ),
            Step(
                "nothing of the horizon is driven", ("R55",), None, stays(o1), QUIET_S, quiet=True
            ),
            Step(
                "the same orderUpdateId again changes nothing and raises no error",
                ("R45",),
                accepted,
                unchanged(o1, 0),
                QUIET_S,
                quiet=True,
            ),
            Step(
                "an update at the decision point replaces the horizon",
                ("R46", "R52"),
                self._order(1, 1, [first, left]),
                carries(o1, 1, [(LEFT, 2, False)]),
                essential=True,
            ),
            Step(
                "a lower orderUpdateId is rejected, the order goes on",
                ("R44", "R30"),
                accepted,
                rejected(o1, 0, kept),
            ),
            Step(
                "an update that does not start at the decision point is rejected",
                ("R47", "R30"),
                self._order(1, 2, [self._stray(), self._horizon(AHEAD, 4, s.at(1.0))]),
                rejected(o1, 2, kept),
            ),
            Step(
                "a new orderId while an order is held is rejected",
                ("R40", "R30"),
                self._order(2, 0, [first, ahead]),
                rejected(o2, 0, kept),
            ),
            Step(
                "an update whose orderUpdateId skips values is accepted when it stitches",
                ("R53",),
                self._order(1, 5, [first, ahead]),
                carries(o1, 5, [(AHEAD, 2, False)]),
                essential=True,
            ),
        ]

    def _idle_update_steps(self) -> list[Step]:
        """The horizon taken away (the order ends), updates to the ended order, a cancel."""
        s = self.start
        first = self._first()
        o1 = self.order_id(1)
        cancel_id = self.cancel_id
        return [
            Step(
                "an update without a horizon leaves none: the order is done",
                ("R54",),
                self._order(1, 6, [first]),
                carries(o1, 6, []),
                essential=True,
            ),
            Step(
                "an update of the ended order that does not start at its last node is rejected",
                ("R49", "R30"),
                self._order(1, 7, [self._stray(), self._horizon(AHEAD, 4, s.at(1.0))]),
                rejected(o1, 7, (o1, 6)),
            ),
            Step(
                "an update of the ended order that starts at its last node is accepted",
                ("R48",),
                self._order(1, 8, [first, self._horizon(LEFT, 2, s.at(0.0, 1.0))]),
                carries(o1, 8, [(LEFT, 2, False)]),
                essential=True,
            ),
            Step(
                "cancelOrder ends FINISHED with nothing of the order listed",
                ("R59", "R62"),
                instant_action("cancelOrder", cancel_id, BlockingType.HARD),
                cancelled(o1, cancel_id),
                within_s=5.0,
                essential=True,
            ),
        ]

    def _new_order_steps(self) -> list[Step]:
        """New orders the idle vehicle must reject, one it must take, and the two requests."""
        s = self.start
        first = self._first()
        o1, o3, o4, o6 = (self.order_id(n) for n in (1, 3, 4, 6))
        far = Node(
            node_id="vda-probe-far",
            sequence_id=0,
            released=True,
            node_position=s.at(FAR_M),
            actions=[],
        )
        unknown = _with_action(first, UNKNOWN_ACTION, f"{o4}-unknown")
        misplaced = _with_action(first, "cancelOrder", f"{o6}-cancel")
        state_id = f"vda-probe-{self.run_id}-state"
        factsheet_id = f"vda-probe-{self.run_id}-factsheet"
        return [
            Step(
                f"a new order whose first node lies {FAR_M:g} m away is rejected",
                ("R37", "R30"),
                self._order(3, 0, [far]),
                rejected(o3, 0, (o1, None)),
            ),
            Step(
                "an order with an action type the vehicle does not know is rejected",
                ("R31", "R33", "R30"),
                self._order(4, 0, [unknown]),
                rejected(o4, 0, (o1, None), absent_action=f"{o4}-unknown"),
            ),
            Step(
                "an order with cancelOrder (an instant action only) on a node is rejected",
                ("R83", "R30"),
                self._order(6, 0, [misplaced]),
                rejected(o6, 0, (o1, None), absent_action=f"{o6}-cancel"),
            ),
            *self._optional_steps(),
            self._last_order_step(),
            Step(
                "stateRequest is answered by a state and FINISHED",
                ("R79",),
                instant_action("stateRequest", state_id),
                finished(state_id),
            ),
            Step(
                "factsheetRequest brings a factsheet and is FINISHED",
                ("R80",),
                instant_action("factsheetRequest", factsheet_id),
                finished(factsheet_id, factsheet=True),
            ),
            *self._trigger_steps(),  # last: its first step, when it fails, skips only the rest
        ]

    def _trigger_steps(self) -> list[Step]:
        """R41 and R82: an order whose only node waits for a trigger, a new order while that
        action runs, and the cancel that must end it FAILED."""
        if self.trigger_parameters is None:
            return []
        o10, o11 = self.order_id(10), self.order_id(11)
        waiting = f"{o10}-wait"
        node = _with_action(self._first(), "waitForTrigger", waiting, self.trigger_parameters)
        return [
            Step(
                "an order whose node waits for a trigger where it stands is taken",
                ("R42",),
                self._order(10, 0, [node]),
                runs(o10, waiting),
                essential=True,
            ),
            Step(
                "an update stitched at that node, with its action as sent and a horizon node, "
                "keeps the action running, listed once",
                ("R51", "R46"),
                self._order(10, 1, [node, self._horizon(AHEAD, 2, self.start.at(1.0))]),
                kept_once(o10, 1, waiting, [(AHEAD, 2, False)]),
            ),
            Step(
                "a new orderId while an action of the order runs is rejected",
                ("R41", "R30"),
                self._order(11, 0, [self._first()]),
                rejected(o11, 0, (o10, None)),
            ),
            Step(
                "cancelOrder ends the waiting trigger FAILED",
                ("R59", "R82"),
                instant_action("cancelOrder", f"{self.cancel_id}-trigger", BlockingType.HARD),
                cancelled(o10, f"{self.cancel_id}-trigger", failing=waiting),
                within_s=5.0,
            ),
        ]

    def _unsupported_field_step(self, path: str) -> Step:
        """R32: an optional edge field the factsheet does not list, on the horizon edge."""
        name = path.rsplit(".", 1)[-1]
        first = self._first()
        order = self._order(9, 0, [first, self._horizon(AHEAD, 2, self.start.at(1.0))])
        edge = order.edges[0].model_copy(update=UNSUPPORTED_CANDIDATES[path])
        order = order.model_copy(update={"edges": [edge]})
        return Step(
            f"an order with {name}, an optional field the factsheet does not list, is rejected",
            ("R32", "R30"),
            order,
            naming(rejected(self.order_id(9), 0, (self.order_id(1), None)), name),
        )

    def _sideways_step(self) -> Step:
        """R34: a differential drive cannot hold an orientation across its edge (TANGENTIAL
        pi/2 on the horizon edge: nothing is released)."""
        order = self._order(12, 0, [self._first(), self._horizon(AHEAD, 2, self.start.at(1.0))])
        edge = order.edges[0].model_copy(
            update={"orientation": math.pi / 2, "orientation_type": OrientationType.TANGENTIAL}
        )
        return Step(
            "an order whose edge asks a differential drive to drive sideways is rejected",
            ("R34", "R30"),
            order.model_copy(update={"edges": [edge]}),
            rejected(self.order_id(12), 0, (self.order_id(1), None)),
        )

    def _last_order_step(self) -> Step:
        """R42 once more; in 2.x also R43: the ended cancelOrder's state goes with the new
        order (3.0 keeps instant actions until ``clearInstantActions``)."""
        order = self._order(5, 0, [self._first()])
        if self.v3:
            title = "a new order from where it stands is accepted and done at once"
            return Step(title, ("R42",), order, carries(self.order_id(5), 0, []))
        return Step(
            "a new order from where it stands is accepted and done at once, the states of "
            "the actions before it gone",
            ("R42", "R43"),
            order,
            carries(self.order_id(5), 0, [], dropped=self.cancel_id),
        )

    def _stray(self) -> Node:
        """A first node that is not the decision point: the horizon node to the left."""
        return Node(
            node_id=LEFT,
            sequence_id=2,
            released=True,
            node_position=self.start.at(0.0, 1.0),
            actions=[],
        )


#: A value of each factsheet valueDataType, for required parameters the probe must fill in.
SAMPLE_VALUES: Final[dict[str, object]] = {
    "BOOL": False,
    "NUMBER": 0,
    "INTEGER": 0,
    "FLOAT": 0.0,
    "STRING": "vda-probe",
    "OBJECT": {},
    "ARRAY": [],
}


def trigger_parameters(factsheet: Factsheet) -> dict[str, object] | None:
    """The parameters to send ``waitForTrigger`` as a node action with, when ``factsheet``
    offers it there (its required parameters, each with a value of its type), else None."""
    for action in factsheet.protocol_features.agv_actions:
        scopes = {scope.value for scope in action.action_scopes}
        if action.action_type == "waitForTrigger" and "NODE" in scopes:
            return {
                p.key: SAMPLE_VALUES.get(p.value_data_type.value, "vda-probe")
                for p in action.action_parameters or ()
                if not p.is_optional
            }
    return None


def unsupported_field(factsheet: Factsheet) -> str | None:
    """The first of ``UNSUPPORTED_CANDIDATES`` that ``factsheet`` does not list as supported
    or required (R32), or None."""
    listed = {p.parameter for p in factsheet.protocol_features.optional_parameters}
    return next((path for path in UNSUPPORTED_CANDIDATES if path not in listed), None)


def _with_action(
    node: Node, action_type: str, action_id: str, parameters: dict[str, object] | None = None
) -> Node:
    action = _action(action_type, action_id, BlockingType.HARD)
    if parameters:
        listed = [ActionParameter(key=k, value=v) for k, v in parameters.items()]
        action = action.model_copy(update={"action_parameters": listed})
    return node.model_copy(update={"actions": [action]})


def timed_out(step: Step, seen: Seen, waited_s: float) -> Verdict:
    """The verdict on a step its judge left undecided for ``waited_s``: a pass when nothing
    was to happen, else a fail saying what the vehicle last showed."""
    if step.quiet:
        return Verdict(Outcome.PASS, "nothing happened")
    return Verdict(Outcome.FAIL, f"undecided after {waited_s:g} s: {last_seen(step, seen)}")


def last_seen(step: Step, seen: Seen) -> str:
    """What the vehicle last showed, for a step that ran out of time undecided."""
    if not seen.states:
        return "no state came"
    state = seen.states[-1]
    if isinstance(step.message, InstantActions):
        (sent,) = step.message.actions
        status = next(
            (a.action_status.value for a in state.action_states if a.action_id == sent.action_id),
            "not listed",
        )
        new = [
            f"{e.error_type}: {e.error_description or ''}"
            for e in state.errors
            if error_key(e) not in seen.errors_before
        ]
        errors = f"; new errors {new}" if new else ""
        return f"{sent.action_type} {status} in the last of {len(seen.states)} state(s){errors}"
    listed = [n.node_id for n in state.node_states]
    return (
        f"the last of {len(seen.states)} state(s) carries {state.order_id!r} update "
        f"{state.order_update_id}, nodes {listed}"
    )


def _action(action_type: str, action_id: str, blocking: BlockingType) -> Action:
    return Action(action_type=action_type, action_id=action_id, blocking_type=blocking)


def instant_action(
    action_type: str, action_id: str, blocking: BlockingType = BlockingType.NONE
) -> InstantActions:
    """One instant action, its header to be stamped when sent."""
    actions = [_action(action_type, action_id, blocking)]
    return InstantActions.model_validate({**UNSTAMPED, "actions": actions})
