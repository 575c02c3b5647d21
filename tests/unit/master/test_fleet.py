"""The fleet view reducer and vehicle availability (§6.10, §6.14, §6.15; R84)."""

from __future__ import annotations

from vda5050.models import (
    ActionState,
    ActionStatus,
    BatteryState,
    Connection,
    ConnectionState,
    Error,
    ErrorLevel,
    NodeState,
    OperatingMode,
)
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId
from vda_master.fleet import (
    FleetSettings,
    FleetView,
    Observation,
    is_unreachable,
    not_ready_reason,
    reduce_fleet,
    unavailable_reason,
)
from vda_master.testing import make_factsheet

AGV = AgvId("acme", "robot_0")
SETTINGS = FleetSettings(unreachable_after_intervals=3.0)


def _connection(state: ConnectionState, version: str = "2.1.0") -> Connection:
    return Connection.model_validate({**HEADER, "version": version, "connection_state": state})


def _online(now: float = 0.0, **state: object) -> FleetView:
    view = reduce_fleet(FleetView(), Observation(AGV, _connection(ConnectionState.ONLINE)), now)
    return reduce_fleet(view, Observation(AGV, make_state(**state)), now)


def test_reduce_keeps_connection_state_and_factsheet() -> None:
    """Connection, state and factsheet messages each fill their part of the vehicle view."""
    view = _online()
    view = reduce_fleet(view, Observation(AGV, make_factsheet()), 1.0)
    vehicle = view.get(AGV)
    assert vehicle is not None
    assert vehicle.connection == ConnectionState.ONLINE
    assert vehicle.state is not None
    assert vehicle.factsheet is not None
    assert vehicle.last_seen == 1.0


def test_reduce_leaves_the_old_view_untouched() -> None:
    """Reducing returns a new view; the previous one still holds the previous data."""
    before = _online()
    after = reduce_fleet(before, Observation(AGV, _connection(ConnectionState.OFFLINE)), 1.0)
    old, new = before.get(AGV), after.get(AGV)
    assert old is not None
    assert new is not None
    assert (old.connection, new.connection) == (ConnectionState.ONLINE, ConnectionState.OFFLINE)


def test_view_holds_many_vehicles_sorted() -> None:
    """The view iterates every vehicle once, sorted by manufacturer and serial number."""
    view = FleetView()
    for serial in ("r3", "r1", "r2", "r1"):
        view = reduce_fleet(view, Observation(AgvId("acme", serial), make_state()), 0.0)
    assert len(view) == 3
    assert [v.agv.serial_number for v in view] == ["r1", "r2", "r3"]


def test_version_follows_the_vehicles_messages() -> None:
    """The vehicle is addressed in the version of its own messages (2.0.0 here)."""
    view = reduce_fleet(
        FleetView(), Observation(AGV, _connection(ConnectionState.ONLINE, "2.0.0")), 0
    )
    vehicle = view.get(AGV)
    assert vehicle is not None
    assert vehicle.version == "2.0.0"


def test_idle_automatic_online_vehicle_is_available() -> None:
    """ONLINE, AUTOMATIC, no FATAL error and idle means available."""
    vehicle = _online().get(AGV)
    assert vehicle is not None
    assert unavailable_reason(vehicle, 1.0, SETTINGS) is None


def test_connection_broken_is_unavailable() -> None:
    """CONNECTIONBROKEN (the last will) makes the vehicle unavailable, its state is kept."""
    view = _online()
    view = reduce_fleet(view, Observation(AGV, _connection(ConnectionState.CONNECTIONBROKEN)), 1)
    vehicle = view.get(AGV)
    assert vehicle is not None
    assert vehicle.state is not None
    assert unavailable_reason(vehicle, 1.0, SETTINGS) == "its connection state is CONNECTIONBROKEN"


def test_manual_mode_is_not_ready() -> None:
    """Nothing is sent to a vehicle in MANUAL (R84)."""
    vehicle = _online(operating_mode=OperatingMode.MANUAL).get(AGV)
    assert vehicle is not None
    assert not_ready_reason(vehicle, 0.0, SETTINGS) == "its operatingMode is MANUAL"


def test_semiautomatic_is_ready_but_not_auto_selected() -> None:
    """SEMIAUTOMATIC may receive orders but is not picked automatically."""
    vehicle = _online(operating_mode=OperatingMode.SEMIAUTOMATIC).get(AGV)
    assert vehicle is not None
    assert not_ready_reason(vehicle, 0.0, SETTINGS) is None
    assert unavailable_reason(vehicle, 0.0, SETTINGS) is not None
    assert unavailable_reason(vehicle, 0.0, SETTINGS, automatic_only=False) is None


def test_fatal_error_is_unavailable() -> None:
    """A FATAL error makes the vehicle unavailable."""
    fatal = Error(error_type="laserDirty", error_level=ErrorLevel.FATAL)
    vehicle = _online(errors=[fatal]).get(AGV)
    assert vehicle is not None
    assert unavailable_reason(vehicle, 0.0, SETTINGS) == "it reports FATAL error 'laserDirty'"


def test_busy_vehicle_is_unavailable() -> None:
    """A vehicle with nodeStates or running actions is busy (Figure 8 step 3)."""
    node = NodeState(node_id="n1", sequence_id=2, released=True)
    running = ActionState(action_id="a", action_status=ActionStatus.RUNNING)
    for fields in ({"node_states": [node]}, {"action_states": [running]}):
        vehicle = _online(order_id="o1", **fields).get(AGV)
        assert vehicle is not None
        assert unavailable_reason(vehicle, 0.0, SETTINGS) == "it is busy with order 'o1'"


def test_charging_vehicle_is_unavailable_until_it_stops_charging() -> None:
    """R77 [§6.8.2]: a vehicle reporting charging is not ready for orders (stopCharging first);
    the reason says what to do."""
    charging = _online(battery_state=BatteryState(battery_charge=40.0, charging=True)).get(AGV)
    assert charging is not None
    assert unavailable_reason(charging, 0.0, SETTINGS) == (
        "it is charging: send the instant action stopCharging first (VDA 5050 §6.8.2)"
    )
    stopped = _online(battery_state=BatteryState(battery_charge=40.0, charging=False)).get(AGV)
    assert stopped is not None
    assert unavailable_reason(stopped, 0.0, SETTINGS) is None


def test_silent_vehicle_becomes_unreachable() -> None:
    """A vehicle whose last state is older than 3 × 30 s is unreachable despite ONLINE."""
    vehicle = _online().get(AGV)
    assert vehicle is not None
    assert not is_unreachable(vehicle, 90.0, SETTINGS)
    assert is_unreachable(vehicle, 90.5, SETTINGS)
    assert "unreachable" in (unavailable_reason(vehicle, 91.0, SETTINGS) or "")


def test_state_interval_comes_from_the_factsheet() -> None:
    """A factsheet defaultStateInterval of 2 s makes 6 s of silence unreachable."""
    view = reduce_fleet(_online(), Observation(AGV, make_factsheet(default_state_interval=2.0)), 0)
    vehicle = view.get(AGV)
    assert vehicle is not None
    assert is_unreachable(vehicle, 6.5, SETTINGS)


def test_vehicle_without_state_is_not_ready() -> None:
    """A vehicle that only announced ONLINE has no state to plan from."""
    view = reduce_fleet(FleetView(), Observation(AGV, _connection(ConnectionState.ONLINE)), 0)
    vehicle = view.get(AGV)
    assert vehicle is not None
    assert not_ready_reason(vehicle, 0.0, SETTINGS) == "it has not published a state yet"
