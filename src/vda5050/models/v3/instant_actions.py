"""Topic ``instantActions`` (3.0): fleet control → mobile robot (§6.2.1, §7.4)."""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator, Field

from vda5050.models.v3.base import V3Message
from vda5050.models.v3.common import Action, BlockingType

__all__ = ["InstantAction", "InstantActions"]


def _only_none(value: BlockingType) -> BlockingType:
    if value is not BlockingType.NONE:
        msg = f"an instant action's blockingType is always NONE (§6.2.1), got {value.value!r}"
        raise ValueError(msg)
    return value


class InstantAction(Action):
    """An action to run now. Its blockingType is always NONE (§6.2.1; the official schema's
    enum holds only NONE), so any other value fails decoding. Its state goes to
    ``instantActionStates`` (§6.6.9)."""

    # The enum type plus a check (rather than a Literal) keeps encoding as fast as for Action.
    blocking_type: Annotated[
        BlockingType, AfterValidator(_only_none), Field(json_schema_extra={"enum": ["NONE"]})
    ]


class InstantActions(V3Message):
    """A batch of instant actions, run in array order (§7.4)."""

    actions: list[InstantAction]
