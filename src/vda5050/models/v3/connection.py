"""Topic ``connection`` (3.0): mobile robot (or the broker, by last will) → fleet control (§6.5,
§7.7)."""

from __future__ import annotations

from enum import StrEnum

from vda5050.models.v3.base import V3Message

__all__ = ["Connection", "ConnectionState"]


class ConnectionState(StrEnum):
    """State of the robot's broker connection (3.0 spelling with underscores).

    HIBERNATING: the robot stays connected but sends no state until ``stopHibernation`` (or its
    own wake-up time) brings it back ONLINE (§6.2.3.1 startHibernation, §7.7).
    """

    ONLINE = "ONLINE"
    OFFLINE = "OFFLINE"
    HIBERNATING = "HIBERNATING"
    CONNECTION_BROKEN = "CONNECTION_BROKEN"


class Connection(V3Message):
    """ONLINE after connect, OFFLINE before a clean disconnect, HIBERNATING while hibernating,
    CONNECTION_BROKEN as last will; always QoS 1 and retained (§4.1, §6.5)."""

    connection_state: ConnectionState
