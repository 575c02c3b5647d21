"""What this vehicle can do: the single source for order checks and for its factsheet.

``decide_order`` rejects what is not listed here, and ``build_factsheet`` declares exactly what
is listed here, so the factsheet stays truthful (§6.1.1, §6.15, R31, R32, R111, R115).
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Final

from pydantic import BaseModel

from vda5050.models import Order, v3
from vda_vehicle.action_catalog import default_catalog
from vda_vehicle.actions import ActionSpec
from vda_vehicle.kinematics import Kinematic
from vda_vehicle.limits import MapExtent, ProtocolLimits
from vda_vehicle.trajectories import MAX_DEGREE

#: Optional order fields this vehicle acts on, as factsheet ``optionalParameters`` paths.
#: Descriptions are free text for people and are always accepted. ``nodePosition`` is REQUIRED:
#: the simulated stack navigates by coordinates (see :data:`REQUIRED_FIELDS`).
SUPPORTED_FIELDS: Final = frozenset(
    {
        "order.zoneSetId",
        "order.nodes.nodeDescription",
        "order.nodes.nodePosition",
        "order.nodes.nodePosition.theta",
        "order.nodes.nodePosition.allowedDeviationXY",
        "order.nodes.nodePosition.allowedDeviationTheta",
        "order.nodes.nodePosition.mapDescription",
        "order.nodes.actions.actionDescription",
        "order.nodes.actions.actionParameters",
        "order.edges.edgeDescription",
        "order.edges.maxSpeed",
        "order.edges.maxHeight",
        "order.edges.orientation",
        "order.edges.orientationType",
        "order.edges.rotationAllowed",
        "order.edges.maxRotationSpeed",
        "order.edges.length",
        "order.edges.trajectory",
        # Accepted and never used to deviate: the simulated stack follows the trajectory (or
        # the straight line) exactly, so it is always inside any corridor (trajectories.py).
        "order.edges.corridor",
        "order.edges.actions.actionDescription",
        "order.edges.actions.actionParameters",
    }
)
REQUIRED_FIELDS: Final = frozenset({"order.nodes.nodePosition"})
#: Supported fields that 2.0 does not have (:func:`fields_for`).
SINCE_2_1_FIELDS: Final = frozenset({"order.edges.corridor"})
#: The factsheet's word on how far a supported field is supported (optionalParameters
#: ``description``, §6.15; 3.0 §7.13), in both versions.
FIELD_NOTES: Final = {
    "order.edges.trajectory": f"NURBS of degree 1 to {MAX_DEGREE}, followed exactly",
    "order.edges.corridor": "accepted; the trajectory is followed exactly, the corridor never used",
}


def fields_for(version: str) -> frozenset[str]:
    """:data:`SUPPORTED_FIELDS` as a vehicle speaking ``version`` has them: 2.0 has no
    corridor, so a 2.0 vehicle neither declares nor takes one."""
    return SUPPORTED_FIELDS - SINCE_2_1_FIELDS if version == "2.0.0" else SUPPORTED_FIELDS


@dataclass(frozen=True, slots=True)
class Capabilities:
    """The vehicle's limits and features. Speeds in m/s and rad/s, lengths in m.

    Defaults: 1.5 m/s, 1.0 rad/s, 2.0 m tall; a node counts as reached within 0.25 m and
    0.2 rad when the order gives no deviation (0 means "the manufacturer's normal tolerance",
    §6.6.6). The battery drains 0.05 %/m and charges 0.5 %/s.
    """

    map_ids: frozenset[str]
    catalog: Mapping[str, ActionSpec] = field(default_factory=default_catalog)
    supported_fields: frozenset[str] = SUPPORTED_FIELDS
    speed_max_mps: float = 1.5
    angular_speed_max_radps: float = 1.0
    height_m: float = 2.0
    width_m: float = 0.8
    length_m: float = 1.2
    deviation_xy_m: float = 0.25
    deviation_theta_rad: float = 0.2
    limits: ProtocolLimits = field(default_factory=ProtocolLimits)
    #: Extent of each held map's nodes (from the graph); orders placing nodes far outside are
    #: refused (:func:`vda_vehicle.limits.physical_problems`).
    map_extents: Mapping[str, MapExtent] = field(default_factory=dict)
    battery_drain_pct_per_m: float = 0.05
    #: Under this charge the vehicle stops and reports batteryLowError (FATAL) until charged
    #: :data:`vda_vehicle.faults.BATTERY_RESUME_MARGIN_PCT` above it.
    battery_stop_pct: float = 1.0
    charge_rate_pct_per_s: float = 0.5
    new_base_request_m: float = 3.0
    #: On cancelOrder, stop at once between nodes instead of finishing the edge (§6.6.3).
    stop_between_nodes: bool = False
    #: The load types it handles: one factsheet ``loadSet`` each; a pick or drop naming
    #: another ``loadType`` is rejected.
    load_types: tuple[str, ...] = ("EPAL",)
    #: OMNI holds any edge orientation; DIFF drives along an edge, forwards or backwards
    #: (:mod:`vda_vehicle.kinematics`, R34).
    kinematic: Kinematic = "OMNI"

    def reach_m(self, battery_charge: float) -> int | None:
        """batteryState.reach (§6.10.6): whole metres the charge lasts at the configured drain;
        None (left out) when driving drains nothing."""
        if not self.battery_drain_pct_per_m:
            return None
        return int(battery_charge / self.battery_drain_pct_per_m)


def optional_fields_used(order: Order | v3.Order) -> Iterator[tuple[str, str]]:
    """Every optional field set in ``order`` (2.x or 3.0: the same shape) as (dotted path,
    where), e.g. ``("order.edges.trajectory", "edge e1")``."""
    yield from _set_optionals(order, "order", "order")
    for node in order.nodes:
        where = f"node {node.node_id}"
        yield from _set_optionals(node, "order.nodes", where)
        if node.node_position is not None:
            yield from _set_optionals(node.node_position, "order.nodes.nodePosition", where)
        for action in node.actions:
            yield from _set_optionals(action, "order.nodes.actions", f"action {action.action_id}")
    for edge in order.edges:
        where = f"edge {edge.edge_id}"
        yield from _set_optionals(edge, "order.edges", where)
        for action in edge.actions:
            yield from _set_optionals(action, "order.edges.actions", f"action {action.action_id}")


def _set_optionals(model: BaseModel, prefix: str, where: str) -> Iterator[tuple[str, str]]:
    """The optional fields set in ``model`` (not None) as (``prefix.alias``, ``where``)."""
    paths = _optional_paths(type(model), prefix)
    for name in model.model_fields_set:
        path = paths.get(name)
        if path is not None and getattr(model, name) is not None:
            yield path, where


@functools.cache
def _optional_paths(model: type[BaseModel], prefix: str) -> dict[str, str]:
    """Attribute name → dotted wire path of ``model``'s optional fields, worked out once per
    model class (an order is checked field by field, R32)."""
    return {
        name: f"{prefix}.{info.serialization_alias or info.alias or name}"
        for name, info in model.model_fields.items()
        if not info.is_required()
    }
