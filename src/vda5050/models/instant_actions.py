"""Topic ``instantActions``: master control → AGV (§6.9)."""

from __future__ import annotations

from vda5050.models.base import Message
from vda5050.models.common import Action


class InstantActions(Message):
    """A batch of actions to run now, in array order (§6.9)."""

    actions: list[Action]
