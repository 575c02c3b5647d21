"""What the map's live stream sends, built from the fleet view, poses and order tracks (pure).

Every function here takes values and returns JSON-ready dicts with camelCase keys; nothing reads
a clock or awaits (the stream passes ``now`` and ``wall_now`` in). The shapes are described for
people in ``docs/web.md``; the page reads them in ``static/js/store.js``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TypeAlias

from pydantic import BaseModel, JsonValue

from vda5050.clock import format_timestamp
from vda5050.graph_file import GraphEdge, GraphZone
from vda5050.models import Factsheet, State
from vda5050.topics import AgvId
from vda_master.alarms import Alarm, alarm_document, error_document
from vda_master.capabilities import state_interval_s
from vda_master.dispatcher import OrderTrack
from vda_master.fleet import FleetSettings, VehicleView, silence_s
from vda_master.graph import Graph
from vda_master.live import Pose
from vda_master.load_rules import load_sets
from vda_master.queue_rules import QueuedOrder
from vda_master.store.records import OutOfServiceRecord
from vda_master.wire3 import is_v3

Json: TypeAlias = dict[str, object]


def vehicle_key(agv: AgvId) -> str:
    """The page's id of a vehicle: ``<manufacturer>/<serialNumber>`` (``data-vehicle``)."""
    return f"{agv.manufacturer}/{agv.serial_number}"


def graph_payload(graph: Graph) -> Json:
    """Nodes with position and station, directed edges as (id, start, end), an edge with a
    trajectory as (id, start, end, [[x, y], ...]: the points between its nodes), the zones as
    polygons and the edges a BLOCKED zone closes (drawn apart)."""
    nodes = [
        {
            "id": node.node_id,
            "x": node.x,
            "y": node.y,
            "theta": node.theta,
            "stationType": node.station_type,
            "stationName": node.station_name,
            "description": node.description,
        }
        for node in graph.nodes.values()
    ]
    edges = [edge_payload(graph, e) for e in graph.edges.values()]
    payload: Json = {"mapId": graph.map_id, "nodes": nodes, "edges": edges}
    if graph.zones:
        from_file = graph.file_zone_ids
        payload["zones"] = [zone_payload(zone, from_file) for zone in graph.zones]
        payload["blockedEdges"] = [
            edge_payload(graph, e.edge) for e in graph.blocked_edges.values()
        ]
    return payload


def edge_payload(graph: Graph, edge: GraphEdge) -> list[JsonValue]:
    """``[id, start, end]``, and for a curved edge the points between its nodes, rounded to
    the millimetre."""
    entry: list[JsonValue] = [edge.edge_id, edge.start_node_id, edge.end_node_id]
    curved = graph.curved_paths.get(edge.edge_id)
    if curved is not None:
        entry.append([[round(x, 3), round(y, 3)] for x, y in curved[1:-1]])
    return entry


def zone_payload(zone: GraphZone, from_file: frozenset[str]) -> Json:
    """A zone as the map and ``GET /zones`` show it; ``from_file``: the ids of the graph file's
    zones (the others were added through the API: ``source``)."""
    return {
        "source": "graph file" if zone.zone_id in from_file else "api",
        "zoneId": zone.zone_id,
        "zoneType": zone.zone_type.value,
        "mapId": zone.map_id,
        "vertices": [[vertex.x, vertex.y] for vertex in zone.vertices],
        "maximumSpeed": zone.maximum_speed,
        "description": zone.description,
    }


def pose_payload(agv: AgvId, pose: Pose, received: float | None) -> Json:
    """A vehicle's new pose alone (a visualization message), with its receive time (ms)."""
    return {
        "id": vehicle_key(agv),
        "x": pose.x,
        "y": pose.y,
        "theta": pose.theta,
        "mapId": pose.map_id,
        "rx": _ms(received),
    }


def _ms(wall_s: float | None) -> float | None:
    return None if wall_s is None else round(wall_s * 1000.0, 1)


def current_pose(vehicle: VehicleView, pose: Pose | None) -> Pose | None:
    """The newer of the last visualization pose and the last state's agvPosition."""
    state_at = vehicle.last_state_at
    position = vehicle.state.agv_position if vehicle.state is not None else None
    if pose is not None and (position is None or state_at is None or pose.at >= state_at):
        return pose
    if position is None or state_at is None:
        return None
    return Pose(position.x, position.y, position.theta, position.map_id, state_at)


def vehicle_payload(
    vehicle: VehicleView,
    *,
    pose: Pose | None,
    received: float | None,
    active_order: OrderTrack | None,
    settings: FleetSettings,
    now: float,
    wall_now: float,
    out_of_service: OutOfServiceRecord | None = None,
    expected_finish: str | None = None,
    alarms: Sequence[Alarm] = (),
) -> Json:
    """Everything the map shows of one vehicle. ``now`` is monotonic, ``wall_now`` epoch s;
    ``out_of_service``: the operator's mark, when it is out of service; ``expected_finish``:
    its active order's ``expectedFinishAt``; ``alarms``: what is wrong with it now, worst
    first (``GET /alarms``'s entries).

    ``lastStateWall`` and ``unreachableAfterS`` let the page notice silence on its own: a vehicle
    that stops publishing sends no change (fleet.is_unreachable is the same rule).
    """
    agv = vehicle.agv
    where = current_pose(vehicle, pose)
    limit = settings.unreachable_after_intervals * state_interval_s(vehicle.factsheet)
    payload: Json = {
        "id": vehicle_key(agv),
        "manufacturer": agv.manufacturer,
        "serialNumber": agv.serial_number,
        "version": vehicle.version,
        "connection": vehicle.connection.value if vehicle.connection else None,
        "x": where.x if where else None,
        "y": where.y if where else None,
        "theta": where.theta if where else None,
        "mapId": where.map_id if where else None,
        "activeOrderId": active_order.order_id if active_order else None,
        "activeOrderStatus": active_order.status.value if active_order else None,
        "activeOrderExpectedFinishAt": expected_finish,
        "lastStateWall": round(wall_now - silence_s(vehicle, now), 3),
        "unreachableAfterS": limit,
        "rx": _ms(received),
    }
    payload["loadTypes"] = load_types_payload(vehicle.factsheet)
    payload["alarms"] = [alarm_document(a) for a in alarms]
    payload.update(service_payload(out_of_service))
    payload.update(state_fields(vehicle.state))
    if vehicle.own_mode is not None:  # a 3.0 robot's own word (STARTUP, INTERVENED, TEACH_IN)
        payload["reportedOperatingMode"] = vehicle.own_mode
    return payload


def loads_payload(state: State | None) -> list[JsonValue] | None:
    """The loads the state reports, as on the wire (§6.10.6); None when it does not report
    them (``GET /vehicles`` and the map both show them so)."""
    if state is None or state.loads is None:
        return None
    return [load.model_dump(mode="json", by_alias=True, exclude_none=True) for load in state.loads]


def service_payload(out_of_service: OutOfServiceRecord | None) -> dict[str, JsonValue]:
    """``inService``, ``outOfServiceSince`` and ``outOfServiceNote`` of a vehicle with this
    mark (None: in service), as ``GET /vehicles`` and the map both show them."""
    if out_of_service is None:
        return {"inService": True, "outOfServiceSince": None, "outOfServiceNote": None}
    return {
        "inService": False,
        "outOfServiceSince": format_timestamp(out_of_service.since),
        "outOfServiceNote": out_of_service.note,
    }


def load_types_payload(factsheet: Factsheet | None) -> list[JsonValue] | None:
    """The load types the factsheet's load sets take (``loadSpecification.loadSets``), in
    their order without repeats; None when it lists none (or there is no factsheet): then
    master control refuses the vehicle no load type (docs/master.md, *Loads*)."""
    sets = load_sets(factsheet)
    return list(dict.fromkeys(s.load_type for s in sets)) if sets else None


def maps_payload(state: State | None) -> list[JsonValue] | None:
    """The map versions the vehicle lists (``state.maps``, 2.1 and 3.0) with their status;
    None when it lists none."""
    if state is None or state.maps is None:
        return None
    return [
        {"mapId": m.map_id, "mapVersion": m.map_version, "mapStatus": m.map_status.value}
        for m in state.maps
    ]


def state_fields(state: State | None) -> Json:
    """The parts of a state the map draws or lists (§6.10.6)."""
    if state is None:
        return {"hasState": False}
    return {
        "hasState": True,
        "battery": state.battery_state.battery_charge,
        "charging": state.battery_state.charging,
        "loads": loads_payload(state),
        "maps": maps_payload(state),
        "driving": state.driving,
        "paused": bool(state.paused),
        "operatingMode": state.operating_mode.value,
        "eStop": state.safety_state.e_stop.value,
        "fieldViolation": state.safety_state.field_violation,
        "orderId": state.order_id,
        "orderUpdateId": state.order_update_id,
        "lastNodeId": state.last_node_id,
        "nodeStates": [
            {
                "nodeId": n.node_id,
                "sequenceId": n.sequence_id,
                "released": n.released,
                "x": n.node_position.x if n.node_position else None,
                "y": n.node_position.y if n.node_position else None,
            }
            for n in state.node_states
        ],
        "edgeStates": [
            {"edgeId": e.edge_id, "sequenceId": e.sequence_id, "released": e.released}
            for e in state.edge_states
        ],
        "actionStates": [
            {
                "actionId": a.action_id,
                "actionType": a.action_type,
                "actionStatus": a.action_status.value,
                "resultDescription": a.result_description,
            }
            for a in state.action_states
        ],
        "errors": _errors(state),
    }


def _errors(state: State) -> list[Json]:
    """Type, level and description of each error; a 3.0 robot's URGENT and CRITICAL as it
    sent them (the core reads them as WARNINGs: :mod:`vda_master.alarms`)."""
    v3 = is_v3(state.version)
    return [
        {key: document[key] for key in ("errorType", "errorLevel", "errorDescription")}
        for document in (error_document(e, v3=v3) for e in state.errors)
    ]


def order_payload(track: OrderTrack, *, active: bool, expected_finish: str | None = None) -> Json:
    """One order as the side panel lists it; ``active``: its vehicle's current order;
    ``expected_finish``: its ``expectedFinishAt``."""
    plan = track.plan
    return {
        "orderId": track.order_id,
        "active": active,
        "status": track.status.value,
        "vehicle": vehicle_key(plan.agv),
        "createdAt": track.created_utc,
        "reason": track.reason or None,
        "nodeIds": [n.node_id for n in plan.nodes],
        "releasedNodes": track.released_end + 1,
        "expectedFinishAt": expected_finish,
    }


def queued_order_payload(entry: QueuedOrder) -> Json:
    """An order waiting for a vehicle (or ended while waiting) as the side panel lists it:
    ``vehicle`` is null while any vehicle may take it."""
    agv = entry.request.agv
    return {
        "orderId": entry.order_id,
        "active": False,
        "status": entry.status.value,
        "vehicle": vehicle_key(agv) if agv is not None else None,
        "createdAt": entry.created_utc,
        "reason": entry.reason or None,
        "nodeIds": [],
        "releasedNodes": 0,
        "priority": entry.priority,
    }


def orders_payload(
    tracks: Iterable[OrderTrack],
    active: Mapping[AgvId, str],
    expected_finish: Callable[[OrderTrack], str | None] | None = None,
) -> list[Json]:
    """Orders, each marked whether it is its vehicle's active one, with ``expected_finish``
    (the ``expectedFinishAt`` of each, when given)."""
    return [
        order_payload(
            track,
            active=active.get(track.plan.agv) == track.order_id,
            expected_finish=expected_finish(track) if expected_finish else None,
        )
        for track in tracks
    ]


def traffic_payload(snapshot: Mapping[str, object] | BaseModel | None) -> object:
    """The traffic snapshot as JSON-ready data (a model is dumped by alias), None without one."""
    if isinstance(snapshot, BaseModel):
        return snapshot.model_dump(mode="json", by_alias=True)
    return None if snapshot is None else dict(snapshot)
