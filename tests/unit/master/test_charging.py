"""Energy management (docs/master.md, *Charging*; VDA 5050 2.1 §4 "charging orders", §6.8.2
startCharging/stopCharging, §6.10.6 batteryState): the rules, and the service shell driven
by a recording publisher and a fake clock."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import ValidationError
from structlog.testing import capture_logs

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import ActionStatus, BatteryState, Connection, ConnectionState
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.capabilities import ActionSpec
from vda_master.charge_rules import (
    ChargeAttempt,
    ChargeSettings,
    charge_done,
    charging_queue,
    free_chargers,
    reach_problem,
    retry_blocked,
    spots_for,
    vacating,
    wants_charge,
)
from vda_master.config import MasterConfig
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.testing import (
    LOAD_ACTIONS,
    RecordingPublisher,
    demo_graph,
    make_factsheet,
    plan_state,
)

AGV = AgvId("acme", "robot_0")
CHARGER_ACTIONS: tuple[dict[str, Any], ...] = (
    *LOAD_ACTIONS,
    {"actionType": "stopCharging", "actionScopes": ["INSTANT", "NODE"]},
)
SETTINGS = ChargeSettings(below_pct=30.0, until_pct=80.0)


def _battery(charge: float, *, charging: bool = False, reach: float | None = None) -> Any:
    return BatteryState(battery_charge=charge, charging=charging, reach=reach)


# -- the rules ----------------------------------------------------------------------------------


def test_who_wants_a_charge_and_whose_charge_is_done() -> None:
    assert wants_charge(make_state(battery_state=_battery(29.9)), SETTINGS)
    assert not wants_charge(make_state(battery_state=_battery(30.0)), SETTINGS)
    assert not wants_charge(make_state(battery_state=_battery(10.0, charging=True)), SETTINGS)
    assert not wants_charge(make_state(battery_state=_battery(10.0)), ChargeSettings(0.0, 80.0))
    assert charge_done(make_state(battery_state=_battery(80.0, charging=True)), SETTINGS)
    assert not charge_done(make_state(battery_state=_battery(79.9, charging=True)), SETTINGS)
    assert not charge_done(make_state(battery_state=_battery(95.0)), SETTINGS)


def test_the_lowest_battery_goes_first_and_taken_chargers_are_not_free() -> None:
    a, b, c = AgvId("m", "a"), AgvId("m", "b"), AgvId("m", "c")
    assert charging_queue([(a, 25.0), (b, 12.0), (c, 25.0)]) == [b, a, c]
    assert free_chargers(["15", "16", "17"], standing={"15"}, bound_for={"17"}) == ["16"]


def test_a_vehicle_alone_on_a_charger_charges_there_and_leaving_vehicles_free_theirs() -> None:
    a, b = AgvId("m", "a"), AgvId("m", "b")
    standing = {"15": {a}, "16": {a, b}}
    free = ["17"]
    assert spots_for(
        a, "15", chargers=["15", "16", "17"], standing=standing, bound_for=(), free=free
    ) == ["15"]
    assert (
        spots_for(a, "16", chargers=["15", "16", "17"], standing=standing, bound_for=(), free=free)
        == free
    )
    assert (
        spots_for(
            a, "15", chargers=["15", "16", "17"], standing=standing, bound_for={"15"}, free=free
        )
        == free
    )
    assert vacating(["15", "16"], standing, bound_for=(), running={a}) == ["15"]
    assert vacating(["15", "16"], standing, bound_for={"15"}, running={a, b}) == ["16"]


def test_an_attempt_that_raised_nothing_is_not_repeated_for_a_while() -> None:
    attempt = ChargeAttempt(at=100.0, battery_pct=20.0)
    assert retry_blocked(attempt, 20.0, now=200.0, retry_after_s=600.0)
    assert retry_blocked(attempt, 19.0, now=200.0, retry_after_s=600.0)
    assert not retry_blocked(attempt, 45.0, now=200.0, retry_after_s=600.0)  # it charged
    assert not retry_blocked(attempt, 20.0, now=700.0, retry_after_s=600.0)  # time to try again
    assert not retry_blocked(None, 20.0, now=200.0, retry_after_s=600.0)


def test_a_route_beyond_the_reach_is_named_and_an_unknown_reach_is_no_limit() -> None:
    short = reach_problem(make_state(battery_state=_battery(12.0, reach=8.0)), 20.0)
    assert short == (
        "its battery reaches 8 m (batteryState.reach, at 12 %) and the route is 20.0 m"
    )
    assert reach_problem(make_state(battery_state=_battery(12.0, reach=8.0)), 8.0) is None
    # placeholders: no reach, or 0 with a charge (vehicles that do not estimate it)
    assert reach_problem(make_state(battery_state=_battery(12.0)), 500.0) is None
    assert reach_problem(make_state(battery_state=_battery(12.0, reach=0.0)), 500.0) is None
    assert reach_problem(None, 500.0) is None


def test_the_config_refuses_a_charge_that_would_end_before_it_began() -> None:
    with pytest.raises(ValidationError, match="charged_pct \\(30\\) must be above"):
        MasterConfig.model_validate({"charge_below_pct": 30, "charged_pct": 30})
    assert MasterConfig.model_validate({"charge_below_pct": 0, "charged_pct": 10}).charged_pct == 10


# -- the service ---------------------------------------------------------------------------------


def _topic(kind: Topic) -> str:
    return build_topic("uagv", 2, AGV, kind)


def _service(
    battery: Any, *, node: str = "7", actions: Any = CHARGER_ACTIONS, **config: object
) -> tuple[MasterService, RecordingPublisher, FakeClock]:
    publisher, clock = RecordingPublisher(), FakeClock()
    settings = MasterConfig.model_validate({"confirm_timeout_s": 1.0, **config})
    service = MasterService(settings, demo_graph(), publisher, clock)
    online = Connection.model_validate({**HEADER, "connection_state": ConnectionState.ONLINE})
    service.ingest(_topic(Topic.CONNECTION), encode(online))
    service.ingest(_topic(Topic.FACTSHEET), encode(make_factsheet(actions=actions)))
    service.ingest(
        _topic(Topic.STATE), encode(make_state(last_node_id=node, battery_state=battery))
    )
    return service, publisher, clock


def _second(service: MasterService, clock: FakeClock) -> None:
    clock.advance(1.0)
    service.tick()


def test_a_low_idle_vehicle_is_sent_to_the_nearest_charger_with_start_charging() -> None:
    service, publisher, clock = _service(_battery(22.0))
    _second(service, clock)
    (order,) = publisher.orders()
    assert [n["nodeId"] for n in order["nodes"]] == ["7", "15"]
    assert [a["actionType"] for a in order["nodes"][-1]["actions"]] == ["startCharging"]
    track = service.tracks[order["orderId"]]
    assert track.note == "charging: battery 22 % is below charge_below_pct 30 %"
    with pytest.raises(RequestError, match="master control is sending it to node '15'"):
        service.create_order(OrderRequest(Target(destination="10"), AGV))


def test_a_vehicle_on_a_charger_charges_where_it_stands() -> None:
    service, publisher, clock = _service(_battery(22.0), node="16")
    _second(service, clock)
    (order,) = publisher.orders()
    assert [n["nodeId"] for n in order["nodes"]] == ["16"]
    assert order["edges"] == []


def test_nothing_happens_with_energy_management_off_or_above_the_threshold() -> None:
    for service, publisher, clock in (
        _service(_battery(22.0), charge_below_pct=0),
        _service(_battery(31.0)),
    ):
        _second(service, clock)
        assert publisher.orders() == []


def test_a_vehicle_that_cannot_start_charging_is_logged_once_and_stays_usable() -> None:
    """Its factsheet lists no startCharging: no charging order, one log line, and the vehicle
    still takes orders (a factsheet narrows what is sent, it does not make a vehicle unusable)."""
    without = [a for a in CHARGER_ACTIONS if a["actionType"] != "startCharging"]
    service, publisher, clock = _service(_battery(22.0), actions=without)
    with capture_logs() as logs:
        _second(service, clock)
        _second(service, clock)
    refused = [e for e in logs if e["event"] == "charging.cannot_send"]
    assert len(refused) == 1
    assert "startCharging" in refused[0]["reason"]
    assert publisher.orders() == []
    service.create_order(OrderRequest(Target(destination="10"), AGV))
    assert len(publisher.orders()) == 1


def test_a_charge_that_raised_nothing_is_not_sent_again_at_once() -> None:
    """The charging order finished, but the vehicle reports the same 22 % and no charging (a
    placeholder battery, a charger that failed): it is not sent again every second."""
    service, publisher, clock = _service(_battery(22.0), time_lapse=1.0)
    _second(service, clock)
    (order,) = publisher.orders()
    plan = service.tracks[order["orderId"]].plan
    finished = dict.fromkeys(plan.action_ids(), ActionStatus.FINISHED)
    done = plan_state(plan, passed=plan.last_index, actions=finished, battery_state=_battery(22.0))
    with capture_logs() as logs:
        service.ingest(_topic(Topic.STATE), encode(done))
        assert service.tracks[order["orderId"]].status.value == "FINISHED"
        for _ in range(5):
            _second(service, clock)
    assert len(publisher.orders()) == 1
    assert [e["event"] for e in logs if e["event"].startswith("charging.")] == [
        "charging.not_charging"
    ]
    clock.advance(600.0)
    service.ingest(_topic(Topic.STATE), encode(done))  # its heartbeat
    service.tick()
    assert len(publisher.orders()) == 2  # time to try again


def test_a_charged_vehicle_is_sent_stop_charging_once_every_five_seconds() -> None:
    service, publisher, clock = _service(_battery(85.0, charging=True), node="15")
    _second(service, clock)
    (stop,) = publisher.messages(Topic.INSTANT_ACTIONS)
    assert [a["actionType"] for a in stop["actions"]] == ["stopCharging"]
    _second(service, clock)
    assert len(publisher.messages(Topic.INSTANT_ACTIONS)) == 1
    clock.advance(5.0)
    service.tick()
    assert len(publisher.messages(Topic.INSTANT_ACTIONS)) == 2  # still charging: again
    with pytest.raises(RequestError, match="master control sends stopCharging at charged_pct 80"):
        service.create_order(OrderRequest(Target(destination="10"), AGV))


def test_a_vehicle_that_cannot_be_sent_stop_charging_is_logged_once() -> None:
    service, publisher, clock = _service(
        _battery(85.0, charging=True), node="15", actions=LOAD_ACTIONS
    )
    with capture_logs() as logs:
        for _ in range(7):
            _second(service, clock)
    assert publisher.messages(Topic.INSTANT_ACTIONS) == []
    (cannot,) = [e for e in logs if e["event"] == "charging.cannot_stop"]
    assert "stopCharging" in cannot["reason"]


def test_a_charge_under_the_target_goes_on() -> None:
    service, publisher, clock = _service(_battery(60.0, charging=True), node="15")
    _second(service, clock)
    assert publisher.messages(Topic.INSTANT_ACTIONS) == []


def test_a_vehicle_whose_order_ends_low_goes_to_charge_before_the_next_order_can_take_it() -> None:
    """The state that ends its order (at 25 %) sends it to charge at once, without waiting for
    the tick: a client asking for its next order in the same moment gets a 409."""
    service, publisher, _ = _service(_battery(31.0))
    service.create_order(OrderRequest(Target(destination="10"), AGV))
    (order,) = publisher.orders()
    plan = service.tracks[order["orderId"]].plan
    done = plan_state(plan, passed=plan.last_index, battery_state=_battery(25.0))
    service.ingest(_topic(Topic.STATE), encode(done))
    assert service.tracks[order["orderId"]].status.value == "FINISHED"
    _, charge = publisher.orders()
    assert charge["nodes"][-1]["nodeId"] in {"15", "16"}
    assert [a["actionType"] for a in charge["nodes"][-1]["actions"]] == ["startCharging"]
    with pytest.raises(RequestError, match="master control is sending it to node"):
        service.create_order(OrderRequest(Target(destination="3"), AGV))


def _another(service: MasterService, agv: AgvId, node: str, level: float) -> None:
    whose: dict[str, Any] = {"serial_number": agv.serial_number}
    online = Connection.model_validate(
        {**HEADER, **whose, "connection_state": ConnectionState.ONLINE}
    )
    for kind, message in (
        (Topic.CONNECTION, online),
        (Topic.FACTSHEET, make_factsheet(actions=CHARGER_ACTIONS, **whose)),
        (Topic.STATE, make_state(last_node_id=node, battery_state=_battery(level), **whose)),
    ):
        service.ingest(build_topic("uagv", 2, agv, kind), encode(message))


@pytest.mark.parametrize("traffic_control", [True, False])
def test_an_order_without_a_vehicle_named_goes_to_one_that_needs_no_charge(
    traffic_control: bool,
) -> None:
    """robot_0 (25 %) stands 5 m from node 1, robot_1 (90 %) 10 m from it: robot_1 goes. With
    robot_1 busy, robot_0 is still used: a low vehicle waiting for a charger is not idle."""
    service, _, _ = _service(_battery(25.0), traffic_control=traffic_control)
    healthy = AgvId("acme", "robot_1")
    _another(service, healthy, "10", 90.0)
    first = service.create_order(OrderRequest(Target(destination="1")))
    assert first.plan.agv == healthy
    second = service.create_order(OrderRequest(Target(destination="2")))
    assert second.plan.agv == AGV


def test_room_is_made_once_and_the_charger_goes_to_the_one_that_waited() -> None:
    """Both chargers (15, 16) are held by idle vehicles A and B that do not charge; C (20 %)
    waits.
    One of them is moved to parking, and while it drives off no second one is moved; once it
    has left, C is sent to the charger it freed."""
    # without traffic control, which would also move C out of A's way (node 7 is on it)
    service, publisher, clock = _service(_battery(90.0), node="15", traffic_control=False)
    b, c = AgvId("acme", "robot_1"), AgvId("acme", "robot_2")
    _another(service, b, "16", 90.0)
    _another(service, c, "7", 20.0)
    _second(service, clock)
    (room,) = publisher.orders()
    assert room["serialNumber"] == "robot_0"
    assert room["nodes"][-1]["nodeId"] in {"17", "18"}  # the demo graph's parking
    assert service.tracks[room["orderId"]].note == (
        "charging: making room at charger '15' for acme/robot_2"
    )
    _second(service, clock)  # robot_0 still stands on 15, driving away: nobody else moves
    assert {o["orderId"] for o in publisher.orders()} == {room["orderId"]}
    plan = service.tracks[room["orderId"]].plan
    service.ingest(_topic(Topic.STATE), encode(plan_state(plan, passed=1)))
    _second(service, clock)
    charge = publisher.orders()[-1]
    assert (charge["serialNumber"], charge["nodes"][-1]["nodeId"]) == ("robot_2", "15")


def test_a_charge_an_operator_started_runs_until_it_is_ended_by_hand() -> None:
    """An operator sends startCharging to a vehicle at 85 % to fill it up: master control does
    not end that charge at charged_pct. Once the vehicle has stopped charging, its next charge
    at or above charged_pct is master control's to end again."""
    service, publisher, clock = _service(_battery(85.0), node="15")
    service.send_instant_actions(AGV, [ActionSpec("startCharging")])
    sent = len(publisher.messages(Topic.INSTANT_ACTIONS))
    for level in (85.0, 90.0, 99.0):
        state = make_state(last_node_id="15", battery_state=_battery(level, charging=True))
        service.ingest(_topic(Topic.STATE), encode(state))
        _second(service, clock)
    assert len(publisher.messages(Topic.INSTANT_ACTIONS)) == sent  # no stopCharging
    stopped = make_state(last_node_id="15", battery_state=_battery(99.0))
    service.ingest(_topic(Topic.STATE), encode(stopped))
    _second(service, clock)
    again = make_state(last_node_id="15", battery_state=_battery(99.0, charging=True))
    service.ingest(_topic(Topic.STATE), encode(again))
    _second(service, clock)
    last = publisher.messages(Topic.INSTANT_ACTIONS)[-1]
    assert [a["actionType"] for a in last["actions"]] == ["stopCharging"]


def test_an_operator_charging_order_is_not_ended_either() -> None:
    service, publisher, clock = _service(_battery(85.0), node="7")
    charge = ActionSpec("startCharging")
    track = service.create_order(
        OrderRequest(Target(destination="15"), AGV, destination_actions=(charge,))
    )
    plan = track.plan
    finished = dict.fromkeys(plan.action_ids(), ActionStatus.FINISHED)
    done = plan_state(
        plan, passed=plan.last_index, actions=finished, battery_state=_battery(86.0, charging=True)
    )
    service.ingest(_topic(Topic.STATE), encode(done))
    assert service.tracks[plan.order_id].status.value == "FINISHED"
    for _ in range(3):
        _second(service, clock)
    assert publisher.messages(Topic.INSTANT_ACTIONS) == []


async def test_a_vehicle_out_of_service_is_not_sent_to_charge_until_put_back() -> None:
    service, publisher, clock = _service(_battery(22.0))
    await service.set_in_service(AGV, in_service=False, note="battery swap")
    _second(service, clock)
    _second(service, clock)
    assert publisher.orders() == []
    await service.set_in_service(AGV, in_service=True)
    _second(service, clock)
    (order,) = publisher.orders()
    assert [n["nodeId"] for n in order["nodes"]] == ["7", "15"]
