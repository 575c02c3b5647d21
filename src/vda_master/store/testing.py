"""Record factories for tests of the store and of master control's use of it."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from vda_master.store.records import JsonObject, OrderEvent, OrderRecord, VehicleRecord

#: A fixed instant the factories start from.
T0 = datetime(2026, 1, 1, 12, 0, tzinfo=UTC)


def at(seconds: float) -> datetime:
    """``T0`` plus ``seconds``."""
    return T0 + timedelta(seconds=seconds)


def sample_plan(order_id: str, nodes: int = 3) -> JsonObject:
    """A plan as master control stores it: version, nodes and edges with an action."""
    return {
        "orderId": order_id,
        "version": "2.0.0",
        "nodes": [
            {"nodeId": f"n{i}", "sequenceId": 2 * i, "released": False, "actions": []}
            for i in range(nodes)
        ],
        "edges": [
            {
                "edgeId": f"e{i}",
                "sequenceId": 2 * i + 1,
                "released": False,
                "startNodeId": f"n{i}",
                "endNodeId": f"n{i + 1}",
                "actions": [{"actionType": "pick", "actionId": f"a{i}", "blockingType": "HARD"}],
            }
            for i in range(nodes - 1)
        ],
    }


def make_order_record(
    order_id: str = "order-1",
    *,
    manufacturer: str = "acme",
    serial_number: str = "robot_0",
    status: str = "SENT",
    created_at: datetime = T0,
    updated_at: datetime | None = None,
    **fields: object,
) -> OrderRecord:
    """An order record with a small plan; ``fields`` override the rest."""
    values: dict[str, object] = {
        "request": {"destination": "n2", "manufacturer": manufacturer},
        "plan": sample_plan(order_id),
        "released_end": 1,
        "update_id": 0,
        **fields,
    }
    return OrderRecord(
        order_id=order_id,
        manufacturer=manufacturer,
        serial_number=serial_number,
        status=status,
        created_at=created_at,
        updated_at=updated_at or created_at,
        **values,  # type: ignore[arg-type]
    )


def make_event(
    order_id: str = "order-1",
    event: str = "created",
    time: datetime = T0,
    **details: object,
) -> OrderEvent:
    """An order event; ``details`` become its JSON details."""
    return OrderEvent(order_id, time, event, dict(details))  # type: ignore[arg-type]


def make_vehicle_record(
    serial_number: str = "robot_0",
    *,
    manufacturer: str = "acme",
    first_seen: datetime = T0,
    last_seen: datetime | None = None,
    **fields: object,
) -> VehicleRecord:
    """A vehicle record, ONLINE and speaking 2.0.0 unless ``fields`` say otherwise."""
    values: dict[str, object] = {"version": "2.0.0", "connection_state": "ONLINE", **fields}
    return VehicleRecord(
        manufacturer=manufacturer,
        serial_number=serial_number,
        first_seen=first_seen,
        last_seen=last_seen or first_seen,
        **values,  # type: ignore[arg-type]
    )
