"""``GET /metrics``: master control's figures in the Prometheus text format (version 0.0.4), for
a plant's monitoring (Prometheus, Grafana, any scraper of that format). docs/master.md,
*Metrics*.

:class:`Counters` are counted by the service as things happen (messages in and dropped, orders
created and ended, messages published and resent, confirmation latencies); everything else is
read from the fleet view, the order tracks and traffic control at the moment of the scrape.
:func:`render` is pure: samples in, text out.
"""

from __future__ import annotations

import bisect
import math
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final

from vda5050.topics import Topic

#: Upper bounds (s) of the order-confirmation histogram's buckets: a state confirming an order
#: message, counted from the (last) send (:mod:`vda_master.confirmation`).
CONFIRM_BUCKETS_S: Final = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0)
CONTENT_TYPE: Final = "text/plain; version=0.0.4; charset=utf-8"

Labels = tuple[tuple[str, str], ...]


@dataclass
class Histogram:
    """Cumulative counts per upper bound, their sum and count (Prometheus histogram)."""

    bounds: tuple[float, ...]
    counts: list[int] = field(default_factory=list)
    total: float = 0.0
    count: int = 0

    def __post_init__(self) -> None:
        self.counts = [0] * len(self.bounds)

    def observe(self, value: float) -> None:
        index = bisect.bisect_left(self.bounds, value)
        if index < len(self.counts):
            self.counts[index] += 1
        self.total += value
        self.count += 1

    def cumulative(self) -> list[int]:
        running, out = 0, []
        for count in self.counts:
            running += count
            out.append(running)
        return out


@dataclass
class Counters:
    """What the service counts as it happens (monotonic since the process started)."""

    #: (topic, major version) → messages received from vehicles on it
    received: Counter[tuple[Topic, int]] = field(default_factory=Counter)
    #: topic → messages dropped as malformed or invalid (each also a ``message.dropped`` line)
    dropped: Counter[Topic] = field(default_factory=Counter)
    #: origin (api, traffic, charging) → orders created
    orders_created: Counter[str] = field(default_factory=Counter)
    #: final status → orders ended (those that ended while queued too)
    orders_ended: Counter[str] = field(default_factory=Counter)
    #: orders that had to wait for a vehicle (``queue: true``)
    orders_queued: int = 0
    #: topic → messages published to vehicles, and of them resent (unconfirmed in time)
    published: Counter[str] = field(default_factory=Counter)
    resent: Counter[str] = field(default_factory=Counter)
    confirm_latency: Histogram = field(default_factory=lambda: Histogram(CONFIRM_BUCKETS_S))


@dataclass(frozen=True, slots=True)
class Metric:
    """One metric family: its samples as (labels, value)."""

    name: str
    kind: str  # "gauge" | "counter"
    help: str
    samples: Sequence[tuple[Labels, float]]


def order_origin(note: str) -> str:
    """Who created an order, from its ``note``: ``api`` (asked for), ``traffic`` or
    ``charging`` (master control's own)."""
    origin = note.split(":", 1)[0] if note else "api"
    return origin if origin in {"traffic", "charging"} else "api"


def counter_metrics(counters: Counters) -> list[Metric]:
    """The counted families (``_total`` names, as Prometheus counters are named)."""
    return [
        Metric(
            "vda_master_messages_received_total",
            "counter",
            "Messages received from vehicles, by topic and VDA 5050 major version.",
            sorted(
                ((("topic", t.value), ("major", str(m))), n)
                for (t, m), n in counters.received.items()
            ),
        ),
        Metric(
            "vda_master_messages_dropped_total",
            "counter",
            "Vehicle messages dropped as malformed or invalid (each is logged), by topic.",
            _by("topic", {t.value: n for t, n in counters.dropped.items()}),
        ),
        Metric(
            "vda_master_orders_created_total",
            "counter",
            "Orders created: asked for through the API, or master control's own (traffic "
            "control's moves out of the way, energy management's charging orders).",
            _by("origin", counters.orders_created),
        ),
        Metric(
            "vda_master_orders_ended_total",
            "counter",
            "Orders that reached a final status, by that status (queued ones that ended "
            "before a vehicle took them too).",
            _by("status", counters.orders_ended),
        ),
        Metric(
            "vda_master_orders_queued_total",
            "counter",
            "Orders asked for with queue: true that had to wait for a vehicle; each is counted "
            "as created once a vehicle takes it.",
            [((), counters.orders_queued)],
        ),
        Metric(
            "vda_master_messages_published_total",
            "counter",
            "Order and instantActions messages published to vehicles, by topic.",
            _by("topic", counters.published),
        ),
        Metric(
            "vda_master_messages_resent_total",
            "counter",
            "Of those, messages sent again because no state confirmed them in time.",
            _by("topic", counters.resent),
        ),
    ]


def _by(label: str, counts: Mapping[str, int]) -> list[tuple[Labels, float]]:
    return [(((label, key),), value) for key, value in sorted(counts.items())]


def render(metrics: Iterable[Metric], histograms: Mapping[str, tuple[str, Histogram]]) -> str:
    """The Prometheus text exposition (0.0.4) of ``metrics`` and ``histograms`` (name → (help,
    histogram))."""
    lines: list[str] = []
    for metric in metrics:
        lines.append(f"# HELP {metric.name} {_help(metric.help)}")
        lines.append(f"# TYPE {metric.name} {metric.kind}")
        lines.extend(
            f"{metric.name}{_labels(labels)} {_number(value)}" for labels, value in metric.samples
        )
    for name, (text, histogram) in histograms.items():
        lines.append(f"# HELP {name} {_help(text)}")
        lines.append(f"# TYPE {name} histogram")
        for bound, count in zip(histogram.bounds, histogram.cumulative(), strict=True):
            lines.append(f'{name}_bucket{{le="{_number(bound)}"}} {count}')
        lines.append(f'{name}_bucket{{le="+Inf"}} {histogram.count}')
        lines.append(f"{name}_sum {_number(histogram.total)}")
        lines.append(f"{name}_count {histogram.count}")
    return "\n".join(lines) + "\n"


def _labels(labels: Labels) -> str:
    if not labels:
        return ""
    inner = ",".join(f'{key}="{_escape(value)}"' for key, value in labels)
    return "{" + inner + "}"


def _escape(value: str) -> str:
    """Label values: backslash, double quote and line feed escaped (the format's rules)."""
    return value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


def _help(text: str) -> str:
    return text.replace("\\", "\\\\").replace("\n", "\\n")


def _number(value: float) -> str:
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "+Inf" if value > 0 else "-Inf"
    if float(value).is_integer():
        return str(int(value))
    return repr(float(value))


@dataclass(frozen=True, slots=True)
class VehicleSample:
    """What the scrape shows of one vehicle."""

    manufacturer: str
    serial_number: str
    connection: str
    available: bool
    battery_pct: float | None
    charging: bool
    driving: bool
    fatal_errors: int
    #: False while an operator has it out of service.
    in_service: bool = True
    #: Its errors of other levels (WARNING; a 3.0 robot's URGENT and CRITICAL too).
    other_errors: int = 0
    #: True while an emergency stop is active or a protective field is violated.
    safety_stop: bool = False


@dataclass(frozen=True, slots=True)
class FleetSample:
    """The fleet and master control's state at the moment of the scrape."""

    vehicles: Sequence[VehicleSample]
    active_orders: int
    waiting_vehicles: int
    deadlocks_resolved: int
    confirm_timeout_s: float
    #: Orders asked for with ``queue: true`` that wait for a vehicle.
    queued_orders: int = 0
    #: Webhook events waiting for delivery, delivered and dropped (``webhook_urls``).
    webhook_queued: int = 0
    webhook_delivered: int = 0
    webhook_dropped: int = 0


def fleet_metrics(sample: FleetSample) -> list[Metric]:
    """Gauges of the fleet (one sample per vehicle where it says which) and of traffic."""
    connections = Counter(v.connection for v in sample.vehicles)

    def each(value: object) -> list[tuple[Labels, float]]:
        return [
            ((("manufacturer", v.manufacturer), ("serial_number", v.serial_number)), float(x))
            for v in sample.vehicles
            if (x := getattr(v, str(value))) is not None
        ]

    return [
        Metric(
            "vda_master_vehicles",
            "gauge",
            "Vehicles master control knows, by connection state (unknown: none reported yet).",
            _by("connection", connections),
        ),
        Metric(
            "vda_master_vehicles_available",
            "gauge",
            "Vehicles that can take an order now (GET /vehicles available).",
            [((), sum(v.available for v in sample.vehicles))],
        ),
        Metric(
            "vda_master_vehicles_out_of_service",
            "gauge",
            "Vehicles an operator took out of service (PATCH /vehicles/...).",
            [((), sum(not v.in_service for v in sample.vehicles))],
        ),
        Metric(
            "vda_master_vehicle_available",
            "gauge",
            "1 while the vehicle can take an order now.",
            each("available"),
        ),
        Metric(
            "vda_master_vehicle_battery_percent",
            "gauge",
            "The vehicle's batteryState.batteryCharge.",
            each("battery_pct"),
        ),
        Metric("vda_master_vehicle_charging", "gauge", "1 while it charges.", each("charging")),
        Metric("vda_master_vehicle_driving", "gauge", "1 while it drives.", each("driving")),
        Metric(
            "vda_master_vehicle_fatal_errors",
            "gauge",
            "FATAL errors in the vehicle's last state.",
            each("fatal_errors"),
        ),
        Metric(
            "vda_master_vehicle_other_errors",
            "gauge",
            "Errors of other levels in the vehicle's last state (WARNING; 3.0 URGENT, CRITICAL).",
            each("other_errors"),
        ),
        Metric(
            "vda_master_vehicle_safety_stop",
            "gauge",
            "1 while the vehicle reports an active emergency stop or a protective field violation.",
            each("safety_stop"),
        ),
        Metric(
            "vda_master_orders_active",
            "gauge",
            "Orders sent to a vehicle and not ended yet.",
            [((), sample.active_orders)],
        ),
        Metric(
            "vda_master_orders_queued",
            "gauge",
            "Orders waiting for a vehicle (asked for with queue: true).",
            [((), sample.queued_orders)],
        ),
        Metric(
            "vda_master_traffic_waiting_vehicles",
            "gauge",
            "Vehicles traffic control holds at the end of their released base.",
            [((), sample.waiting_vehicles)],
        ),
        Metric(
            "vda_master_traffic_deadlocks_resolved_total",
            "counter",
            "Deadlocks traffic control resolved (GET /traffic deadlocksResolved).",
            [((), sample.deadlocks_resolved)],
        ),
        Metric(
            "vda_master_webhook_events_queued",
            "gauge",
            "Webhook events waiting for delivery, over all receivers.",
            [((), sample.webhook_queued)],
        ),
        Metric(
            "vda_master_webhook_events_delivered_total",
            "counter",
            "Webhook events a receiver answered with 2xx.",
            [((), sample.webhook_delivered)],
        ),
        Metric(
            "vda_master_webhook_events_dropped_total",
            "counter",
            "Webhook events given up: refused, out of attempts, or over the queue's limit.",
            [((), sample.webhook_dropped)],
        ),
        Metric(
            "vda_master_order_confirm_timeout_seconds",
            "gauge",
            "The confirmation timeout in force: confirm_timeout_s, longer under load.",
            [((), sample.confirm_timeout_s)],
        ),
    ]
