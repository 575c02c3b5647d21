"""Orders and vehicles as the JSON objects the HTTP API answers with (camelCase keys).

The list endpoints (``GET /orders``, ``GET /vehicles``) render these objects with orjson
directly: building a thousand ``OrderInfo`` or ``VehicleSummary`` models first cost about 20 µs
each, 30 ms of event loop per listing on a 2-core machine, during which no state, order or
request was handled (docs/performance.md). The single-object endpoints validate the same
object into its model (``OrderInfo.model_validate``), so the models stay the contract and the
OpenAPI schema; a test checks that every listed object is exactly what its model dumps.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import Enum
from typing import Final

import orjson
from pydantic import JsonValue

from vda5050.clock import format_timestamp
from vda5050.graph_file import GraphZoneType
from vda5050.models import v3
from vda_master.dispatcher import OrderStatus, OrderTrack
from vda_master.fleet import VehicleView, is_unreachable, silence_s
from vda_master.graph import Graph
from vda_master.queue_rules import QueuedOrder
from vda_master.service import MasterService
from vda_master.stops import stop_document
from vda_master.store import OrderRecord
from vda_master.web.payloads import (
    load_types_payload,
    loads_payload,
    maps_payload,
    service_payload,
    vehicle_key,
    zone_payload,
)
from vda_master.zone_answers import ZoneAnswers
from vda_master.zone_distribution import ZoneDistribution

Document = dict[str, JsonValue]


def any_order_document(
    service: MasterService, order: OrderTrack | QueuedOrder | OrderRecord
) -> Document:
    """An order in memory (sent, or waiting for a vehicle) or read from the store, as
    ``OrderInfo``."""
    if isinstance(order, OrderRecord):
        return stored_order_document(order)
    if isinstance(order, QueuedOrder):
        return queued_order_document(service, order)
    return order_document(service, order)


def queued_answer(service: MasterService, entry: QueuedOrder) -> Document:
    """``POST /orders``'s 202 for an order that waits for a vehicle, as ``OrderQueued``."""
    agv = entry.request.agv
    return {
        "orderId": entry.order_id,
        "status": entry.status.value,
        "manufacturer": agv.manufacturer if agv else None,
        "serialNumber": agv.serial_number if agv else None,
        "priority": entry.priority,
        "queuePosition": service.position(entry.order_id),
        "reason": entry.reason,
    }


def queued_order_document(service: MasterService, entry: QueuedOrder) -> Document:
    """An order waiting for a vehicle, or ended while waiting, as ``OrderInfo``: no vehicle
    has been sent anything, so it has no nodes yet."""
    agv = entry.request.agv
    return {
        "orderId": entry.order_id,
        "status": entry.status.value,
        "createdAt": entry.created_utc,
        "manufacturer": agv.manufacturer if agv else None,
        "serialNumber": agv.serial_number if agv else None,
        "reason": entry.reason or None,
        **_NOTHING_SENT,
        "priority": entry.priority,
        "queuePosition": service.position(entry.order_id),
        "stopsAhead": [stop_document(stop) for stop in entry.request.onward],
    }


#: The ``OrderInfo`` fields of an order no vehicle has been sent.
_NOTHING_SENT: Final[Document] = {
    "orderUpdateId": 0,
    "confirmedOrderUpdateId": None,
    "nodeIds": [],
    "edgeIds": [],
    "releasedNodeIds": [],
    "cancelActionId": None,
    "waitingFor": [],
    "waitingAt": None,
    "waitedS": None,
    "expectedFinishAt": None,
    "note": None,
}


def order_document(service: MasterService, track: OrderTrack) -> Document:
    """An order in memory, as ``OrderInfo``; with its vehicle's wait while it is active."""
    plan = track.plan
    wait = None
    if service.active.get(plan.agv) == track.order_id:
        wait = service.coordinator.wait_of(plan.agv, service.clock.monotonic())
    node_ids: list[JsonValue] = [n.node_id for n in plan.nodes]
    return {
        "orderId": track.order_id,
        "status": track.status.value,
        "createdAt": track.created_utc,
        "manufacturer": plan.agv.manufacturer,
        "serialNumber": plan.agv.serial_number,
        "reason": track.reason or None,
        "orderUpdateId": track.update_id,
        "confirmedOrderUpdateId": track.confirmed_update_id,
        "nodeIds": node_ids,
        "edgeIds": [e.edge_id for e in plan.edges],
        "releasedNodeIds": node_ids[: track.released_end + 1],
        "cancelActionId": track.cancel_action_id,
        "waitingFor": list(wait.waiting_for) if wait else [],
        "waitingAt": wait.node_id if wait else None,
        "waitedS": wait.waited_s if wait else None,
        "expectedFinishAt": service.expected_finish_utc(track),
        "note": track.note or None,
        "priority": _priority(orjson.loads(track.request_json))
        if '"queue"' in track.request_json  # parsed only for orders asked to queue
        else None,
        "queuePosition": None,
        "stopsAhead": [stop_document(stop) for stop in track.onward],
    }


def _priority(request: Mapping[str, JsonValue]) -> int | None:
    """``priority`` of an order that was asked for with ``queue: true`` (None otherwise)."""
    priority = request.get("priority") if request.get("queue") else None
    return priority if isinstance(priority, int) else None


def stored_order_document(record: OrderRecord) -> Document:
    """An order read from the store (it left memory, or ended in an earlier run)."""
    plan = record.plan
    nodes: list[JsonValue] = [str(n["nodeId"]) for n in _objects(plan.get("nodes"))]
    note = plan.get("note")
    return {
        "orderId": record.order_id,
        "status": OrderStatus(record.status).value,
        "createdAt": format_timestamp(record.created_at),
        # "": an order queued for any vehicle that ended before one took it
        "manufacturer": record.manufacturer or None,
        "serialNumber": record.serial_number or None,
        "reason": record.reason or None,
        "orderUpdateId": record.update_id,
        "confirmedOrderUpdateId": record.confirmed_update_id,
        "nodeIds": nodes,
        "edgeIds": [str(e["edgeId"]) for e in _objects(plan.get("edges"))],
        "releasedNodeIds": nodes[: record.released_end + 1],
        "cancelActionId": record.cancel_action_id,
        "waitingFor": [],
        "waitingAt": None,
        "waitedS": None,
        "expectedFinishAt": None,
        "note": note if isinstance(note, str) and note else None,
        "priority": _priority(record.request),
        "queuePosition": None,
        "stopsAhead": list(_objects(plan.get("onward"))),
    }


def vehicle_document(service: MasterService, vehicle: VehicleView) -> Document:
    """A vehicle as ``VehicleSummary``."""
    now = service.clock.monotonic()
    state = vehicle.state
    reason = service.availability(vehicle, now)
    return {
        "manufacturer": vehicle.agv.manufacturer,
        "serialNumber": vehicle.agv.serial_number,
        "version": vehicle.version,
        "connectionState": _value(vehicle.connection),
        "hibernating": vehicle.hibernating,
        "intervened": vehicle.intervened,
        "reportedOperatingMode": vehicle.own_mode
        or (_value(state.operating_mode) if state else None),
        "operatingMode": _value(state.operating_mode) if state else None,
        "orderId": state.order_id if state else None,
        "lastNodeId": state.last_node_id if state else None,
        "driving": state.driving if state else None,
        "batteryCharge": state.battery_state.battery_charge if state else None,
        "charging": state.battery_state.charging if state else None,
        "loads": loads_payload(state),
        "loadTypes": load_types_payload(vehicle.factsheet),
        "maps": maps_payload(state),
        "reachable": not is_unreachable(vehicle, now, service.fleet_settings),
        "lastStateAgeS": round(silence_s(vehicle, now), 3),
        "activeOrderId": service.active.get(vehicle.agv),
        **service_payload(service.out_of_service.get(vehicle.agv)),
        "available": reason is None,
        "unavailableReason": reason,
        "hasFactsheet": vehicle.factsheet is not None,
        "factsheetProblem": vehicle.factsheet_problem,
    }


def zones_document(
    graph: Graph, distribution: ZoneDistribution | None = None, answers: ZoneAnswers | None = None
) -> list[dict[str, object]]:
    """``GET /zones``: each zone of the graph file and what it does to the graph; with
    ``distribution``, the 3.0 zone set it is part of and how far each robot given zone sets
    has got with it (ENABLED, DISABLED, SENT, UNSUPPORTED); with ``answers``, a RELEASE zone's
    vehicle (``heldBy``) and the robots asking for it (``requests``: id -> requestStatus)."""
    documents: list[dict[str, object]] = []
    from_file = graph.file_zone_ids
    for zone in graph.zones:
        map_id = zone.map_id or graph.map_id
        document: dict[str, object] = {**zone_payload(zone, from_file), "mapId": map_id}
        if distribution is not None:
            zone_set_id = distribution.zone_sets[map_id].zone_set_id
            document["zoneSetId"] = zone_set_id
            zone_type = v3.ZoneType(zone.zone_type.value)
            document["robots"] = {
                f"{agv.manufacturer}/{agv.serial_number}": distribution.zone_set_status(
                    agv, zone_set_id, zone_type
                )
                for agv in distribution.zone_robots()
            }
        if zone.zone_type is GraphZoneType.RELEASE:
            loss = zone.release_loss_behavior
            document["releaseLossBehavior"] = "STOP" if loss is None else loss.value
            if answers is not None:
                holder = answers.release_zone_holder(zone.zone_id)
                document["heldBy"] = None if holder is None else vehicle_key(holder)
                document["requests"] = answers.release_zone_requests(zone.zone_id)
        elif zone.zone_type is GraphZoneType.BLOCKED:
            document["closedEdges"] = sorted(
                e for e, closed in graph.blocked_edges.items() if closed.zone_id == zone.zone_id
            )
            document["nodesInside"] = sorted(
                n for n, z in graph.blocked_nodes.items() if z == zone.zone_id
            )
        else:
            document["limitedEdges"] = sorted(
                e for e, z in graph.limited_edges.items() if z == zone.zone_id
            )
        documents.append(document)
    return documents


def _value(member: Enum | None) -> JsonValue:
    return None if member is None else member.value


def _objects(value: JsonValue) -> list[dict[str, JsonValue]]:
    return [v for v in value if isinstance(v, dict)] if isinstance(value, list) else []
