"""Topic ``visualization``: AGV → visualisation systems (§6.13)."""

from __future__ import annotations

from vda5050.models.base import LenientHeaderMessage
from vda5050.models.common import AgvPosition, Velocity


class Visualization(LenientHeaderMessage):
    """High-rate pose for display only; the 2.x schema requires no field at all."""

    agv_position: AgvPosition | None = None
    velocity: Velocity | None = None
