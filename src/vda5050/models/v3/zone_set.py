"""Topic ``zoneSet`` (3.0): fleet control → mobile robot (§6.4, §7.6).

A zone set is a list of polygonal zones for one map. Each zone type needs its own parameters
(§6.4.1 Tables 6 and 7); which ones is data (:data:`ZONE_PARAMETERS`) that both the model
check and the generated JSON schema (its ``allOf``/``if``/``then``, as in the official schema)
are built from.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import StrEnum
from types import MappingProxyType
from typing import Annotated, Final, Self

from pydantic import Field, model_validator
from pydantic.alias_generators import to_snake

from vda5050.models.v3.base import V3Message, V3WireModel
from vda5050.models.v3.common import ActionParameter, BlockingType

__all__ = [
    "CONTOUR_BASED_ZONES",
    "ZONE_PARAMETERS",
    "BidirectedLimitation",
    "DirectedLimitation",
    "Vertex",
    "Zone",
    "ZoneAction",
    "ZoneReleaseLossBehavior",
    "ZoneSet",
    "ZoneSetMessage",
    "ZoneType",
]


class ZoneType(StrEnum):
    """The ten zone types (§6.4.1)."""

    BLOCKED = "BLOCKED"
    LINE_GUIDED = "LINE_GUIDED"
    RELEASE = "RELEASE"
    COORDINATED_REPLANNING = "COORDINATED_REPLANNING"
    SPEED_LIMIT = "SPEED_LIMIT"
    ACTION = "ACTION"
    PRIORITY = "PRIORITY"
    PENALTY = "PENALTY"
    DIRECTED = "DIRECTED"
    BIDIRECTED = "BIDIRECTED"


#: Zones entered when any part of the contour (with load) enters (Table 6); the others are
#: entered with the kinematic center (Table 7).
CONTOUR_BASED_ZONES: Final = frozenset(
    {
        ZoneType.BLOCKED,
        ZoneType.LINE_GUIDED,
        ZoneType.RELEASE,
        ZoneType.COORDINATED_REPLANNING,
        ZoneType.SPEED_LIMIT,
        ZoneType.ACTION,
    }
)

#: The JSON fields a zone of each type must carry (§7.6 "required only for ..."; the official
#: schema's if/then). Table 6 adds that a RELEASE zone without releaseLossBehavior means STOP;
#: the message table and the schema require it, and so does this model.
ZONE_PARAMETERS: Final[Mapping[ZoneType, tuple[str, ...]]] = MappingProxyType(
    {
        ZoneType.BLOCKED: (),
        ZoneType.LINE_GUIDED: (),
        ZoneType.RELEASE: ("releaseLossBehavior",),
        ZoneType.COORDINATED_REPLANNING: (),
        ZoneType.SPEED_LIMIT: ("maximumSpeed",),
        ZoneType.ACTION: ("entryActions", "duringActions", "exitActions"),
        ZoneType.PRIORITY: ("priorityFactor",),
        ZoneType.PENALTY: ("penaltyFactor",),
        ZoneType.DIRECTED: ("direction", "directedLimitation"),
        ZoneType.BIDIRECTED: ("direction", "bidirectedLimitation"),
    }
)


class ZoneReleaseLossBehavior(StrEnum):
    """What a robot inside a RELEASE zone does when its release is revoked or expires."""

    STOP = "STOP"
    CONTINUE = "CONTINUE"
    EVACUATE = "EVACUATE"


class DirectedLimitation(StrEnum):
    """How strictly a DIRECTED zone's direction binds (Table 7)."""

    SOFT = "SOFT"
    RESTRICTED = "RESTRICTED"
    STRICT = "STRICT"


class BidirectedLimitation(StrEnum):
    """How strictly a BIDIRECTED zone's directions bind (Table 7)."""

    SOFT = "SOFT"
    RESTRICTED = "RESTRICTED"


class Vertex(V3WireModel):
    """A polygon corner in project coordinates, metres."""

    x: float
    y: float


class ZoneAction(V3WireModel):
    """An action of an ACTION zone; like an order action, but the robot makes up the actionId
    itself (§7.6), so there is none on the wire."""

    action_type: str
    action_descriptor: str | None = None
    blocking_type: BlockingType
    action_parameters: list[ActionParameter] | None = None
    retriable: bool | None = None


def _conditional_requirements(schema: dict[str, object]) -> None:
    schema["allOf"] = [
        {
            "if": {"properties": {"zoneType": {"const": zone_type.value}}},
            "then": {"required": list(fields)},
        }
        for zone_type, fields in ZONE_PARAMETERS.items()
        if fields
    ]


class Zone(V3WireModel, json_schema_extra=_conditional_requirements):
    """One zone: a simple polygon given counterclockwise, closed implicitly (§7.6)."""

    zone_id: str
    zone_type: ZoneType
    zone_descriptor: str | None = None
    #: At least three vertices; a zone with fewer is invalid and shall be rejected (§7.6).
    vertices: Annotated[list[Vertex], Field(min_length=3)]
    maximum_speed: float | None = None
    entry_actions: list[ZoneAction] | None = None
    during_actions: list[ZoneAction] | None = None
    exit_actions: list[ZoneAction] | None = None
    release_loss_behavior: ZoneReleaseLossBehavior | None = None
    priority_factor: Annotated[float, Field(ge=0, le=1)] | None = None
    penalty_factor: Annotated[float, Field(ge=0, le=1)] | None = None
    #: Direction of travel in radians (DIRECTED, BIDIRECTED).
    direction: float | None = None
    directed_limitation: DirectedLimitation | None = None
    bidirected_limitation: BidirectedLimitation | None = None

    @model_validator(mode="after")
    def _has_type_parameters(self) -> Self:
        missing = [
            name
            for name in ZONE_PARAMETERS[self.zone_type]
            if getattr(self, to_snake(name)) is None
        ]
        if missing:
            msg = f"a {self.zone_type.value} zone needs {', '.join(missing)} (§7.6)"
            raise ValueError(msg)
        return self


class ZoneSet(V3WireModel):
    """The zones of one map under a globally unique ``zoneSetId``; its content never changes
    under the same id (§6.4.2)."""

    map_id: str
    zone_set_id: str
    zone_set_descriptor: str | None = None
    zones: list[Zone]


class ZoneSetMessage(V3Message):
    """The ``zoneSet`` message: header plus one zone set (§7.6)."""

    zone_set: ZoneSet
