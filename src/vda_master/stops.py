"""Orders with several stops: where each goes and what it does there (pure).

``POST /orders`` with ``stops`` (docs/master.md, *Orders with several stops*) asks for one order
that drives to each stop in turn and does its actions there: pick here, drop there. Master
control plans and sends the first stop as any order; each further stop is an
:class:`Stop` kept with the order's track (and its store record) and appended by an order
update once the vehicle stands at the stop before it (the stitching node, §6.6.2).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import orjson
from pydantic import JsonValue

from vda5050.models import ActionStatus, BlockingType, State
from vda_master.capabilities import ActionSpec
from vda_master.graph import Graph

#: At most this many stops in one order.
MAX_STOPS = 100


@dataclass(frozen=True, slots=True)
class Stop:
    """A stop still ahead: a node (``destination``) or the nearest node of ``station_type`` from
    the stop before it, and the node actions to do there."""

    destination: str | None
    station_type: str | None
    actions: tuple[ActionSpec, ...] = ()

    def describe(self) -> str:
        """The stop in words, for reasons and logs."""
        if self.destination is not None:
            return f"node {self.destination!r}"
        return f"a node of stationType {self.station_type!r}"


def spec_document(spec: ActionSpec) -> dict[str, JsonValue]:
    """An action as the API's JSON (``actionType``, ``blockingType``, ``actionParameters``)."""
    return {
        "actionType": spec.action_type,
        "blockingType": spec.blocking_type.value if spec.blocking_type else None,
        "actionParameters": [{"key": k, "value": v} for k, v in spec.parameters.items()],
    }


def stop_document(stop: Stop) -> dict[str, JsonValue]:
    """A stop as the API's JSON: ``destination`` or ``stationType``, and ``actions``."""
    document: dict[str, JsonValue] = {}
    if stop.destination is not None:
        document["destination"] = stop.destination
    if stop.station_type is not None:
        document["stationType"] = stop.station_type
    document["actions"] = [spec_document(spec) for spec in stop.actions]
    return document


def stop_from_document(document: Mapping[str, Any]) -> Stop:
    """The stop :func:`stop_document` wrote (from the store)."""
    actions = tuple(_spec_from_document(a) for a in document.get("actions", ()))
    return Stop(document.get("destination"), document.get("stationType"), actions)


def _spec_from_document(document: Mapping[str, Any]) -> ActionSpec:
    blocking = document.get("blockingType")
    parameters = {p["key"]: p["value"] for p in document.get("actionParameters", ())}
    return ActionSpec(
        str(document["actionType"]), BlockingType(blocking) if blocking else None, parameters
    )


def repeated_stop(stops: Sequence[Stop]) -> str | None:
    """Why the stops cannot follow each other (two in a row at the same node), or None."""
    for before, after in itertools.pairwise(stops):
        if before.destination is not None and before.destination == after.destination:
            return (
                f"two stops in a row at node {after.destination!r}: give the actions of both to "
                "one stop"
            )
    return None


def closed_stop(graph: Graph, onward: Sequence[Stop], first_number: int) -> str | None:
    """Why an order cannot reach one of its stops still ``onward`` (numbered from
    ``first_number``): the first whose node lies in a BLOCKED zone, or whose station type has
    no open node left; None when every one is open. An order that would pick a load it can
    never drop is better stopped before the pick."""
    for number, stop in enumerate(onward, start=first_number):
        if stop.destination is not None:
            why = graph.node_closed(stop.destination)
        else:
            closed = graph.station_type_closed(stop.station_type or "")
            why = None if closed is None else closed[0]
        if why is not None:
            return f"stop {number} ({stop.describe()}): {why}"
    return None


def stop_number(request_json: str | None, ahead: int) -> int:
    """The number (from 1, as the request counts its ``stops``) of the next of the ``ahead``
    stops still to come; without the request, as if the order had no more stops than those."""
    document = orjson.loads(request_json or "{}")
    asked = document.get("stops") if isinstance(document, dict) else None
    count = len(asked) if isinstance(asked, list) else 0
    return count - ahead + 1 if count else ahead + 1


def reran_actions(done: frozenset[str], state: State) -> tuple[str, ...]:
    """Of a stitching node's actions ``done`` (FINISHED before the update), those ``state``
    lists as not FINISHED or more than once: the vehicle ran them again, which it must not
    (R51; 3.0 §6.6.2: re-sent actions "will not be executed again")."""
    seen = [s.action_id for s in state.action_states if s.action_id in done]
    again = {
        s.action_id
        for s in state.action_states
        if s.action_id in done and s.action_status is not ActionStatus.FINISHED
    }
    twice = {a for a in seen if seen.count(a) > 1}
    return tuple(sorted(again | twice))
