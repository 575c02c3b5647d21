"""Live progress lines for the terminal, rendered from the master's API answers (pure)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from pydantic import JsonValue

JsonObject = Mapping[str, JsonValue]


def _number(value: JsonValue, fmt: str = ".1f") -> str:
    return format(value, fmt) if isinstance(value, int | float) else "?"


def vehicle_line(vehicle: JsonObject, order: JsonObject | None, mission: str) -> str:
    """One robot: where it is, what its order does, its battery."""
    state = vehicle.get("state")
    state = state if isinstance(state, dict) else {}
    position = state.get("agvPosition")
    position = position if isinstance(position, dict) else {}
    battery = state.get("batteryState")
    battery = battery if isinstance(battery, dict) else {}
    where = (
        f"node {vehicle.get('lastNodeId') or '-':>3} ({_number(position.get('x'))}, "
        f"{_number(position.get('y'))})"
    )
    status = order.get("status") if order else "idle"
    motion = "driving" if vehicle.get("driving") else "standing"
    charging = " charging" if battery.get("charging") else ""
    return (
        f"{vehicle.get('serialNumber')!s:<9} {where:<24} {status!s:<9} {motion:<8} "
        f"battery {_number(battery.get('batteryCharge'))}%{charging}  {mission}"
        f"{expected_text(order)}{wait_text(order)}{service_text(vehicle)}"
    )


def expected_text(order: JsonObject | None) -> str:
    """``  done by 14:03:45 UTC`` while master control expects the order to finish then (its
    ``expectedFinishAt``)."""
    at = order.get("expectedFinishAt") if order else None
    if not isinstance(at, str) or "T" not in at:
        return ""
    return f"  done by {at.split('T', 1)[1][:8]} UTC"


def service_text(vehicle: JsonObject) -> str:
    """``  out of service: brake check`` while an operator has the robot out of service (it
    gets no order until it is put back: ``PATCH /vehicles/...``)."""
    if vehicle.get("inService") is not False:
        return ""
    note = vehicle.get("outOfServiceNote")
    return f"  out of service{f': {note}' if note else ''}"


def wait_text(order: JsonObject | None) -> str:
    """``  waits for robot_0 at node A3 (2.1 s)`` while traffic control holds the robot."""
    waiting = order.get("waitingFor") if order else None
    if not order or not isinstance(waiting, list) or not waiting:
        return ""
    names = ", ".join(str(w).rsplit("/", 1)[-1] for w in waiting)
    where = f" at node {order['waitingAt']}" if order.get("waitingAt") else ""
    return f"  waits for {names}{where} ({_number(order.get('waitedS'))} s)"


def summary_lines(
    finished: Sequence[tuple[str, str, float]], expected: Mapping[str, float] | None = None
) -> list[str]:
    """The closing summary: one line per finished order (robot, order id, seconds), with the
    seconds master control expected when the order was first seen under way."""
    expected = expected or {}
    return [
        f"  {robot:<9} order {order_id} finished after {seconds:.1f} s"
        + (f" (expected {expected[order_id]:.1f} s)" if order_id in expected else "")
        for robot, order_id, seconds in finished
    ]
