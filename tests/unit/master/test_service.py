"""The master service shell without a broker: a recording publisher and a fake clock drive it
(§6.14, R84, R112; house style §3.1.4 bad input)."""

from __future__ import annotations

from typing import Any

import orjson
import pytest
from structlog.testing import capture_logs

import vda_master.dispatcher
import vda_master.service
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import Connection, ConnectionState, OperatingMode, State
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderStatus
from vda_master.inquiries import CONNECT_GRACE_S, FIRST_DELAY_S
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError, speaking_version
from vda_master.service import BEHIND_BYTES, BEHIND_MESSAGES, MasterService
from vda_master.testing import RecordingPublisher, demo_graph, make_factsheet, plan_state

AGV = AgvId("acme", "robot_0")


def _topic(kind: Topic) -> str:
    return build_topic("uagv", 2, AGV, kind)


def _connection(state: ConnectionState) -> bytes:
    return encode(Connection.model_validate({**HEADER, "connection_state": state}))


def _service(**config: object) -> tuple[MasterService, RecordingPublisher, FakeClock]:
    publisher, clock = RecordingPublisher(), FakeClock()
    settings = MasterConfig.model_validate({"confirm_timeout_s": 1.0, **config})
    service = MasterService(settings, demo_graph(), publisher, clock)
    service.ingest(_topic(Topic.CONNECTION), _connection(ConnectionState.ONLINE))
    service.ingest(_topic(Topic.FACTSHEET), encode(make_factsheet()))
    service.ingest(_topic(Topic.STATE), encode(make_state(last_node_id="7")))
    return service, publisher, clock


def _state(message: State) -> bytes:
    return encode(message)


def test_order_is_stamped_in_the_vehicles_version() -> None:
    """Orders carry the vehicle's own version and per-vehicle headerIds from 0 (§6.4)."""
    service, publisher, _ = _service()
    service.ingest(
        _topic(Topic.CONNECTION),
        encode(
            Connection.model_validate({**HEADER, "version": "2.0.0", "connection_state": "ONLINE"})
        ),
    )
    service.create_order(OrderRequest(Target(destination="10"), AGV))
    (order,) = publisher.orders()
    assert (order["version"], order["headerId"]) == ("2.0.0", 0)


def test_unconfirmed_order_is_resent_on_tick() -> None:
    """A tick after the timeout resends the order with the next headerId (QoS 0 loss)."""
    service, publisher, clock = _service()
    service.create_order(OrderRequest(Target(destination="10"), AGV))
    clock.advance(0.5)
    service.tick()
    assert len(publisher.orders()) == 1
    clock.advance(0.6)
    service.tick()
    first, second = publisher.orders()
    assert second["headerId"] == 1
    assert {k: v for k, v in first.items() if k not in {"headerId", "timestamp"}} == {
        k: v for k, v in second.items() if k not in {"headerId", "timestamp"}
    }


def test_the_tick_visits_only_orders_waiting_for_a_confirmation(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """§6.6.4.3 resends (same orderId and orderUpdateId, which R45 has the vehicle discard) at
    fleet scale: once the vehicle's state confirmed an order, the tick no longer looks at it;
    an order still unconfirmed is looked at and resent as before."""
    service, publisher, clock = _service(traffic_control=False)
    other = AgvId("acme", "robot_1")
    header = {**HEADER, "serial_number": other.serial_number}
    topic = build_topic("uagv", 2, other, Topic.CONNECTION)
    service.ingest(
        topic, encode(Connection.model_validate({**header, "connection_state": "ONLINE"}))
    )
    service.ingest(
        build_topic("uagv", 2, other, Topic.FACTSHEET),
        encode(make_factsheet(serial_number=other.serial_number)),
    )
    service.ingest(
        build_topic("uagv", 2, other, Topic.STATE),
        encode(make_state(serial_number=other.serial_number, last_node_id="10")),
    )
    confirmed = service.create_order(OrderRequest(Target(destination="10"), AGV))
    service.ingest(_topic(Topic.STATE), _state(plan_state(confirmed.plan)))
    assert service.tracks[confirmed.order_id].status == OrderStatus.RUNNING
    unconfirmed = service.create_order(OrderRequest(Target(destination="7"), other))
    looked_at: list[str] = []
    checks = vda_master.dispatcher.anything_due

    def counting(track: Any, *args: Any, **kwargs: Any) -> bool:
        looked_at.append(track.order_id)
        return checks(track, *args, **kwargs)

    monkeypatch.setattr(vda_master.service, "anything_due", counting)
    for _ in range(3):
        clock.advance(0.6)
        service.tick()
    assert set(looked_at) == {unconfirmed.order_id}
    resent = [o for o in publisher.orders() if o["orderId"] == unconfirmed.order_id]
    assert [o["headerId"] for o in resent] == [0, 1]


def test_a_late_confirmation_stretches_the_timeout_for_later_orders() -> None:
    """A confirmation that came 0.9 s after the send (load, not loss: timeout 1 s) makes the
    master wait longer before resending the next order (confirmation module)."""
    service, publisher, clock = _service()
    track = service.create_order(OrderRequest(Target(destination="10"), AGV))
    clock.advance(0.9)
    service.ingest(_topic(Topic.STATE), _state(plan_state(service.tracks[track.order_id].plan)))
    assert service.confirmations.timeout_s > 2.0
    assert service.dispatch_settings.confirm_timeout_s == service.confirmations.timeout_s
    plan = service.tracks[track.order_id].plan
    finished = plan_state(plan, passed=plan.last_index)
    service.ingest(_topic(Topic.STATE), _state(finished))
    assert service.tracks[track.order_id].status == OrderStatus.FINISHED
    service.create_order(OrderRequest(Target(destination="7"), AGV))
    clock.advance(1.5)
    service.tick()
    assert len(publisher.orders()) == 2  # no resend of the second order after 1.5 s


def test_a_state_confirming_an_order_proves_its_topic_delivered() -> None:
    """The state that confirms an order tells the session that the broker let the order
    through, so it needs no echo check (vda5050.access, after evidence); a state that
    confirms nothing new (the one before the order) says nothing."""
    service, _, clock = _service()
    delivered: list[str] = []
    service.on_order_delivered = delivered.append
    track = service.create_order(OrderRequest(Target(destination="10"), AGV))
    service.ingest(_topic(Topic.STATE), encode(make_state(last_node_id="7")))
    assert delivered == []
    clock.advance(0.1)
    service.ingest(_topic(Topic.STATE), _state(plan_state(service.tracks[track.order_id].plan)))
    assert delivered == [_topic(Topic.ORDER)]


def test_no_resend_and_no_request_while_the_inbound_lags() -> None:
    """With unread inbound bytes above BEHIND_BYTES, or more than BEHIND_MESSAGES waiting to be
    sent, the tick resends nothing (the confirming state may be unread, the order may not have
    left yet); once caught up, the overdue order is resent."""
    service, publisher, clock = _service()
    backlog = [(BEHIND_BYTES + 1, 0)]
    service.backlog = lambda: backlog[0]
    service.create_order(OrderRequest(Target(destination="10"), AGV))
    clock.advance(1.5)
    service.tick()
    assert len(publisher.orders()) == 1
    backlog[0] = (0, BEHIND_MESSAGES + 1)  # its own messages queued, not sent yet: no resend
    service.tick()
    assert len(publisher.orders()) == 1
    backlog[0] = (0, 0)
    service.tick()
    assert len(publisher.orders()) == 2


def test_connection_broken_pauses_but_keeps_tracking() -> None:
    """CONNECTIONBROKEN stops resends; back ONLINE the vehicle's state continues the order."""
    service, publisher, clock = _service()
    track = service.create_order(OrderRequest(Target(destination="10"), AGV))
    service.ingest(_topic(Topic.CONNECTION), _connection(ConnectionState.CONNECTIONBROKEN))
    clock.advance(5.0)
    service.tick()
    assert len(publisher.orders()) == 1
    assert service.tracks[track.order_id].status == OrderStatus.SENT
    service.ingest(_topic(Topic.CONNECTION), _connection(ConnectionState.ONLINE))
    service.ingest(_topic(Topic.STATE), _state(plan_state(track.plan, passed=1)))
    assert service.tracks[track.order_id].status == OrderStatus.RUNNING


def test_no_resend_to_a_vehicle_switched_to_manual() -> None:
    """A vehicle that went MANUAL gets no resend (R84)."""
    service, publisher, clock = _service()
    service.create_order(OrderRequest(Target(destination="10"), AGV))
    manual = make_state(last_node_id="7", operating_mode=OperatingMode.MANUAL)
    service.ingest(_topic(Topic.STATE), _state(manual))
    clock.advance(5.0)
    service.tick()
    assert len(publisher.orders()) == 1


def test_min_order_interval_delays_the_next_order() -> None:
    """A vehicle with minOrderInterval 1 s gets its next order message only after 1 s (R114)."""
    service, publisher, clock = _service()
    service.ingest(_topic(Topic.FACTSHEET), encode(make_factsheet(min_order_interval=1.0)))
    first = service.create_order(OrderRequest(Target(destination="10"), AGV))
    service.ingest(_topic(Topic.STATE), _state(plan_state(first.plan, passed=3)))
    assert service.tracks[first.order_id].status == OrderStatus.FINISHED
    service.ingest(_topic(Topic.STATE), _state(make_state(last_node_id="10")))
    service.create_order(OrderRequest(Target(destination="7"), AGV))
    assert len(publisher.orders()) == 1
    clock.advance(1.0)
    service.tick()
    assert len(publisher.orders()) == 2


def test_invalid_factsheet_is_dropped_and_the_old_one_kept() -> None:
    """A broken factsheet is dropped with one log line; the valid one stays in the view."""
    service, _, _ = _service()
    with capture_logs() as logs:
        service.ingest(_topic(Topic.FACTSHEET), b'{"typeSpecification": 3}')
    (line,) = logs
    assert line["event"] == "message.dropped"
    assert line["agv"] == "acme/robot_0"
    assert line["topic"] == _topic(Topic.FACTSHEET)
    vehicle = service.fleet.get(AGV)
    assert vehicle is not None
    assert vehicle.factsheet is not None


def test_message_on_a_foreign_topic_is_dropped() -> None:
    """A payload whose header names another vehicle than its topic is dropped (R17, R18)."""
    service, _, _ = _service()
    other = make_state(serial_number="someone_else")
    with capture_logs() as logs:
        service.ingest(_topic(Topic.STATE), encode(other))
    assert [line["event"] for line in logs] == ["message.dropped"]
    vehicle = service.fleet.get(AGV)
    assert vehicle is not None
    assert vehicle.state is not None
    assert vehicle.state.serial_number == "robot_0"


def test_unparsable_topic_is_dropped() -> None:
    """A topic that is not a VDA 5050 topic is dropped with its reason."""
    service, _, _ = _service()
    with capture_logs() as logs:
        service.ingest("uagv/v2/acme/state", b"{}")
    assert logs[0]["event"] == "message.dropped"
    assert "levels" in logs[0]["reason"]


def test_unknown_vehicle_is_a_404() -> None:
    """An order for a vehicle the master never heard from is refused with 404."""
    service, _, _ = _service()
    with pytest.raises(RequestError) as caught:
        service.create_order(OrderRequest(Target(destination="10"), AgvId("acme", "x")))
    assert caught.value.status == 404


def test_speaking_version_maps_patch_versions() -> None:
    """A vehicle speaking 2.0.x is addressed in 2.0.0, anything else 2.x in 2.1.0."""
    assert speaking_version("2.0.3") == "2.0.0"
    assert speaking_version("2.1.0") == "2.1.0"
    assert speaking_version(None) == "2.1.0"


def _bare_service() -> tuple[MasterService, RecordingPublisher, FakeClock]:
    publisher, clock = RecordingPublisher(), FakeClock()
    service = MasterService(MasterConfig(), demo_graph(), publisher, clock)
    return service, publisher, clock


def _instant(publisher: RecordingPublisher) -> list[dict[str, Any]]:
    return [orjson.loads(p) for t, p in publisher.sent if t.endswith("/instantActions")]


def _online(version: str, serial: str = "robot_0") -> bytes:
    return encode(
        Connection.model_validate(
            {**HEADER, "version": version, "serial_number": serial, "connection_state": "ONLINE"}
        )
    )


def test_vehicle_without_factsheet_is_asked_for_state_and_factsheet() -> None:
    """An ONLINE vehicle that published neither a state nor a factsheet gets a stateRequest and
    a factsheetRequest within a second (a missing factsheet does not make it unusable)."""
    service, publisher, clock = _bare_service()
    service.ingest(_topic(Topic.CONNECTION), _online("2.1.0"))
    clock.advance(1.0)
    service.tick()
    types = [a["actionType"] for m in _instant(publisher) for a in m["actions"]]
    assert types == ["stateRequest", "factsheetRequest"]


def test_a_vehicle_seen_connecting_gets_time_to_publish_its_state() -> None:
    """A live ONLINE (the vehicle connected just now, R09: its state follows) gets
    CONNECT_GRACE_S before any request; a retained one (it connected before master control
    subscribed: its first state went to nobody) the usual FIRST_DELAY_S."""
    for retained, wait in ((False, CONNECT_GRACE_S), (True, FIRST_DELAY_S)):
        service, publisher, clock = _bare_service()
        service.ingest(_topic(Topic.CONNECTION), _online("2.1.0"), retained=retained)
        clock.advance(wait - 0.1)
        service.tick()
        assert _instant(publisher) == []
        clock.advance(0.1)
        service.tick()
        assert [a["actionType"] for m in _instant(publisher) for a in m["actions"]] == [
            "stateRequest",
            "factsheetRequest",
        ]


def test_no_request_for_a_state_that_may_be_unread() -> None:
    """While the inbound lags (a fleet connecting at once), a vehicle whose ONLINE was read but
    not yet its state is not asked for it after a second: the state is most likely among the
    unread messages. Once caught up, or long overdue, the request goes out."""
    service, publisher, clock = _bare_service()
    backlog = [(BEHIND_BYTES + 1, 0)]
    service.backlog = lambda: backlog[0]
    service.tick()
    service.ingest(_topic(Topic.CONNECTION), _online("2.1.0"))
    clock.advance(1.0)
    service.ingest(_topic(Topic.FACTSHEET), encode(make_factsheet()))  # asks nothing either
    service.tick()
    assert _instant(publisher) == []
    backlog[0] = (0, 0)
    service.tick()
    assert [a["actionType"] for m in _instant(publisher) for a in m["actions"]] == ["stateRequest"]


def test_vehicle_without_factsheet_gets_full_orders() -> None:
    """Without a factsheet the order carries nodePosition (x, y, mapId), edge length (issue 8)."""
    service, publisher, _ = _bare_service()
    service.ingest(_topic(Topic.CONNECTION), _online("2.0.0"))
    service.ingest(_topic(Topic.STATE), encode(make_state(last_node_id="7", version="2.0.0")))
    service.create_order(OrderRequest(Target(destination="10"), AGV))
    (order,) = publisher.orders()
    nodes = order["nodes"]
    assert isinstance(nodes, list)
    assert all(node["nodePosition"]["mapId"] == "demo" for node in nodes)
    assert all("length" in edge for edge in order["edges"])


def test_instant_actions_to_a_2_0_vehicle_carry_the_legacy_key_too() -> None:
    """2.0 vehicles get the array under 'actions' and, for vda-5050-lib, 'instantActions';
    2.1 vehicles only under 'actions'."""
    for version, legacy in (("2.0.0", True), ("2.1.0", False)):
        service, publisher, clock = _bare_service()
        service.ingest(_topic(Topic.CONNECTION), _online(version))
        clock.advance(1.0)
        service.tick()
        (message, *_) = _instant(publisher)
        assert ("instantActions" in message) is legacy
        assert message.get("instantActions", message["actions"]) == message["actions"]


def test_unlisted_vehicles_are_ignored_when_not_accepted() -> None:
    """accept_unlisted_vehicles false: only the robots list is tracked; others are logged once
    and never reach the view (issue 14)."""
    publisher, clock = RecordingPublisher(), FakeClock()
    config = MasterConfig.model_validate(
        {
            "accept_unlisted_vehicles": False,
            "robots": [{"manufacturer": "acme", "serial_number": "robot_0"}],
        }
    )
    service = MasterService(config, demo_graph(), publisher, clock)
    stranger = AgvId("acme", "made-up")
    with capture_logs() as logs:
        for _ in range(3):
            service.ingest(
                build_topic("uagv", 2, stranger, Topic.CONNECTION), _online("2.1.0", "made-up")
            )
    assert service.fleet.get(stranger) is None
    assert [e["event"] for e in logs] == ["vehicle.ignored"]
    service.ingest(_topic(Topic.CONNECTION), _online("2.1.0"))
    vehicle = service.fleet.get(AGV)
    assert vehicle is not None
    assert vehicle.connection == ConnectionState.ONLINE


def test_silent_unlisted_vehicles_leave_the_view() -> None:
    """A vehicle that only said ONLINE and then nothing leaves the live view after
    forget_after_s; listed robots stay (issue 14)."""
    publisher, clock = RecordingPublisher(), FakeClock()
    config = MasterConfig.model_validate(
        {"forget_after_s": 60.0, "robots": [{"manufacturer": "acme", "serial_number": "listed"}]}
    )
    service = MasterService(config, demo_graph(), publisher, clock)
    ghost = AgvId("acme", "ghost")
    service.ingest(build_topic("uagv", 2, ghost, Topic.CONNECTION), _online("2.1.0", "ghost"))
    assert service.fleet.get(ghost) is not None
    clock.advance(30.0)
    service.tick()
    assert service.fleet.get(ghost) is not None
    clock.advance(40.0)
    service.tick()
    assert service.fleet.get(ghost) is None
    assert service.fleet.get(AgvId("acme", "listed")) is not None
    assert service.inquirer.pending() == 0


def test_oversized_vehicle_message_is_dropped() -> None:
    """A state over max_message_bytes never reaches the view (issue 14)."""
    service, _, _ = _service(max_message_bytes=2048)
    huge = make_state(last_node_id="7", order_id="x" * 5000)
    with capture_logs() as logs:
        service.ingest(_topic(Topic.STATE), encode(huge))
    vehicle = service.fleet.get(AGV)
    assert vehicle is not None
    assert vehicle.state is not None
    assert vehicle.state.order_id == ""
    assert "over the 2048 limit" in logs[0]["reason"]


def test_without_traffic_control_nothing_is_reserved_and_orders_still_route() -> None:
    """With traffic control off the master keeps no reservations (GET /traffic shows it off
    and holds nothing); an order is still planned, chosen and dispatched (issue 9 §5)."""
    service, publisher, _ = _service(traffic_control=False)
    track = service.create_order(OrderRequest(Target(destination="10"), None))
    assert track.plan.agv == AGV
    assert len(publisher.orders()) == 1
    snapshot: Any = service.traffic_snapshot()
    assert snapshot["enabled"] is False
    assert [vehicle["holds"] for vehicle in snapshot["vehicles"]] in ([], [[]])


@pytest.mark.parametrize(("time_lapse", "looks"), [(1.0, range(1)), (10.0, range(8, 11))])
def test_traffic_advice_is_looked_at_every_simulated_second(
    time_lapse: float, looks: range
) -> None:
    """Deadlocks and long waits are looked for once a second of the vehicles' time: with
    ``time_lapse`` 10, ten times in a second of the master's clock."""
    service, _, clock = _service(time_lapse=time_lapse)
    seen: list[float] = []
    service.resolve_traffic = seen.append  # type: ignore[method-assign,assignment]
    service.tick()
    seen.clear()
    for _ in range(19):  # 0.95 s
        clock.advance(0.05)
        service.tick()
    assert len(seen) in looks
