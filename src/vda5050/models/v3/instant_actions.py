"""Topic ``instantActions`` (3.0): fleet control → mobile robot (§6.2.1, §7.4)."""

from __future__ import annotations

from typing import Literal

from vda5050.models.v3.base import V3Message
from vda5050.models.v3.common import Action, BlockingType

__all__ = ["InstantAction", "InstantActions"]


class InstantAction(Action):
    """An action to run now. Its blockingType is always NONE (§6.2.1; the official schema's
    enum holds only NONE), so any other value fails decoding. Its state goes to
    ``instantActionStates`` (§6.6.9)."""

    blocking_type: Literal[BlockingType.NONE]


class InstantActions(V3Message):
    """A batch of instant actions, run in array order (§7.4)."""

    actions: list[InstantAction]
