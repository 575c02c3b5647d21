"""Topic ``connection``: AGV (or the broker, by last will) → master control (§6.14)."""

from __future__ import annotations

from enum import StrEnum

from vda5050.models.base import Message


class ConnectionState(StrEnum):
    """State of the AGV's broker connection (2.x spelling, no underscore)."""

    ONLINE = "ONLINE"
    OFFLINE = "OFFLINE"
    CONNECTIONBROKEN = "CONNECTIONBROKEN"


class Connection(Message):
    """ONLINE after connect, OFFLINE before a clean disconnect, CONNECTIONBROKEN as last will."""

    connection_state: ConnectionState
