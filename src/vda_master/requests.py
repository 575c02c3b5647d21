"""What the HTTP API asks of master control, and how refusals are expressed.

A refusal is a :class:`RequestError` carrying the HTTP status to answer (404 unknown vehicle,
node, edge or order; 409 the vehicle cannot take it now; 422 the request itself is wrong) and a
message that says what is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import orjson
from pydantic import computed_field

from vda5050.models import Action, InstantActions
from vda5050.topics import AgvId
from vda_master.capabilities import ActionSpec
from vda_master.planner import Target
from vda_master.routing import ProblemKind
from vda_master.stops import Stop, spec_document, stop_document

PROBLEM_STATUS: Final = {
    ProblemKind.UNKNOWN_NODE: 404,
    ProblemKind.UNKNOWN_EDGE: 404,
    ProblemKind.DISCONTINUOUS: 422,
    ProblemKind.NO_POSITION: 409,
    ProblemKind.NO_ROUTE: 409,
}


class RequestError(Exception):
    """A request master control cannot carry out; ``status`` is the HTTP status to answer."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


@dataclass(frozen=True, slots=True)
class OrderRequest:
    """``POST /orders``: an optional vehicle, a target, actions at the destination node."""

    target: Target
    agv: AgvId | None = None
    destination_actions: tuple[ActionSpec, ...] = ()
    #: Wait for a vehicle instead of a 409 when none can take it now (docs/master.md,
    #: *Queued orders*); ``priority`` orders the waiting ones (higher first).
    queue: bool = False
    priority: int = 0
    #: Simulated seconds a queued order may wait before it fails (None: as long as it takes).
    queue_timeout_s: float | None = None
    #: The stops after the first (``target`` with ``destination_actions``), in order
    #: (:mod:`vda_master.stops`).
    onward: tuple[Stop, ...] = ()

    def as_json(self) -> str:
        """The request as the API's JSON (camelCase), kept with the order in the store."""
        document: dict[str, object] = {}
        if self.agv is not None:
            document["manufacturer"] = self.agv.manufacturer
            document["serialNumber"] = self.agv.serial_number
        target = self.target
        if self.onward:
            first = Stop(target.destination, target.station_type, self.destination_actions)
            document["stops"] = [stop_document(stop) for stop in (first, *self.onward)]
        else:
            if target.destination is not None:
                document["destination"] = target.destination
            if target.route is not None:
                document["route"] = list(target.route)
            if target.station_type is not None:
                document["stationType"] = target.station_type
            document["destinationActions"] = [
                spec_document(spec) for spec in self.destination_actions
            ]
        if self.queue:
            document["queue"] = True
            document["priority"] = self.priority
            if self.queue_timeout_s is not None:
                document["queueTimeoutS"] = self.queue_timeout_s
        return orjson.dumps(document).decode()


def speaking_version(version: str | None) -> str:
    """The version to address a vehicle in: the one of its own messages (§6.4); 3.x vehicles
    get 3.0.0 (3.0 T12: minor and patch differences are accepted)."""
    if version in {"2.0.0", "2.1.0"}:
        return version
    if version is not None and version.startswith("3."):
        return "3.0.0"
    return "2.0.0" if version is not None and version.startswith("2.0.") else "2.1.0"


def instant_actions_message(agv: AgvId, actions: list[Action]) -> InstantActions:
    """An unstamped instantActions message; the stamper writes the header when it is sent."""
    return InstantActions(
        header_id=0,
        timestamp="1970-01-01T00:00:00.000Z",
        version="2.1.0",
        manufacturer=agv.manufacturer,
        serial_number=agv.serial_number,
        actions=actions,
    )


class LegacyKeyInstantActions(InstantActions):
    """instantActions whose array is also written under ``instantActions``, for 2.0 vehicles.

    vda-5050-lib 1.4 (the most used open VDA 5050 library) reads 2.0 instant actions only under
    the 1.x name ``instantActions`` and rejects a spec-exact message. The duplicate keeps the
    message valid against the official 2.0.0 schema (additional properties are allowed) and is
    ignored by vehicles that read ``actions``. Master config ``legacy_instant_actions_key``.
    """

    @computed_field(alias="instantActions")  # type: ignore[prop-decorator]
    @property
    def legacy_actions(self) -> list[Action]:
        return self.actions


def with_legacy_key(message: InstantActions) -> LegacyKeyInstantActions:
    """``message`` with its actions also under the 1.x key (:class:`LegacyKeyInstantActions`)."""
    return LegacyKeyInstantActions.model_validate(message.model_dump())
