"""Orders that wait for a vehicle (docs/master.md, *Queued orders*): the rules, and the service
shell driven by a recording publisher and a fake clock. Without ``queue: true`` the same
requests are refused with 409, as architecture §3.4 says (the other tests of the service)."""

from __future__ import annotations

import math
from typing import Any

import pytest
from structlog.testing import capture_logs

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import ActionStatus, Connection, ConnectionState, OperatingMode
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.capabilities import ActionSpec
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderStatus, OrderTrack
from vda_master.order_records import queued_record
from vda_master.planner import Target
from vda_master.queue_rules import (
    NEVER_SENT,
    QueuedOrder,
    queue_position,
    serving_order,
    worth_trying,
)
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.testing import RecordingPublisher, demo_graph, make_factsheet, plan_state

A = AgvId("acme", "robot_0")
B = AgvId("acme", "robot_1")


def _entry(seq: int, priority: int = 0, agv: AgvId | None = None, **more: Any) -> QueuedOrder:
    request = OrderRequest(Target(destination="10"), agv, queue=True, priority=priority)
    return QueuedOrder(f"o{seq}", request, priority, seq, f"2026-12-01T00:00:0{seq}.000Z", **more)


# -- the rules ----------------------------------------------------------------------------------


def test_higher_priority_goes_first_and_equal_ones_in_arrival_order() -> None:
    entries = [_entry(0), _entry(1, priority=5), _entry(2), _entry(3, priority=5)]
    assert [e.order_id for e in serving_order(entries)] == ["o1", "o3", "o0", "o2"]
    assert queue_position(entries, "o0") == 3
    ended = _entry(4, priority=9, status=OrderStatus.CANCELLED)
    assert queue_position([*entries, ended], "o4") is None  # it waits no more
    assert queue_position(entries, "unknown") is None


def test_an_order_is_tried_when_a_vehicle_for_it_is_available_and_something_changed() -> None:
    fresh = _entry(0)
    assert not worth_trying(fresh, frozenset(), now=0.0, retry_s=10.0)  # nobody is free
    assert worth_trying(fresh, frozenset({A}), now=0.0, retry_s=10.0)
    refused = _entry(0, tried_with=frozenset({A}), tried_at=100.0)
    assert not worth_trying(refused, frozenset({A}), now=105.0, retry_s=10.0)  # same answer
    assert worth_trying(refused, frozenset({A, B}), now=105.0, retry_s=10.0)  # B came free
    assert worth_trying(refused, frozenset({A}), now=110.0, retry_s=10.0)  # time to ask again
    named = _entry(1, agv=B, tried_with=frozenset({B}), tried_at=100.0)
    assert not worth_trying(named, frozenset({A}), now=200.0, retry_s=10.0)  # only B will do
    assert not worth_trying(named, frozenset({A, B}), now=105.0, retry_s=10.0)  # A is no news
    assert worth_trying(_entry(1, agv=B, tried_at=-math.inf), frozenset({B}), 0.0, 10.0)


# -- the service ---------------------------------------------------------------------------------


def _topic(agv: AgvId, kind: Topic) -> str:
    return build_topic("uagv", 2, agv, kind)


def _online(service: MasterService, agv: AgvId, node: str, **state: Any) -> None:
    online = Connection.model_validate({**HEADER, "connection_state": ConnectionState.ONLINE})
    header = {"manufacturer": agv.manufacturer, "serial_number": agv.serial_number}
    service.ingest(_topic(agv, Topic.CONNECTION), encode(online.model_copy(update=header)))
    factsheet = make_factsheet().model_copy(update=header)
    service.ingest(_topic(agv, Topic.FACTSHEET), encode(factsheet))
    report = make_state(last_node_id=node, **header, **state)
    service.ingest(_topic(agv, Topic.STATE), encode(report))


def _service(*vehicles: tuple[AgvId, str]) -> tuple[MasterService, RecordingPublisher, FakeClock]:
    publisher, clock = RecordingPublisher(), FakeClock()
    config = MasterConfig.model_validate({"confirm_timeout_s": 1.0, "charge_below_pct": 0})
    service = MasterService(config, demo_graph(), publisher, clock)
    for agv, node in vehicles:
        _online(service, agv, node)
    return service, publisher, clock


def _finish(service: MasterService, track: OrderTrack) -> None:
    """The vehicle reports the order done: last node reached, every action FINISHED."""
    plan = track.plan
    finished = dict.fromkeys(plan.action_ids(), ActionStatus.FINISHED)
    done = plan_state(plan, passed=plan.last_index, actions=finished)
    header = {"manufacturer": plan.agv.manufacturer, "serial_number": plan.agv.serial_number}
    service.ingest(_topic(plan.agv, Topic.STATE), encode(done.model_copy(update=header)))


def _queued(service: MasterService, destination: str, **more: Any) -> QueuedOrder:
    outcome = service.place_order(OrderRequest(Target(destination=destination), queue=True, **more))
    assert isinstance(outcome, QueuedOrder)
    return outcome


def test_an_order_no_vehicle_can_take_waits_and_goes_out_when_one_comes_free() -> None:
    service, publisher, clock = _service((A, "7"))
    running = service.create_order(OrderRequest(Target(destination="10")))
    assert isinstance(running, OrderTrack)
    with pytest.raises(RequestError, match="no available vehicle can reach 12"):
        service.create_order(OrderRequest(Target(destination="12")))  # without queue: 409
    clock.advance(3.0)
    with capture_logs() as logs:
        waiting = _queued(service, "12")
    assert waiting.status is OrderStatus.QUEUED
    assert f"it runs order {running.order_id!r}" in waiting.reason
    assert [e["position"] for e in logs if e["event"] == "order.queued"] == [1]
    assert len(publisher.orders()) == 1  # nothing sent for it yet
    _finish(service, running)  # the same state serves the queue
    sent = publisher.orders()[-1]
    assert sent["orderId"] == waiting.order_id
    assert sent["nodes"][-1]["nodeId"] == "12"
    track = service.tracks[waiting.order_id]
    assert track.created_utc == waiting.created_utc  # it keeps its place in time
    assert service.queue == {}
    assert service.availability_of(A) == f"it runs order {waiting.order_id!r}"


def test_the_highest_priority_goes_first_then_first_come_first_served() -> None:
    service, publisher, _ = _service((A, "7"))
    running = service.create_order(OrderRequest(Target(destination="10")))
    assert isinstance(running, OrderTrack)
    first = _queued(service, "12")
    urgent = _queued(service, "13", priority=5)
    second = _queued(service, "14")
    assert [service.position(q.order_id) for q in (first, urgent, second)] == [2, 1, 3]
    served = []
    track = running
    for _ in range(3):
        _finish(service, track)
        served.append(publisher.orders()[-1]["orderId"])
        track = service.tracks[served[-1]]
    assert served == [urgent.order_id, first.order_id, second.order_id]


def test_a_named_vehicle_is_waited_for_while_others_serve_the_rest() -> None:
    service, publisher, clock = _service((A, "7"), (B, "1"))
    for_a = service.create_order(OrderRequest(Target(destination="10"), A))
    assert isinstance(for_a, OrderTrack)
    later_for_a = _queued(service, "12", agv=A)
    anyone = service.place_order(OrderRequest(Target(destination="13"), queue=True))
    assert isinstance(anyone, OrderTrack)  # B is free: it goes at once
    assert anyone.plan.agv == B
    clock.advance(1.0)
    service.tick()
    assert later_for_a.order_id in service.queue  # B never takes an order that names A
    _finish(service, for_a)
    assert publisher.orders()[-1]["orderId"] == later_for_a.order_id


def test_a_vehicle_that_becomes_available_is_found_within_a_second() -> None:
    """No order ended: the vehicle was in MANUAL and its next state says AUTOMATIC."""
    service, publisher, clock = _service()
    _online(service, A, "7", operating_mode=OperatingMode.MANUAL)
    waiting = _queued(service, "10")
    assert "MANUAL" in waiting.reason
    service.ingest(_topic(A, Topic.STATE), encode(make_state(last_node_id="7")))
    assert publisher.orders() == []
    clock.advance(1.0)
    service.tick()
    (sent,) = publisher.orders()
    assert sent["orderId"] == waiting.order_id


def test_a_cancelled_queued_order_ends_at_once_and_is_never_sent() -> None:
    service, publisher, clock = _service((A, "7"))
    running = service.create_order(OrderRequest(Target(destination="10")))
    assert isinstance(running, OrderTrack)
    waiting = _queued(service, "12")
    cancelled = service.cancel_order(waiting.order_id)
    assert isinstance(cancelled, QueuedOrder)
    assert cancelled.status is OrderStatus.CANCELLED
    assert cancelled.reason == NEVER_SENT + "cancelled while queued"
    assert publisher.messages(Topic.INSTANT_ACTIONS) == []  # no vehicle had anything to cancel
    assert (service.counters.orders_queued, service.counters.orders_ended["CANCELLED"]) == (1, 1)
    with pytest.raises(RequestError, match="has ended \\(CANCELLED\\)"):
        service.cancel_order(waiting.order_id)
    _finish(service, running)
    clock.advance(1.0)
    service.tick()
    assert len(publisher.orders()) == 1


def test_an_order_for_a_busy_vehicle_that_can_never_take_it_is_refused_at_once() -> None:
    """An action its factsheet does not list: 422 now, not a wait that ends FAILED."""
    service, _, _ = _service((A, "7"))
    running = service.create_order(OrderRequest(Target(destination="10"), A))
    assert isinstance(running, OrderTrack)
    with pytest.raises(RequestError, match="does not list action 'juggle'") as refused:
        _queued(service, "12", agv=A, destination_actions=(ActionSpec("juggle"),))
    assert refused.value.status == 422
    assert service.queue == {}


def test_a_queued_order_its_vehicle_cannot_take_any_more_fails_when_its_turn_comes() -> None:
    """The robot published a new factsheet without the action while the order waited: when
    the robot comes free the order FAILS with the reason, and the next one in line goes."""
    service, publisher, _ = _service((A, "7"))
    running = service.create_order(OrderRequest(Target(destination="10"), A))
    assert isinstance(running, OrderTrack)
    pick = (ActionSpec("pick"),)
    odd = _queued(service, "12", agv=A, destination_actions=pick)
    after = _queued(service, "13", agv=A)
    header = {"manufacturer": A.manufacturer, "serial_number": A.serial_number}
    without_pick = make_factsheet(actions=[{"actionType": "drop", "actionScopes": ["NODE"]}])
    service.ingest(_topic(A, Topic.FACTSHEET), encode(without_pick.model_copy(update=header)))
    _finish(service, running)
    failed = service.queued(odd.order_id)
    assert failed is not None
    assert failed.status is OrderStatus.FAILED
    assert failed.reason.startswith(NEVER_SENT + f"vehicle {A} cannot take this order")
    assert "'pick'" in failed.reason
    assert publisher.orders()[-1]["orderId"] == after.order_id


def test_only_a_409_waits_unknown_targets_and_wrong_requests_are_refused_at_once() -> None:
    service, _, _ = _service((A, "7"))
    with pytest.raises(RequestError) as unknown:
        service.place_order(OrderRequest(Target(destination="nowhere"), queue=True))
    assert unknown.value.status == 404
    with pytest.raises(RequestError) as stranger:
        service.place_order(
            OrderRequest(Target(destination="10"), AgvId("acme", "ghost"), queue=True)
        )
    assert stranger.value.status == 404
    assert service.queue == {}


def test_an_order_no_vehicle_took_within_its_queue_timeout_fails_saying_why() -> None:
    service, publisher, clock = _service((A, "7"))
    running = service.create_order(OrderRequest(Target(destination="10")))
    assert isinstance(running, OrderTrack)
    hurried = _queued(service, "12", queue_timeout_s=5.0)
    patient = _queued(service, "13")
    clock.advance(4.0)
    service.tick()
    assert hurried.order_id in service.queue  # 4 s of 5
    clock.advance(1.0)
    service.tick()
    failed = service.queued(hurried.order_id)
    assert failed is not None
    assert failed.status is OrderStatus.FAILED
    assert failed.reason.startswith(
        NEVER_SENT + "no vehicle could take it within queueTimeoutS 5 s"
    )
    assert f"it runs order {running.order_id!r}" in failed.reason
    _finish(service, running)
    assert publisher.orders()[-1]["orderId"] == patient.order_id  # the patient one goes


def test_a_restored_order_s_queue_timeout_counts_from_its_creation() -> None:
    """Master control was down 10 s: an order that could wait 5 s has run out, one that may
    wait 60 s has 50 left."""
    service, _, clock = _service((A, "7"))
    running = service.create_order(OrderRequest(Target(destination="10")))
    assert isinstance(running, OrderTrack)
    short = _queued(service, "12", queue_timeout_s=5.0)
    long = _queued(service, "13", queue_timeout_s=60.0)
    created = clock.now()
    records = [queued_record(entry, created=created, updated=created) for entry in (short, long)]
    clock.advance(10.0)
    restarted, _, _ = _service((A, "7"))
    restarted.create_order(OrderRequest(Target(destination="10")))  # busy again
    assert isinstance(restarted.clock, FakeClock)
    restarted.clock.advance(10.0)
    restarted.restore_queue(records)
    assert {e.order_id for e in restarted.queue.values()} == {short.order_id, long.order_id}
    restarted.clock.advance(1.0)
    restarted.tick()
    ended = restarted.queued(short.order_id)
    assert ended is not None
    assert ended.status is OrderStatus.FAILED
    waiting = restarted.queued(long.order_id)
    assert waiting is not None
    assert waiting.status is OrderStatus.QUEUED
