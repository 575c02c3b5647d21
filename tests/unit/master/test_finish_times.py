"""``expectedFinishAt`` in the order view, from master control's service (docs/master.md
*Expected finish*): the plan at the vehicle's factsheet speed, what the vehicle's states say
it has driven, and the pace and dwell learned from the orders before."""

from __future__ import annotations

from datetime import datetime, timedelta
from pathlib import Path

import pytest
from structlog.testing import capture_logs

import vda_master.operations
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import ActionStatus
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.api_documents import order_document
from vda_master.capabilities import ActionSpec
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderStatus, OrderTrack
from vda_master.eta import Drive, LearnedMean, graph_legs, leg_times, plan_legs
from vda_master.finish_times import LEARNED_FILE
from vda_master.graph import Graph
from vda_master.planner import Target
from vda_master.requests import OrderRequest
from vda_master.routing import Route, RouteProblem, shortest_route
from vda_master.service import MasterService
from vda_master.stops import Stop
from vda_master.testing import RecordingPublisher, demo_graph, plan_state, report_online

AGV = AgvId("acme", "robot_0")
#: make_factsheet's speedMax (m/s); a 2.0 factsheet gives no turning speed.
SPEED = 2.0


def _service(**config: object) -> tuple[MasterService, FakeClock]:
    clock = FakeClock()
    settings = MasterConfig.model_validate({"traffic_control": False, **config})
    service = MasterService(settings, demo_graph(), RecordingPublisher(), clock)
    report_online(service, AGV, "7")
    return service, clock


def _expected(service: MasterService, track: OrderTrack) -> datetime | None:
    text = order_document(service, service.tracks[track.order_id])["expectedFinishAt"]
    return None if text is None else datetime.fromisoformat(str(text))


def _drive_s(service: MasterService, track: OrderTrack) -> float:
    legs = plan_legs(track.plan.nodes, track.plan.edges)
    return leg_times(service.graph, legs, Drive(SPEED)).to_node[-1]


def _ingest_state(
    service: MasterService,
    track: OrderTrack,
    *,
    passed: int = 0,
    actions: dict[str, ActionStatus] | None = None,
    distance_since_last_node: float | None = None,
) -> None:
    plan = service.tracks[track.order_id].plan
    state = plan_state(
        plan, passed=passed, actions=actions, distance_since_last_node=distance_since_last_node
    )
    service.ingest(build_topic("uagv", 2, AGV, Topic.STATE), encode(state))


def _pick() -> tuple[ActionSpec, ...]:
    return (ActionSpec("pick"),)


def test_a_new_order_is_expected_after_its_drive_at_the_factsheet_speed() -> None:
    """Before anything is learned: now + the plan's edges at speedMax (capped by each edge's
    maxSpeed); it moves on with the vehicle: half an edge driven is off the time left."""
    service, clock = _service()
    track = service.create_order(OrderRequest(Target(destination="10"), AGV))
    drive = _drive_s(service, track)
    assert drive > 0
    expected = _expected(service, track)
    assert expected is not None
    assert (expected - clock.now()).total_seconds() == pytest.approx(drive, abs=0.002)

    clock.advance(1.0)
    first = track.plan.edges[0]
    length = service.graph.edge_length(first.edge_id)
    speed = min(SPEED, first.max_speed or SPEED)
    _ingest_state(service, track, distance_since_last_node=length / 2)
    expected = _expected(service, track)
    assert expected is not None
    left = (expected - clock.now()).total_seconds()
    assert left == pytest.approx(drive - length / 2 / speed, abs=0.002)


def test_the_second_order_counts_the_pace_and_dwell_of_the_first() -> None:
    """The first order takes 1.5 times its drive and 4 s at its pick: the next one, from the
    same node to the same pick, is expected at now + 1.5 × drive + 4 s; once the order ended
    it has no expected finish."""
    service, clock = _service()
    first = service.create_order(
        OrderRequest(Target(destination="10"), AGV, destination_actions=_pick())
    )
    drive = _drive_s(service, first)
    last = first.plan.last_index
    _ingest_state(service, first)
    clock.advance(drive * 1.5)
    _ingest_state(
        service, first, passed=last, actions={first.plan.action_ids()[0]: ActionStatus.RUNNING}
    )
    clock.advance(4.0)
    _ingest_state(
        service, first, passed=last, actions={first.plan.action_ids()[0]: ActionStatus.FINISHED}
    )
    assert service.tracks[first.order_id].status is OrderStatus.FINISHED
    assert _expected(service, first) is None

    report_online(service, AGV, "7")
    second = service.create_order(
        OrderRequest(Target(destination="10"), AGV, destination_actions=_pick())
    )
    expected = _expected(service, second)
    assert expected is not None
    assert (expected - clock.now()) == pytest.approx(
        timedelta(seconds=drive * 1.5 + 4.0), abs=timedelta(milliseconds=5)
    )


def test_master_controls_own_orders_teach_no_pace() -> None:
    """A pace is learned only from orders that were asked for: an order master control made
    itself (its note says why: parking, a back-off) may wait on purpose."""
    service, clock = _service()
    vehicle = service.fleet.get(AGV)
    assert vehicle is not None
    route = shortest_route(service.graph, "7", "10")
    assert isinstance(route, Route)
    track = service.start_order(vehicle, route, (), clock.monotonic(), note="parking")
    clock.advance(_drive_s(service, track) * 3)
    _ingest_state(service, track, passed=track.plan.last_index)
    assert service.estimates.pace_of("acme") == 1.0


def test_a_vehicle_that_hardly_moves_gets_no_estimate_rather_than_a_crash() -> None:
    """A factsheet speed of almost nothing (a bad factsheet) would put the finish centuries
    ahead, beyond what a date can hold: the order view says null instead."""
    service, _ = _service()
    track = service.create_order(OrderRequest(Target(destination="10"), AGV))
    service.estimates.pace["acme"] = LearnedMean(1e12, 1)  # as a near-zero speed would make it
    assert order_document(service, service.tracks[track.order_id])["expectedFinishAt"] is None


def test_the_stops_still_to_come_add_their_way_and_a_second_view_searches_no_route(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An order with a further stop (docs/master.md, *Orders with several stops*) is expected
    after its first leg and the way from there to the stop (the shortest, traffic control
    off; nothing learned yet); the way is found once, not at every view of the order."""
    service, clock = _service()
    drop = Stop("14", None, (ActionSpec("drop"),))
    track = service.create_order(
        OrderRequest(Target(destination="10"), AGV, destination_actions=_pick(), onward=(drop,))
    )
    second = shortest_route(service.graph, "10", "14")
    assert isinstance(second, Route)
    legs = graph_legs(service.graph, second.edge_ids)
    second_s = leg_times(service.graph, legs, Drive(SPEED)).to_node[-1]
    searches: list[tuple[str, str]] = []
    search = shortest_route

    def counted(graph: Graph, start: str, destination: str) -> Route | RouteProblem:
        searches.append((start, destination))
        return search(graph, start, destination)

    monkeypatch.setattr(vda_master.operations, "shortest_route", counted)
    expected = _expected(service, track)
    assert expected is not None
    assert (expected - clock.now()).total_seconds() == pytest.approx(
        _drive_s(service, track) + second_s, abs=0.002
    )
    _expected(service, track)
    assert searches == [("10", "14")]


async def test_what_was_learned_outlives_a_restart(tmp_path: Path) -> None:
    """Master control keeps the pace and dwell it learned in its data folder: started again,
    its first estimate counts them, as the running one did."""
    service, clock = _service(data_dir=str(tmp_path))
    first = service.create_order(
        OrderRequest(Target(destination="10"), AGV, destination_actions=_pick())
    )
    drive = _drive_s(service, first)
    _ingest_state(service, first)
    clock.advance(drive * 2.0)
    done = {first.plan.action_ids()[0]: ActionStatus.FINISHED}
    _ingest_state(service, first, passed=first.plan.last_index, actions=done)
    await service.keep_learned()
    written = service.learned_path.stat().st_mtime_ns
    await service.keep_learned()  # nothing new: not written again
    assert service.learned_path.stat().st_mtime_ns == written

    restarted, clock = _service(data_dir=str(tmp_path))
    with capture_logs() as logs:
        restarted.load_learned()
    assert [e["event"] for e in logs] == ["eta.learned_resumed"]
    second = restarted.create_order(
        OrderRequest(Target(destination="10"), AGV, destination_actions=_pick())
    )
    expected = _expected(restarted, second)
    assert expected is not None
    assert (expected - clock.now()).total_seconds() == pytest.approx(drive * 2.0, abs=0.01)


def test_a_learned_file_that_cannot_be_read_is_logged_and_left_alone(tmp_path: Path) -> None:
    (tmp_path / LEARNED_FILE).write_text("{not json")
    service, _ = _service(data_dir=str(tmp_path))
    with capture_logs() as logs:
        service.load_learned()
    assert [e["event"] for e in logs] == ["eta.learned_unreadable"]
    assert service.estimates.pace == {}
