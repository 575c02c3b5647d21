"""Order tracks ⇄ store records (issue 10), pure.

A record holds what resuming an order needs: the request, the whole plan (nodes and edges with
their actions, the graph route, the vehicle's node limit, the traffic note and back-off resume),
the release and update counters, status and reason. Messages are cut from the plan again after
a restart (:func:`vda_master.order_builder.build_message`), so stitching holds across restarts.

:func:`track_events` turns a track change into entries of the order's history.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from datetime import datetime
from typing import Any

from vda5050.models import Action, Edge, Node
from vda5050.topics import AgvId
from vda_master.api_models import CreateOrder
from vda_master.dispatcher import OrderStatus, OrderTrack, Outgoing, Resume
from vda_master.order_builder import OrderPlan, build_message
from vda_master.queue_rules import QueuedOrder, deadline_of
from vda_master.routing import Route
from vda_master.stops import stop_document, stop_from_document
from vda_master.store import JsonObject, OrderEvent, OrderEventKind, OrderRecord


def to_record(
    track: OrderTrack, plan_document: JsonObject, *, created: datetime, updated: datetime
) -> OrderRecord:
    """The store record of ``track`` at ``updated``; ``plan_document`` is
    :func:`plan_document` of its plan (computed once per plan by the caller)."""
    plan = track.plan
    return OrderRecord(
        order_id=track.order_id,
        manufacturer=plan.agv.manufacturer,
        serial_number=plan.agv.serial_number,
        status=track.status.value,
        created_at=created,
        updated_at=updated,
        request=json.loads(track.request_json),
        plan={**plan_document, **_track_document(track)},
        released_end=track.released_end,
        update_id=track.update_id,
        sent_update_id=track.sent_update_id,
        confirmed_update_id=track.confirmed_update_id,
        cancel_action_id=track.cancel_action_id,
        reason=track.reason,
    )


def plan_document(plan: OrderPlan) -> JsonObject:
    """The plan as JSON: version, every node and edge with their actions, the graph route."""
    route = plan.route
    document: dict[str, Any] = {
        "version": plan.version,
        "nodes": [n.model_dump(mode="json", by_alias=True, exclude_none=True) for n in plan.nodes],
        "edges": [e.model_dump(mode="json", by_alias=True, exclude_none=True) for e in plan.edges],
    }
    if route is not None:
        document["route"] = {
            "nodeIds": list(route.node_ids),
            "edgeIds": list(route.edge_ids),
            "lengthM": route.length_m,
            "startPosition": list(route.start_position) if route.start_position else None,
        }
    result: JsonObject = document
    return result


def _track_document(track: OrderTrack) -> dict[str, Any]:
    """What the track adds to its plan: node limit, where the latest message starts (node 0,
    or the decision point of the latest update), creation time, traffic note, resume, the stops
    still to come, and why master control cancelled it itself."""
    document: dict[str, Any] = {
        "maxNodes": track.max_nodes,
        "messageFirst": track.message.nodes[0].sequence_id // 2 if track.message.nodes else 0,
        "note": track.note,
        "createdUtc": track.created_utc,
    }
    if track.cancel_reason:
        document["cancelReason"] = track.cancel_reason
    if track.onward:
        document["onward"] = [stop_document(stop) for stop in track.onward]
    if track.resume is not None:
        document["resume"] = {
            "nodeId": track.resume.node_id,
            "actions": [a.model_dump(mode="json", by_alias=True) for a in track.resume.actions],
        }
    return document


def track_events(old: OrderTrack | None, new: OrderTrack, time: datetime) -> list[OrderEvent]:
    """History entries for the change from ``old`` to ``new`` (None: the order was created).

    Publishing, nodes passed and traffic waits are recorded where they happen (the shell);
    this covers what a track change shows: creation, re-plans, confirmations, cancel requests
    and status changes.
    """
    plan = new.plan
    if old is None:
        created: JsonObject = {
            "manufacturer": plan.agv.manufacturer,
            "serialNumber": plan.agv.serial_number,
            "destination": plan.destination,
            "nodes": len(plan.nodes),
        }
        if new.note:
            created["note"] = new.note
        return [OrderEvent(new.order_id, time, OrderEventKind.CREATED, created)]
    events: list[OrderEvent] = []
    if old.plan is not plan:
        replanned: JsonObject = {"destination": plan.destination, "nodes": len(plan.nodes)}
        kind = OrderEventKind.REPLANNED
        if len(new.onward) < len(old.onward):
            kind, replanned["stopsAhead"] = OrderEventKind.STOP_APPENDED, len(new.onward)
        events.append(OrderEvent(new.order_id, time, kind, replanned))
    confirmed = new.confirmed_update_id
    if confirmed is not None and confirmed != old.confirmed_update_id:
        accepted: JsonObject = {"orderUpdateId": confirmed}
        events.append(OrderEvent(new.order_id, time, OrderEventKind.ACCEPTED, accepted))
    if new.cancel_action_id is not None and old.cancel_action_id is None:
        cancel: JsonObject = {"actionId": new.cancel_action_id}
        events.append(OrderEvent(new.order_id, time, OrderEventKind.CANCEL_REQUESTED, cancel))
    if new.status != old.status:
        changed: JsonObject = {"status": new.status.value, "previous": old.status.value}
        if new.reason:
            changed["reason"] = new.reason
        events.append(OrderEvent(new.order_id, time, OrderEventKind.STATUS_CHANGED, changed))
    return events


def from_record(record: OrderRecord, *, now: float) -> OrderTrack:
    """The track of a stored order, marked as recovering since ``now`` (monotonic).

    A message that was published is taken as sent once at ``now`` (resent if no state confirms
    it within the confirmation timeout); one built but never published goes out as new.
    """
    document: dict[str, Any] = dict(record.plan)
    plan = OrderPlan(
        record.order_id,
        AgvId(record.manufacturer, record.serial_number),
        str(document["version"]),
        tuple(Node.model_validate(n) for n in document["nodes"]),
        tuple(Edge.model_validate(e) for e in document["edges"]),
        _route(document.get("route")),
    )
    max_nodes = document.get("maxNodes")
    message = build_message(
        plan,
        first=int(document.get("messageFirst") or 0),
        release_end=record.released_end,
        update_id=record.update_id,
        max_nodes=max_nodes,
    )
    status = OrderStatus(record.status)
    pending = None
    if record.confirmed_update_id is None or record.confirmed_update_id < record.update_id:
        sent = record.sent_update_id == record.update_id
        pending = Outgoing(message, sends=1, last_sent=now) if sent else Outgoing(message)
    return OrderTrack(
        plan=plan,
        status=status,
        released_end=record.released_end,
        update_id=record.update_id,
        max_nodes=max_nodes,
        message=message,
        pending=None if status.value in _ENDED else pending,
        created_at=now,
        confirmed_update_id=record.confirmed_update_id,
        created_utc=str(document.get("createdUtc") or ""),
        note=str(document.get("note") or ""),
        resume=_resume(document.get("resume")),
        onward=tuple(stop_from_document(d) for d in document.get("onward") or ()),
        sent_update_id=record.sent_update_id,
        request_json=json.dumps(record.request),
        cancel_action_id=record.cancel_action_id,
        reason=record.reason,
        cancel_reason=str(document.get("cancelReason") or ""),
        recovering_since=now,
    )


_ENDED = frozenset({"FINISHED", "FAILED", "REJECTED", "CANCELLED"})


def _route(document: Any) -> Route | None:  # noqa: ANN401 - JSON from the store
    if not isinstance(document, dict):
        return None
    start = document.get("startPosition")
    return Route(
        tuple(document["nodeIds"]),
        tuple(document["edgeIds"]),
        float(document["lengthM"]),
        (float(start[0]), float(start[1])) if start else None,
    )


def _resume(document: Any) -> Resume | None:  # noqa: ANN401 - JSON from the store
    if not isinstance(document, dict):
        return None
    actions = tuple(Action.model_validate(a) for a in document.get("actions", ()))
    return Resume(str(document["nodeId"]), actions)


def last_passed(events: Sequence[OrderEvent]) -> int:
    """The index of the last node an order's history shows passed (-1: none)."""
    indices = [
        sequence_id // 2
        for e in events
        if e.event == OrderEventKind.NODE_PASSED
        and isinstance(sequence_id := e.details.get("sequenceId"), int)
    ]
    return max(indices, default=-1)


def queued_record(entry: QueuedOrder, *, created: datetime, updated: datetime) -> OrderRecord:
    """The store record of an order that waits for a vehicle, or ended while waiting: no
    vehicle (``""`` unless it names one) and no plan yet; the request keeps ``queue`` and
    ``priority``, from which :func:`queued_from_record` restores it."""
    agv = entry.request.agv
    return OrderRecord(
        order_id=entry.order_id,
        manufacturer=agv.manufacturer if agv is not None else "",
        serial_number=agv.serial_number if agv is not None else "",
        status=entry.status.value,
        created_at=created,
        updated_at=updated,
        request=json.loads(entry.request.as_json()),
        plan={"createdUtc": entry.created_utc},
        released_end=-1,
        update_id=0,
        reason=entry.reason,
    )


def queued_from_record(record: OrderRecord, seq: int, time_lapse: float) -> QueuedOrder:
    """A stored QUEUED order back in the queue at place ``seq``; its deadline counts from its
    creation, the time master control was down included.

    Raises:
        pydantic.ValidationError: the stored request is not one ``POST /orders`` takes.
    """
    body = CreateOrder.model_validate(record.request)
    request = body.to_request()
    created = record.plan.get("createdUtc")
    return QueuedOrder(
        order_id=record.order_id,
        request=request,
        priority=request.priority,
        seq=seq,
        created_utc=created if isinstance(created, str) else "",
        reason=record.reason,
        deadline=deadline_of(record.created_at, request.queue_timeout_s, time_lapse),
    )
