"""Topic ``instantActions``: master control → AGV (§6.9)."""

from __future__ import annotations

from typing import Any, Final

from pydantic import ModelWrapValidatorHandler, PrivateAttr, model_validator

from vda5050.models.base import Message
from vda5050.models.common import Action

#: What a reader notes when it accepts the array under the VDA 5050 1.x name.
LEGACY_ARRAY_KEY_NOTE: Final = (
    "the actions came under 'instantActions' (the VDA 5050 1.x name) instead of 'actions'"
)


class InstantActions(Message):
    """A batch of actions to run now, in array order (§6.9)."""

    # Tolerant reader: 2.0 peers built on vda-5050-lib 1.4 send the array under `instantActions`
    # (the 1.1 name, digest §10.1). Such a message is read as if it said `actions`, and
    # `tolerated` says so, for the receiver to log. Writers always use `actions`.
    actions: list[Action]
    _tolerated: tuple[str, ...] = PrivateAttr(default=())

    @model_validator(mode="wrap")
    @classmethod
    def _accept_legacy_array_key(
        cls,
        data: Any,  # noqa: ANN401 - whatever the reader got, before validation
        handler: ModelWrapValidatorHandler[InstantActions],
    ) -> InstantActions:
        if (
            isinstance(data, dict)
            and "actions" not in data
            and isinstance(data.get("instantActions"), list)
        ):
            message = handler({**data, "actions": data["instantActions"]})
            message._tolerated = (LEGACY_ARRAY_KEY_NOTE,)  # noqa: SLF001 - set by the model itself
            return message
        return handler(data)

    @property
    def tolerated(self) -> tuple[str, ...]:
        """Deviations from the standard that were accepted when this message was read."""
        return self._tolerated
