"""``GET /metrics`` from the running service: the counters it keeps and a sample of the fleet,
rendered by :mod:`vda_master.metrics` (docs/master.md, *Metrics*). O(fleet) per scrape."""

from __future__ import annotations

from vda5050.models import ErrorLevel
from vda_master.alarms import is_stopped
from vda_master.metrics import (
    FleetSample,
    VehicleSample,
    counter_metrics,
    fleet_metrics,
    render,
)
from vda_master.service import MasterService

_CONFIRM_HELP = (
    "Time from sending an order message to the first state confirming it (its last send)."
)


def metrics_text(service: MasterService) -> str:
    """The Prometheus text exposition of master control now."""
    now = service.clock.monotonic()
    vehicles = []
    for vehicle in service.fleet:
        state = vehicle.state
        vehicles.append(
            VehicleSample(
                manufacturer=vehicle.agv.manufacturer,
                serial_number=vehicle.agv.serial_number,
                connection=vehicle.connection.value if vehicle.connection else "unknown",
                available=service.availability(vehicle, now) is None,
                in_service=vehicle.agv not in service.out_of_service,
                battery_pct=state.battery_state.battery_charge if state else None,
                charging=bool(state and state.battery_state.charging),
                driving=bool(state and state.driving),
                fatal_errors=sum(e.error_level == ErrorLevel.FATAL for e in state.errors)
                if state
                else 0,
                other_errors=sum(e.error_level != ErrorLevel.FATAL for e in state.errors)
                if state
                else 0,
                safety_stop=bool(state and is_stopped(state.safety_state)),
            )
        )
    traffic = service.coordinator.snapshot(now)
    sample = FleetSample(
        vehicles=vehicles,
        active_orders=len(service.active),
        waiting_vehicles=sum(1 for v in traffic.vehicles if v.waiting_for),
        deadlocks_resolved=traffic.deadlocks_resolved,
        confirm_timeout_s=service.confirmations.timeout_s,
        queued_orders=len(service.queue),
        webhook_queued=service.webhooks.queued(),
        webhook_delivered=service.webhooks.delivered,
        webhook_dropped=service.webhooks.dropped,
    )
    histograms = {
        "vda_master_order_confirm_seconds": (_CONFIRM_HELP, service.counters.confirm_latency)
    }
    return render([*fleet_metrics(sample), *counter_metrics(service.counters)], histograms)
