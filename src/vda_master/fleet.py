"""The fleet view: what master control knows about every vehicle (§6.10, §6.14, §6.15).

``reduce_fleet(view, observation, now)`` folds one decoded vehicle message into an immutable view.
Per vehicle it keeps the connection state (from the retained ``connection`` topic), the latest
state, the latest valid factsheet, the protocol version the vehicle speaks and when it was last
heard from. Invalid messages never get here: the shell drops them at the edge.

The view is a small persistent map (64 buckets), so folding in one message copies one bucket and
a 64-slot tuple instead of the whole fleet: no O(fleet) work per message on the ingest hot path.

The connection topic is not a health signal (§6.14) and a broker may never deliver a last will
(mqtt-notes: amqtt does not enforce keep-alive), so a vehicle whose last state is older than a
multiple of its state interval counts as unreachable whatever its connection topic says.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Final

from vda5050.models import (
    ActionStatus,
    Connection,
    ConnectionState,
    ErrorLevel,
    Factsheet,
    OperatingMode,
    State,
)
from vda5050.topics import AgvId
from vda_master.capabilities import state_interval_s

_BUCKETS: Final = 64
_ENDED = frozenset({ActionStatus.FINISHED, ActionStatus.FAILED})
#: Modes in which master control may send orders and actions (§6.10.6 Table 1, R84).
CONTROLLABLE_MODES = frozenset({OperatingMode.AUTOMATIC, OperatingMode.SEMIAUTOMATIC})


@dataclass(frozen=True, slots=True)
class FactsheetProblem:
    """A factsheet arrived that could not be used; the valid one held before (if any) stays."""

    reason: str


Observed = State | Connection | Factsheet | FactsheetProblem


@dataclass(frozen=True, slots=True)
class Observation:
    """One valid message from vehicle ``agv`` (its topic's manufacturer and serial number)."""

    agv: AgvId
    message: Observed


@dataclass(frozen=True, slots=True)
class VehicleView:
    """What is known about one vehicle; times are monotonic seconds."""

    agv: AgvId
    first_seen: float
    last_seen: float
    version: str | None = None
    connection: ConnectionState | None = None
    state: State | None = None
    factsheet: Factsheet | None = None
    last_state_at: float | None = None
    #: Why the last factsheet received was not used (None once a valid one arrives).
    factsheet_problem: str | None = None
    #: 3.0 HIBERNATING (``connection`` then reads OFFLINE): connected, silent until
    #: stopHibernation, the only instant action it answers (3.0 §6.2.3.1, T06, T09).
    hibernating: bool = False
    #: A 3.0 robot's operatingMode in its own words (STARTUP, INTERVENED, TEACH_IN, ...; the
    #: state reads them in 2.x terms: SERVICE, MANUAL, TEACHIN); None for a 2.x vehicle.
    own_mode: str | None = None

    @property
    def intervened(self) -> bool:
        """3.0 INTERVENED (``operatingMode`` reads MANUAL): an operator steers, the robot keeps
        its order, and of the instant actions only cancelOrder may be sent (Table 11, T58)."""
        return self.own_mode == "INTERVENED"


@dataclass(frozen=True, slots=True)
class FleetSettings:
    """``unreachable_after_intervals``: how many state intervals of silence make a vehicle
    unreachable (its factsheet's defaultStateInterval, else 30 s, §6.10); ``charged_pct``: where
    master control ends a charge (None: energy management is off)."""

    unreachable_after_intervals: float = 3.0
    charged_pct: float | None = None


class FleetView:
    """An immutable map AgvId → VehicleView whose updates share most of their structure."""

    __slots__ = ("_buckets", "_size")

    def __init__(
        self, buckets: tuple[dict[AgvId, VehicleView], ...] | None = None, size: int = 0
    ) -> None:
        # Buckets are never mutated once a view holds them; updates copy the one they change.
        self._buckets = buckets if buckets is not None else tuple({} for _ in range(_BUCKETS))
        self._size = size

    def get(self, agv: AgvId) -> VehicleView | None:
        """The vehicle's view, or None if it was never heard from."""
        return self._buckets[hash(agv) % _BUCKETS].get(agv)

    def with_vehicle(self, vehicle: VehicleView) -> FleetView:
        """A new view with ``vehicle`` added or replaced; this one is left unchanged."""
        index = hash(vehicle.agv) % _BUCKETS
        bucket = dict(self._buckets[index])
        added = vehicle.agv not in bucket
        bucket[vehicle.agv] = vehicle
        buckets = (*self._buckets[:index], bucket, *self._buckets[index + 1 :])
        return FleetView(buckets, self._size + added)

    def without(self, agv: AgvId) -> FleetView:
        """A new view without ``agv`` (unchanged if it is not in the view)."""
        index = hash(agv) % _BUCKETS
        if agv not in self._buckets[index]:
            return self
        bucket = {key: value for key, value in self._buckets[index].items() if key != agv}
        buckets = (*self._buckets[:index], bucket, *self._buckets[index + 1 :])
        return FleetView(buckets, self._size - 1)

    def __len__(self) -> int:
        return self._size

    def __iter__(self) -> Iterator[VehicleView]:
        """Every vehicle, sorted by manufacturer and serial number."""
        vehicles = [v for bucket in self._buckets for v in bucket.values()]
        vehicles.sort(key=lambda v: (v.agv.manufacturer, v.agv.serial_number))
        return iter(vehicles)


def reduce_fleet(view: FleetView, observation: Observation, now: float) -> FleetView:
    """Fold one valid vehicle message into the view."""
    return view.with_vehicle(reduce_vehicle(view.get(observation.agv), observation, now))


def reduce_vehicle(
    vehicle: VehicleView | None, observation: Observation, now: float
) -> VehicleView:
    """Fold one valid message into one vehicle's view."""
    if vehicle is None:
        vehicle = VehicleView(agv=observation.agv, first_seen=now, last_seen=now)
    message = observation.message
    version = getattr(message, "version", None) or vehicle.version
    if isinstance(message, State):  # the hot path: built directly, cheaper than replace()
        return VehicleView(
            vehicle.agv, vehicle.first_seen, now, version, vehicle.connection, message,
            vehicle.factsheet, now, vehicle.factsheet_problem, vehicle.hibernating,
            vehicle.own_mode,
        )  # fmt: skip
    if isinstance(message, Connection):
        return replace(vehicle, connection=message.connection_state, last_seen=now, version=version)
    if isinstance(message, FactsheetProblem):
        return replace(vehicle, factsheet_problem=message.reason, last_seen=now)
    return replace(
        vehicle, factsheet=message, factsheet_problem=None, last_seen=now, version=version
    )


def is_idle(state: State) -> bool:
    """No node or edge left and every action ended (§6.6.2 Figure 8 step 3 "busy", negated)."""
    return (
        not state.node_states
        and not state.edge_states
        and all(a.action_status in _ENDED for a in state.action_states)
    )


def silence_s(vehicle: VehicleView, now: float) -> float:
    """Seconds since the last state (or, before any state, since first contact)."""
    since = vehicle.last_state_at if vehicle.last_state_at is not None else vehicle.first_seen
    return now - since


def is_unreachable(vehicle: VehicleView, now: float, settings: FleetSettings) -> bool:
    """The last state is older than the allowed multiple of the vehicle's state interval."""
    limit = settings.unreachable_after_intervals * state_interval_s(vehicle.factsheet)
    return silence_s(vehicle, now) > limit


def not_ready_reason(
    vehicle: VehicleView, now: float, settings: FleetSettings, *, cancel_order: bool = False
) -> str | None:
    """Why nothing may be sent to the vehicle now (R84, §6.14), or None; with ``cancel_order``,
    why no cancelOrder may (3.0 INTERVENED takes it, Table 11)."""
    if vehicle.hibernating:
        return "it is HIBERNATING (3.0): only stopHibernation is answered"
    if vehicle.connection != ConnectionState.ONLINE:
        state = vehicle.connection.value if vehicle.connection else "unknown"
        return f"its connection state is {state}"
    if vehicle.state is None:
        return "it has not published a state yet"
    mode = vehicle.state.operating_mode
    if mode not in CONTROLLABLE_MODES and not (cancel_order and vehicle.intervened):
        return f"its operatingMode is {vehicle.own_mode or mode.value}"
    if is_unreachable(vehicle, now, settings):
        return f"its last state is {silence_s(vehicle, now):.1f} s old (unreachable)"
    return None


def unavailable_reason(
    vehicle: VehicleView, now: float, settings: FleetSettings, *, automatic_only: bool = True
) -> str | None:
    """Why the vehicle cannot take a new order, or None when it is available.

    Available: ONLINE, AUTOMATIC (SEMIAUTOMATIC too when named explicitly, ``automatic_only``
    False), reachable, no FATAL error, idle, not charging.
    """
    reason = not_ready_reason(vehicle, now, settings)
    if reason is not None or vehicle.state is None:
        return reason
    state = vehicle.state
    if automatic_only and state.operating_mode != OperatingMode.AUTOMATIC:
        return f"its operatingMode is {state.operating_mode.value}, not AUTOMATIC"
    fatal = [e.error_type for e in state.errors if e.error_level == ErrorLevel.FATAL]
    if fatal:
        return f"it reports FATAL error {fatal[0]!r}"
    if not is_idle(state):
        return "it is busy with order " + repr(state.order_id)
    if state.battery_state.charging:
        return _charging(state, settings)
    return None


def _charging(state: State, settings: FleetSettings) -> str:
    """§6.8.2 stopCharging: charging stops before a new order; vehicles that take one anyway
    either drive off the charger or hold the order until charging ends (vda-5050-lib)."""
    if settings.charged_pct is None:
        return "it is charging: send the instant action stopCharging first (VDA 5050 §6.8.2)"
    return (
        f"it is charging (batteryCharge {state.battery_state.battery_charge:g} %): master "
        f"control sends stopCharging at charged_pct {settings.charged_pct:g} %, or send the "
        "instant action stopCharging yourself (VDA 5050 §6.8.2)"
    )


def forgettable(vehicle: VehicleView, now: float, forget_after_s: float) -> bool:
    """The vehicle left the live view's interest: nothing heard from it for ``forget_after_s``
    (OFFLINE, CONNECTIONBROKEN, or ONLINE but silent, like a serial number someone made up)."""
    return now - vehicle.last_seen >= forget_after_s
