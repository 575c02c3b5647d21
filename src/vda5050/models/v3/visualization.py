"""Topic ``visualization`` (3.0): mobile robot → visualisation systems (§6.7, §6.8, §7.9)."""

from __future__ import annotations

from vda5050.models.base import UInt32
from vda5050.models.v3.base import V3Message
from vda5050.models.v3.common import IntermediatePath, MobileRobotPosition, PlannedPath, Velocity

__all__ = ["Visualization"]


class Visualization(V3Message):
    """High-rate pose and paths. Unlike 2.x, the header is required and the message names the
    state it belongs to by that state's headerId (``referenceStateHeaderId``)."""

    reference_state_header_id: UInt32
    planned_path: PlannedPath | None = None
    intermediate_path: IntermediatePath | None = None
    mobile_robot_position: MobileRobotPosition | None = None
    velocity: Velocity | None = None
