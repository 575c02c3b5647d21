"""Objects that several topics share: actions, positions, trajectories, loads (§6.6.6, §6.10.6)."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

from pydantic import Field, JsonValue, field_validator

from vda5050.models.base import Angle, NonNegativeFloat, WireModel, is_finite_json


class BlockingType(StrEnum):
    """How an action blocks driving and other actions (§6.12)."""

    NONE = "NONE"
    SOFT = "SOFT"
    HARD = "HARD"


#: An action parameter's value: array, boolean, number, string or object (§7.2); never null.
ParameterValue = Annotated[
    JsonValue,
    Field(json_schema_extra={"type": ["array", "boolean", "number", "string", "object"]}),
]


class ActionParameter(WireModel):
    """A key/value pair of an action (§7.2)."""

    key: str
    value: ParameterValue

    @field_validator("value")
    @classmethod
    def _reject_non_finite(cls, value: ParameterValue) -> ParameterValue:
        # §7.2 allows array, boolean, number, string and object, so no null; §6.1.4 bans
        # NaN/Infinity, also inside free-form values.
        if value is None:
            msg = "an action parameter value must not be null"
            raise ValueError(msg)
        if not is_finite_json(value):
            msg = "NaN and Infinity are not allowed in JSON numbers"
            raise ValueError(msg)
        return value


class Action(WireModel):
    """A node, edge or instant action (§6.6.6, §6.9)."""

    action_type: str
    action_id: str
    action_description: str | None = None
    blocking_type: BlockingType
    action_parameters: list[ActionParameter] | None = None

    def parameter(self, key: str) -> ParameterValue | None:
        """Return the value of parameter ``key``, or None when the action does not carry it."""
        for parameter in self.action_parameters or ():
            if parameter.key == key:
                return parameter.value
        return None


class NodePosition(WireModel):
    """Where a node is on which map, and how closely the vehicle must reach it (§6.6.6)."""

    x: float
    y: float
    theta: Angle | None = None
    allowed_deviation_xy: NonNegativeFloat | None = Field(default=None, alias="allowedDeviationXY")
    allowed_deviation_theta: Annotated[float, Field(ge=0, le=3.141592654)] | None = None
    map_id: str
    map_description: str | None = None


class ControlPoint(WireModel):
    """A NURBS control point; weight defaults to 1.0 (§6.6.6)."""

    x: float
    y: float
    weight: NonNegativeFloat | None = None


class Trajectory(WireModel):
    """A NURBS path between two nodes (§6.6.6)."""

    # Integer in the schemas, float64 in the prose: accept 1.0, always send integers (digest §11.4).
    degree: Annotated[int, Field(ge=1, strict=False)]
    knot_vector: list[Annotated[float, Field(ge=0, le=1)]]
    control_points: list[ControlPoint]


class AgvPosition(WireModel):
    """The vehicle pose on a map (§6.10.6)."""

    x: float
    y: float
    theta: Angle
    map_id: str
    map_description: str | None = None
    position_initialized: bool
    localization_score: Annotated[float, Field(ge=0, le=1)] | None = None
    deviation_range: float | None = None


class Velocity(WireModel):
    """Velocity in the vehicle frame, m/s and rad/s (§6.10.6)."""

    vx: float | None = None
    vy: float | None = None
    omega: float | None = None


class BoundingBoxReference(WireModel):
    """Centre of the bottom face of a load's bounding box, in vehicle coordinates."""

    x: float
    y: float
    z: float
    theta: float | None = None


class LoadDimensions(WireModel):
    """Size of a load's bounding box in metres."""

    length: float
    width: float
    height: float | None = None
