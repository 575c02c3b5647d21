"""What a vehicle's factsheet allows master control to send (§6.1.1, §6.15; R112–R114).

- Optional fields go out only when ``protocolFeatures.optionalParameters`` lists them as
  SUPPORTED or REQUIRED (R112); REQUIRED ones are always filled in (R113). A listed sub-path
  (``order.nodes.nodePosition.theta``) implies its parent object (``order.nodes.nodePosition``).
- Actions go out only with a declared actionType, scope, blockingType and parameter keys
  (§6.8, digest §5.1), and every non-optional declared parameter is filled in.
- ``protocolLimits`` bound array sizes, id lengths and characters, the message size and the gap
  between two orders (R114). A missing or 0 limit means no limit.

The factsheet narrows, it does not permit: a vehicle without a valid factsheet gets full orders,
every field in :data:`FILLABLE_FIELDS` the graph has a value for (fields every vehicle can honour
or, like ``nodePosition`` for a line-guided vehicle, may ignore) and the actions the request asks
for, with the blocking types master control would pick anyway; but no ``trajectory`` nor
``corridor`` (:data:`FACTSHEET_ONLY_FIELDS`): a vehicle that plans its own path or cannot
process NURBS must not be sent one (§6.6.6), and without them every vehicle can drive the edge.
Such a vehicle rejects what it cannot do with an error in its state, which master control
reports as the order's reason.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from pydantic import JsonValue

from vda5050.memo import IdentityMemo
from vda5050.models import Action, ActionScope, BlockingType, Factsheet
from vda5050.models.factsheet import AgvAction, ProtocolFeatures, Support

#: Order fields master control knows how to fill in from the graph, by their dotted path.
NODE_POSITION = "order.nodes.nodePosition"
NODE_THETA = "order.nodes.nodePosition.theta"
NODE_DEVIATION_XY = "order.nodes.nodePosition.allowedDeviationXY"
NODE_DEVIATION_THETA = "order.nodes.nodePosition.allowedDeviationTheta"
NODE_DESCRIPTION = "order.nodes.nodeDescription"
EDGE_MAX_SPEED = "order.edges.maxSpeed"
EDGE_LENGTH = "order.edges.length"
EDGE_DESCRIPTION = "order.edges.edgeDescription"
EDGE_MAX_HEIGHT = "order.edges.maxHeight"
EDGE_MIN_HEIGHT = "order.edges.minHeight"
EDGE_ORIENTATION = "order.edges.orientation"
EDGE_ORIENTATION_TYPE = "order.edges.orientationType"
EDGE_DIRECTION = "order.edges.direction"
EDGE_ROTATION_ALLOWED = "order.edges.rotationAllowed"
EDGE_MAX_ROTATION_SPEED = "order.edges.maxRotationSpeed"
EDGE_TRAJECTORY = "order.edges.trajectory"
EDGE_CORRIDOR = "order.edges.corridor"
#: Sent only to a vehicle whose factsheet lists them: "if an AGV cannot process trajectories,
#: master control shall not send a trajectory" (2.1 §6.6.6), and a corridor needs one (§6.6.5).
FACTSHEET_ONLY_FIELDS = frozenset({EDGE_TRAJECTORY, EDGE_CORRIDOR})
FILLABLE_FIELDS = frozenset(
    {
        NODE_POSITION,
        NODE_THETA,
        NODE_DEVIATION_XY,
        NODE_DEVIATION_THETA,
        NODE_DESCRIPTION,
        EDGE_MAX_SPEED,
        EDGE_LENGTH,
        EDGE_DESCRIPTION,
        EDGE_MAX_HEIGHT,
        EDGE_MIN_HEIGHT,
        EDGE_ORIENTATION,
        EDGE_ORIENTATION_TYPE,
        EDGE_DIRECTION,
        EDGE_ROTATION_ALLOWED,
        EDGE_MAX_ROTATION_SPEED,
        *FACTSHEET_ONLY_FIELDS,
    }
)
#: What a vehicle without a factsheet is sent.
_WITHOUT_FACTSHEET = FILLABLE_FIELDS - FACTSHEET_ONLY_FIELDS
#: §6.10: without a factsheet value a vehicle publishes a state at least every 30 s.
DEFAULT_STATE_INTERVAL_S = 30.0
#: Blocking types master control picks when a request names none (§6.12): load handling and
#: positioning must not happen while driving.
DEFAULT_BLOCKING = {
    "pick": BlockingType.HARD,
    "drop": BlockingType.HARD,
    "finePositioning": BlockingType.HARD,
    "startCharging": BlockingType.HARD,
    "waitForTrigger": BlockingType.HARD,
}


#: Scopes of the predefined actions (§6.8.1 table, digest §5.5): what a vehicle without a
#: factsheet is sent, so that an obvious misuse (``pick`` as an instant action) is refused here.
_I, _N, _E = ActionScope.INSTANT, ActionScope.NODE, ActionScope.EDGE
PREDEFINED_SCOPES: dict[str, frozenset[ActionScope]] = {
    "startPause": frozenset({_I}),
    "stopPause": frozenset({_I}),
    "startCharging": frozenset({_I, _N}),
    "stopCharging": frozenset({_I, _N}),
    "initPosition": frozenset({_I, _N}),
    "enableMap": frozenset({_I, _N}),
    "downloadMap": frozenset({_I}),
    "deleteMap": frozenset({_I}),
    "stateRequest": frozenset({_I}),
    "logReport": frozenset({_I}),
    "pick": frozenset({_N, _E}),
    "drop": frozenset({_N, _E}),
    "detectObject": frozenset({_N, _E}),
    "finePositioning": frozenset({_N, _E}),
    "waitForTrigger": frozenset({_N}),
    "cancelOrder": frozenset({_I}),
    "factsheetRequest": frozenset({_I}),
}


@dataclass(frozen=True, slots=True)
class ActionSpec:
    """An action master control is asked to send; blockingType None = pick a sensible one."""

    action_type: str
    blocking_type: BlockingType | None = None
    parameters: Mapping[str, JsonValue] = field(default_factory=dict)


def supports_field(factsheet: Factsheet | None, path: str) -> bool:
    """Whether the optional field ``path`` may be sent (R112); without a factsheet every field
    master control can fill may be sent but a trajectory and a corridor (module docstring)."""
    return path in sendable_fields(factsheet)


def sendable_fields(factsheet: Factsheet | None) -> frozenset[str]:
    """Every optional field path :func:`supports_field` allows, as one set (for a planner that
    asks about a score of fields per order)."""
    if factsheet is None:
        return _WITHOUT_FACTSHEET
    return _optional_fields(factsheet).listed


def required_fields(factsheet: Factsheet | None) -> frozenset[str]:
    """The optional fields the vehicle marks REQUIRED (R113)."""
    if factsheet is None:
        return frozenset()
    return _optional_fields(factsheet).required


@dataclass(frozen=True, slots=True)
class _OptionalFields:
    """A factsheet's ``optionalParameters`` as sets: ``listed`` holds every listed path and the
    parent paths it implies (``a.b.c`` lists ``a.b.c``, ``a.b`` and ``a``)."""

    listed: frozenset[str]
    required: frozenset[str]


#: Per factsheet's protocolFeatures (by identity; models are immutable), so that planning an
#: order does not scan the list once per node and field. A fleet's factsheets decoded through
#: codec.SharedBodies share that object: one entry per vehicle type, not per vehicle.
_OPTIONAL_FIELDS: IdentityMemo[_OptionalFields] = IdentityMemo(limit=10_000)


def _optional_fields(factsheet: Factsheet) -> _OptionalFields:
    features = factsheet.protocol_features
    return _OPTIONAL_FIELDS.get(features, None, lambda: _collect_optional_fields(features))


def _collect_optional_fields(features: ProtocolFeatures) -> _OptionalFields:
    parameters = features.optional_parameters
    listed: set[str] = set()
    for parameter in parameters:
        path = parameter.parameter
        while path and path not in listed:  # the path, then its parents up to the first dot
            listed.add(path)
            path = path.rpartition(".")[0]
    required = frozenset(p.parameter for p in parameters if p.support == Support.REQUIRED)
    return _OptionalFields(frozenset(listed), required)


def unfillable_required(factsheet: Factsheet | None) -> list[str]:
    """REQUIRED order fields master control cannot produce (R113): an order would be rejected."""
    return sorted(
        path
        for path in required_fields(factsheet)
        if path.startswith("order.") and path not in FILLABLE_FIELDS
    )


def resolve_action(
    factsheet: Factsheet | None, spec: ActionSpec, scope: ActionScope
) -> tuple[BlockingType, dict[str, JsonValue]] | str:
    """The blockingType and parameters to send for ``spec`` in ``scope``, or why it cannot be."""
    if factsheet is None:
        return _without_factsheet(spec, scope)
    declared = declared_action(factsheet, spec.action_type, scope)
    if isinstance(declared, str):
        return declared
    blocking = _blocking_type(declared, spec)
    if not isinstance(blocking, BlockingType):  # BlockingType is a StrEnum: test it first
        return blocking
    problem = _parameter_problem(declared, spec.parameters)
    return problem if problem is not None else (blocking, dict(spec.parameters))


def declared_action(factsheet: Factsheet, action_type: str, scope: ActionScope) -> AgvAction | str:
    """The factsheet's declaration of ``action_type``, or why the vehicle never takes it in
    ``scope`` (not listed, or not in that scope; §6.15)."""
    declared = factsheet.action(action_type)
    if declared is None:
        return f"the vehicle's factsheet does not list action {action_type!r} (§6.15)"
    if scope not in declared.action_scopes:
        scopes = ", ".join(declared.action_scopes) or "none"
        return f"action {action_type!r} is not allowed as {scope.value} (factsheet: {scopes})"
    return declared


def _without_factsheet(
    spec: ActionSpec, scope: ActionScope
) -> tuple[BlockingType, dict[str, JsonValue]] | str:
    """The action as asked for; only the predefined scopes are checked (§6.8.1)."""
    predefined = PREDEFINED_SCOPES.get(spec.action_type)
    if predefined is not None and scope not in predefined:
        allowed = ", ".join(sorted(predefined))
        return f"action {spec.action_type!r} is not allowed as {scope.value} (§6.8.1: {allowed})"
    blocking = spec.blocking_type or DEFAULT_BLOCKING.get(spec.action_type, BlockingType.NONE)
    return blocking, dict(spec.parameters)


def declared_parameter_keys(factsheet: Factsheet | None, action_type: str) -> frozenset[str]:
    """Parameter keys the factsheet declares for ``action_type``."""
    declared = None if factsheet is None else factsheet.action(action_type)
    if declared is None:
        return frozenset()
    return frozenset(p.key for p in declared.action_parameters or ())


def _blocking_type(declared: AgvAction, spec: ActionSpec) -> BlockingType | str:
    allowed = declared.blocking_types
    if spec.blocking_type is not None:
        if allowed and spec.blocking_type not in allowed:
            names = ", ".join(allowed)
            return (
                f"action {spec.action_type!r} does not allow blockingType "
                f"{spec.blocking_type.value} (factsheet: {names})"
            )
        return spec.blocking_type
    default = DEFAULT_BLOCKING.get(spec.action_type, BlockingType.NONE)
    return allowed[0] if allowed and default not in allowed else default


def _parameter_problem(declared: AgvAction, parameters: Mapping[str, JsonValue]) -> str | None:
    known = {p.key: p for p in declared.action_parameters or ()}
    unknown = sorted(set(parameters) - set(known))
    if unknown:
        return (
            f"action {declared.action_type!r} has no parameter {', '.join(map(repr, unknown))} "
            "in the vehicle's factsheet"
        )
    missing = sorted(key for key, p in known.items() if not p.is_optional and key not in parameters)
    if missing:
        return f"action {declared.action_type!r} needs parameter {', '.join(map(repr, missing))}"
    return None


# -- protocolLimits (R114) --------------------------------------------------------------------


def _limit(value: int | None) -> int | None:
    return value or None


def max_order_nodes(factsheet: Factsheet | None) -> int | None:
    """How many nodes one order message may hold (``order.nodes``, and edges = nodes - 1)."""
    if factsheet is None:
        return None
    lens = factsheet.protocol_limits.max_array_lens
    nodes, edges = _limit(lens.order_nodes), _limit(lens.order_edges)
    candidates = [n for n in (nodes, None if edges is None else edges + 1) if n is not None]
    return min(candidates) if candidates else None


def min_order_interval_s(factsheet: Factsheet | None) -> float:
    """Least time between two order messages to this vehicle (§6.15 timing)."""
    return 0.0 if factsheet is None else factsheet.protocol_limits.timing.min_order_interval


def state_interval_s(factsheet: Factsheet | None) -> float:
    """The longest a healthy vehicle stays silent on ``state`` (§6.10, R92)."""
    timing = None if factsheet is None else factsheet.protocol_limits.timing
    if timing is None or not timing.default_state_interval:
        return DEFAULT_STATE_INTERVAL_S
    return timing.default_state_interval


def id_problems(factsheet: Factsheet | None, ids: Iterable[str]) -> list[str]:
    """Ids that break ``maxStringLens.idLen`` or ``idNumericalOnly`` (R114)."""
    if factsheet is None:
        return []
    lens = factsheet.protocol_limits.max_string_lens
    problems: list[str] = []
    for ident in ids:
        if lens.id_len and len(ident) > lens.id_len:
            problems.append(f"id {ident!r} is longer than the vehicle's idLen {lens.id_len}")
        if lens.id_numerical_only and not ident.isdigit():
            problems.append(f"id {ident!r} is not numeric (vehicle sets idNumericalOnly)")
    return problems


def action_limit_problems(factsheet: Factsheet | None, actions: Iterable[Action]) -> list[str]:
    """Actions over the vehicle's limits: parameters per action (``actions.actionsParameters``),
    actionType and parameter keys over ``enumLen`` (R114)."""
    if factsheet is None:
        return []
    enum_len = factsheet.protocol_limits.max_string_lens.enum_len
    problems: list[str] = []
    for action in actions:
        parameters = action.action_parameters or []
        counts = {"actions.actionsParameters": len(parameters)}
        problems.extend(array_problems(factsheet, counts))
        names = [action.action_type, *(p.key for p in parameters)]
        problems.extend(
            f"{name!r} is longer than the vehicle's enumLen {enum_len}"
            for name in names
            if enum_len and len(name) > enum_len
        )
    return problems


def array_problems(factsheet: Factsheet | None, counts: Mapping[str, int]) -> list[str]:
    """Array sizes over ``maxArrayLens`` (keys as in the factsheet, e.g. ``node.actions``)."""
    if factsheet is None:
        return []
    limits = factsheet.protocol_limits.max_array_lens.model_dump(by_alias=True)
    return [
        f"{key} holds {count} entries, over the vehicle's limit of {limits[key]}"
        for key, count in counts.items()
        if limits.get(key) and count > limits[key]
    ]


def message_size_problem(factsheet: Factsheet | None, size: int) -> str | None:
    """A message over ``maxStringLens.msgLen`` bytes, if any."""
    limit = None if factsheet is None else factsheet.protocol_limits.max_string_lens.msg_len
    if limit and size > limit:
        return f"the message is {size} bytes, over the vehicle's msgLen of {limit}"
    return None
