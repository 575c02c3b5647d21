"""3.0 objects that several topics share: actions, trajectories, positions, paths, loads.

Field tables: action §7.3, trajectory §7.3 / §7.8, mobileRobotPosition, velocity, load,
plannedPath and intermediatePath §7.8 (visualization reuses them, §7.9).
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

from pydantic import Field

from vda5050.models.base import Angle, NonNegativeFloat, Timestamp
from vda5050.models.common import ActionParameter, BoundingBoxReference, ParameterValue, Velocity
from vda5050.models.v3.base import V3WireModel

__all__ = [
    "Action",
    "ActionParameter",
    "BlockingType",
    "BoundingBoxReference",
    "ControlPoint",
    "IntermediatePath",
    "Load",
    "LoadDimensions",
    "MobileRobotPosition",
    "PlannedPath",
    "Trajectory",
    "Velocity",
    "Waypoint",
]


class BlockingType(StrEnum):
    """Whether an action lets the robot drive and run other actions at the same time (§6.2.2,
    Table 3): NONE drive + parallel, SINGLE drive + alone, SOFT stop + parallel, HARD stop +
    alone."""

    NONE = "NONE"
    SINGLE = "SINGLE"
    SOFT = "SOFT"
    HARD = "HARD"

    @property
    def allows_driving(self) -> bool:
        """NONE and SINGLE let automatic driving go on (Table 3)."""
        return self in {BlockingType.NONE, BlockingType.SINGLE}

    @property
    def allows_parallel(self) -> bool:
        """NONE and SOFT may run beside other actions (Table 3)."""
        return self in {BlockingType.NONE, BlockingType.SOFT}


class Action(V3WireModel):
    """A node or edge action of an order (§7.3 ``action``)."""

    action_type: str
    action_id: str
    action_descriptor: str | None = None
    blocking_type: BlockingType
    action_parameters: list[ActionParameter] | None = None
    #: true: a failure goes to RETRIABLE instead of FAILED (§6.6.9). Absent means false.
    retriable: bool | None = None

    def parameter(self, key: str) -> ParameterValue | None:
        """Return the value of parameter ``key``, or None when the action does not carry it."""
        for parameter in self.action_parameters or ():
            if parameter.key == key:
                return parameter.value
        return None

    @property
    def is_retriable(self) -> bool:
        """The ``retriable`` flag with its default (false) applied."""
        return bool(self.retriable)


class ControlPoint(V3WireModel):
    """A NURBS control point. ``weight`` defaults to 1.0.

    The text gives the weight range ]0.0 ... float64.max]; the official schema has no bound. The
    text wins, so a weight of 0 or below is rejected.
    """

    x: float
    y: float
    weight: Annotated[float, Field(gt=0)] | None = None


class Trajectory(V3WireModel):
    """A NURBS curve (§7.3 ``trajectory``); also used by edgeStates, plannedPath and zone
    requests.

    3.0 makes ``degree`` (default 1) and ``knotVector`` (default: uniform knots) optional and
    types ``degree`` as uint32 (2.x prose said float64), so 1.0 is not accepted as a degree.
    """

    degree: Annotated[int, Field(ge=1)] | None = None
    knot_vector: list[Annotated[float, Field(ge=0, le=1)]] | None = None
    control_points: list[ControlPoint]


class MobileRobotPosition(V3WireModel):
    """The robot's pose on a map (§7.8; 2.x ``agvPosition``). ``localized`` replaces 2.x
    ``positionInitialized``: false means x, y and theta cannot be trusted."""

    x: float
    y: float
    theta: Angle
    map_id: str
    localized: bool
    localization_score: Annotated[float, Field(ge=0, le=1)] | None = None
    deviation_range: NonNegativeFloat | None = None


class Waypoint(V3WireModel):
    """End point of one segment of the intermediate path, with its estimated time of arrival."""

    x: float
    y: float
    theta: Angle | None = None
    eta: Timestamp


class IntermediatePath(V3WireModel):
    """The near path the robot perceives, as a polyline from its current position (§6.8)."""

    polyline: list[Waypoint]


class PlannedPath(V3WireModel):
    """The robot's own longer-range plan within its active order, as NURBS (§6.8)."""

    trajectory: Trajectory
    #: nodeIds of the current order that the planned path passes.
    traversed_nodes: list[str] | None = None


class LoadDimensions(V3WireModel):
    """Size of a load's bounding box in metres."""

    length: NonNegativeFloat
    width: NonNegativeFloat
    height: NonNegativeFloat | None = None


class Load(V3WireModel):
    """A load the robot carries (§7.8 ``load``)."""

    load_id: str | None = None
    load_type: str | None = None
    load_position: str | None = None
    bounding_box_reference: BoundingBoxReference | None = None
    load_dimensions: LoadDimensions | None = None
    weight: NonNegativeFloat | None = None
