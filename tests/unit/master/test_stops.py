"""Orders with several stops (vda_master.stops, vda_master.onward; docs/master.md, *Orders with
several stops*): one order, each stop appended by an update once the vehicle stands at the one
before, with its actions."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

import orjson
import pytest
from pydantic import ValidationError

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.graph_file import GraphZone
from vda5050.models import ActionStatus, Connection, ConnectionState, State
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.api_models import CreateOrder
from vda_master.capabilities import ActionSpec
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderStatus, OrderTrack
from vda_master.order_records import from_record, plan_document, to_record, track_events
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.stops import (
    Stop,
    closed_stop,
    reran_actions,
    stop_document,
    stop_from_document,
)
from vda_master.store import OrderEventKind
from vda_master.testing import (
    RecordingPublisher,
    demo_graph,
    make_factsheet,
    plan_state,
    zone,
)

A = AgvId("acme", "a")
PICK = {"actionType": "pick"}
DROP = {"actionType": "drop"}


def _topic(kind: Topic) -> str:
    return build_topic("uagv", 2, A, kind)


def _service(
    *, traffic: bool = False, graph: Any = None, **settings: object
) -> tuple[MasterService, RecordingPublisher]:
    publisher = RecordingPublisher()
    config = MasterConfig.model_validate(
        {"traffic_control": traffic, "charge_below_pct": 0, **settings}
    )
    service = MasterService(config, graph or demo_graph(), publisher, FakeClock())
    header = {"manufacturer": A.manufacturer, "serial_number": A.serial_number}
    online = Connection.model_validate({**HEADER, "connection_state": ConnectionState.ONLINE})
    service.ingest(_topic(Topic.CONNECTION), encode(online.model_copy(update=header)))
    service.ingest(_topic(Topic.FACTSHEET), encode(make_factsheet().model_copy(update=header)))
    service.ingest(_topic(Topic.STATE), encode(make_state(last_node_id="7", loads=[], **header)))
    return service, publisher


def _report(service: MasterService, state: State) -> None:
    header = {"manufacturer": A.manufacturer, "serial_number": A.serial_number}
    service.ingest(_topic(Topic.STATE), encode(state.model_copy(update=header)))


def _request(*stops: dict[str, Any], **more: Any) -> OrderRequest:
    body = {"manufacturer": "acme", "serialNumber": "a", "stops": list(stops), **more}
    return CreateOrder.model_validate(body).to_request()


def _track(service: MasterService, order_id: str) -> OrderTrack:
    return service.tracks[order_id]


def _at_last_node(service: MasterService, order_id: str, **statuses: ActionStatus) -> OrderTrack:
    """The vehicle drives the order's base as it is released, then reports standing at its
    last node with ``statuses``; the track after that."""
    track = _track(service, order_id)
    while track.released_end < track.plan.last_index:
        end = track.released_end
        _report(
            service,
            plan_state(track.plan, update_id=track.update_id, passed=end, released_end=end),
        )
        track = _track(service, order_id)
    plan = track.plan
    state = plan_state(
        plan, update_id=track.update_id, passed=plan.last_index, actions=statuses or None
    )
    _report(service, state)
    return _track(service, order_id)


def _all(track: OrderTrack, status: ActionStatus) -> dict[str, ActionStatus]:
    return dict.fromkeys(track.plan.action_ids(), status)


def test_a_pick_then_drop_order_appends_the_drop_once_the_pick_is_done() -> None:
    """The drop goes out by an order update stitched at the pick node once the vehicle has
    FINISHED the pick there (a vehicle with nothing left reports the order done at 12 as it
    should: the update then continues the ended order, R48); the order is FINISHED at 14."""
    service, publisher = _service()
    created = service.create_order(
        _request({"destination": "12", "actions": [PICK]}, {"destination": "14", "actions": [DROP]})
    )
    first = publisher.orders()[-1]
    assert first["nodes"][-1]["nodeId"] == "12"
    assert [a["actionType"] for a in first["nodes"][-1]["actions"]] == ["pick"]
    assert created.onward == (Stop("14", None, (ActionSpec("drop"),)),)
    picking = _at_last_node(service, created.order_id, **_all(created, ActionStatus.RUNNING))
    assert picking.plan.destination == "12"  # not while the pick runs
    sent = len(publisher.orders())
    track = _at_last_node(service, created.order_id, **_all(created, ActionStatus.FINISHED))
    assert track.status is OrderStatus.RUNNING  # not FINISHED: the drop is to come
    assert len(publisher.orders()) == sent + 1
    update = publisher.orders()[-1]
    assert update["orderId"] == created.order_id
    assert update["orderUpdateId"] == track.update_id > 0
    assert update["nodes"][0]["nodeId"] == "12"
    assert update["nodes"][0]["actions"] == first["nodes"][-1]["actions"]  # as first sent (R58)
    assert update["nodes"][-1]["nodeId"] == "14"
    assert [a["actionType"] for a in update["nodes"][-1]["actions"]] == ["drop"]
    assert track.onward == ()
    (appended,) = track_events(picking, track, datetime(2026, 12, 2, tzinfo=UTC))[:1]
    assert (appended.event, appended.details) == (
        OrderEventKind.STOP_APPENDED,
        {"destination": "14", "nodes": len(track.plan.nodes), "stopsAhead": 0},
    )
    done = _at_last_node(service, created.order_id, **_all(track, ActionStatus.FINISHED))
    assert done.status is OrderStatus.FINISHED
    assert done.plan.destination == "14"
    assert A not in service.active


def test_a_vehicle_that_runs_the_stop_s_actions_again_gets_no_more_orders_with_stops() -> None:
    """vda-5050-lib's AGV runs the stitching node's actions again (R51): the state after the
    update lists the pick as WAITING. Master control notes it and refuses further orders with
    stops for that vehicle, saying why; orders with one destination still go."""
    service, _ = _service()
    two_stops = ({"destination": "12", "actions": [PICK]}, {"destination": "14", "actions": [DROP]})
    created = service.create_order(_request(*two_stops))
    track = _at_last_node(service, created.order_id, **_all(created, ActionStatus.FINISHED))
    assert service.reruns_stop_actions(A) is None
    pick = created.plan.nodes[-1].actions[0].action_id
    again = plan_state(
        track.plan,
        update_id=track.update_id,
        passed=created.plan.last_index,
        actions={**_all(track, ActionStatus.FINISHED), pick: ActionStatus.WAITING},
    )
    _report(service, again)
    assert "ran the actions of the node an order update starts at again (R51" in (
        service.reruns_stop_actions(A) or ""
    )
    cancelling = service.cancel_order(created.order_id)
    assert isinstance(cancelling, OrderTrack)
    cancel = cancelling.cancel_action_id
    assert cancel is not None
    _report(
        service,
        plan_state(
            cancelling.plan,
            update_id=cancelling.update_id,
            passed=created.plan.last_index,
            actions={**_all(cancelling, ActionStatus.FINISHED), cancel: ActionStatus.FINISHED},
            node_states=[],
            edge_states=[],
        ),
    )
    assert A not in service.active
    with pytest.raises(RequestError, match="takes no order with stops: it ran the actions") as e:
        service.create_order(_request(*two_stops))
    assert e.value.status == 422
    assert service.create_order(_request({"destination": "14"})).plan.destination == "14"


def test_a_stop_of_a_station_type_goes_to_its_nearest_node_from_the_stop_before() -> None:
    service, publisher = _service()
    created = service.create_order(
        _request(
            {"destination": "11", "actions": [PICK]}, {"stationType": "drop", "actions": [DROP]}
        )
    )
    _at_last_node(service, created.order_id, **_all(created, ActionStatus.FINISHED))
    update = publisher.orders()[-1]
    graph = demo_graph()
    assert graph.nodes[update["nodes"][-1]["nodeId"]].station_type == "drop"


async def test_a_next_stop_closed_meanwhile_ends_the_order_failed_saying_which_stop() -> None:
    """A BLOCKED zone added over a stop still to come stops the order at once, before the
    vehicle picks a load it could not drop: master control cancels it, and it ends FAILED
    saying which stop. A zone elsewhere changes nothing."""
    service, publisher = _service()
    created = service.create_order(
        _request({"destination": "12", "actions": [PICK]}, {"destination": "14", "actions": [DROP]})
    )

    def cancels() -> list[dict[str, Any]]:
        return [
            a for m in publisher.messages(Topic.INSTANT_ACTIONS) for a in m["actions"]
            if a["actionType"] == "cancelOrder"
        ]  # fmt: skip

    def around(node_id: str) -> list[list[float]]:
        x, y = demo_graph().nodes[node_id].x, demo_graph().nodes[node_id].y
        return [[x - 0.5, y - 0.5], [x + 0.5, y - 0.5], [x + 0.5, y + 0.5], [x - 0.5, y + 0.5]]

    track = _track(service, created.order_id)  # the vehicle has taken it, and drives
    _report(service, plan_state(track.plan, update_id=track.update_id, passed=0, released_end=0))
    await service.add_zone(GraphZone.model_validate(zone("elsewhere", "BLOCKED", around("17"))))
    assert cancels() == []
    await service.add_zone(GraphZone.model_validate(zone("spill", "BLOCKED", around("14"))))
    (cancel,) = cancels()  # while the vehicle is on its way to the pick at 12
    track = _track(service, created.order_id)
    assert track.plan.destination == "12"
    _report(
        service,
        plan_state(
            track.plan,
            passed=0,
            update_id=track.update_id,
            actions={cancel["actionId"]: ActionStatus.FINISHED},
        ),
    )
    ended = _track(service, created.order_id)
    assert ended.status is OrderStatus.FAILED
    assert ended.reason == (
        "master control stopped it: stop 2 (node '14'): node '14' lies in BLOCKED zone 'spill'"
    )


def test_a_closed_stop_is_named_with_its_number_and_why() -> None:
    """stops.closed_stop: the first stop still ahead whose node is BLOCKED, or whose station
    type has no open node left; numbered as the request counts them."""
    graph = demo_graph()

    def around(*node_ids: str) -> Any:
        zones = []
        for n in node_ids:
            x, y = graph.nodes[n].x, graph.nodes[n].y
            square = [
                [x - 0.5, y - 0.5],
                [x + 0.5, y - 0.5],
                [x + 0.5, y + 0.5],
                [x - 0.5, y + 0.5],
            ]
            zones.append(GraphZone.model_validate(zone(f"z{n}", "BLOCKED", square)))
        return graph.with_zones(zones)

    ahead = (Stop("13", None), Stop(None, "drop"))
    assert closed_stop(graph, ahead, 2) is None
    assert closed_stop(around("13"), ahead, 2) == (
        "stop 2 (node '13'): node '13' lies in BLOCKED zone 'z13'"
    )
    assert closed_stop(around("14"), ahead[1:], 3) is None  # 13 is a drop node still open
    assert closed_stop(around("13", "14"), ahead[1:], 3) == (
        "stop 3 (a node of stationType 'drop'): every node of stationType 'drop' lies in a "
        "BLOCKED zone"
    )


def test_stops_are_checked_before_anything_is_sent() -> None:
    """An unknown node (404), an action the factsheet does not offer at a later stop (422,
    R112), two stops in a row at one node and a stop with two places (malformed)."""
    service, publisher = _service()
    with pytest.raises(RequestError, match="node 'nowhere' is not in the graph") as unknown:
        service.create_order(_request({"destination": "12"}, {"destination": "nowhere"}))
    assert unknown.value.status == 404
    with pytest.raises(RequestError, match=r"stop 2: .*'beep'") as unsupported:
        service.create_order(
            _request(
                {"destination": "12"}, {"destination": "14", "actions": [{"actionType": "beep"}]}
            )
        )
    assert unsupported.value.status == 422
    assert publisher.orders() == []
    with pytest.raises(ValidationError, match="two stops in a row at node '14'"):
        _request({"destination": "14"}, {"destination": "14"})
    with pytest.raises(ValidationError, match="give each stop its actions"):
        _request({"destination": "12"}, {"destination": "14"}, destinationActions=[DROP])
    with pytest.raises(ValidationError, match="exactly one of destination and stationType"):
        _request({"destination": "12", "stationType": "drop"})


def test_the_stops_to_come_are_kept_in_the_store_record() -> None:
    service, _ = _service()
    created = service.create_order(
        _request(
            {"destination": "12", "actions": [PICK]},
            {
                "destination": "14",
                "actions": [{**DROP, "blockingType": "SOFT"}],
            },
            {"stationType": "parking"},
        )
    )
    time = datetime(2026, 12, 2, tzinfo=UTC)
    record = to_record(created, plan_document(created.plan), created=time, updated=time)
    restored = from_record(record, now=0.0)
    assert restored.onward == created.onward
    assert [stop_document(s) for s in created.onward] == [
        {
            "destination": "14",
            "actions": [
                {
                    "actionType": "drop",
                    "blockingType": "SOFT",
                    "actionParameters": [],
                }
            ],
        },
        {"stationType": "parking", "actions": []},
    ]
    assert stop_from_document(stop_document(created.onward[0])) == created.onward[0]


def test_with_traffic_control_each_leg_is_planned_and_driven() -> None:
    """Each leg is a re-plan of the order's route, and the order is due against all of its
    legs: the free-flow estimate grows by the next leg's (otherwise the second leg of every
    pick-then-drop order would turn late early and claim the way ahead of on-time orders)."""
    service, publisher = _service(traffic=True)
    created = service.create_order(
        _request({"destination": "12", "actions": [PICK]}, {"destination": "14", "actions": [DROP]})
    )
    controller = service.coordinator.controller
    first_leg_s = controller.vehicle(A).free_flow_s
    assert first_leg_s is not None
    track = _at_last_node(service, created.order_id, **_all(created, ActionStatus.FINISHED))
    assert track.plan.destination == "14"
    assert publisher.orders()[-1]["nodes"][0]["nodeId"] == "12"
    controller = service.coordinator.controller
    assert controller.vehicle(A).route == track.plan.route  # the new leg
    alone = controller.plan(A, "12", "14", 0.0)  # the only vehicle: the free-flow route
    assert alone is not None
    second_leg_s = alone.arrival + controller.state.settings.dwell_s
    assert controller.vehicle(A).free_flow_s == pytest.approx(first_leg_s + second_leg_s)
    done = _at_last_node(service, created.order_id, **_all(track, ActionStatus.FINISHED))
    assert done.status is OrderStatus.FINISHED


def test_the_request_with_stops_reads_back_as_asked() -> None:
    """What the store keeps of the request (a queued order is restored from it) is the
    request again."""
    request = _request(
        {"destination": "12", "actions": [PICK]},
        {"stationType": "drop", "actions": [{**DROP, "blockingType": "HARD"}]},
        queue=True,
        priority=3,
    )
    again = CreateOrder.model_validate(orjson.loads(request.as_json())).to_request()
    assert again == request
    assert [s.station_type for s in again.onward] == ["drop"]


def test_a_cancelled_order_with_stops_appends_none_of_them() -> None:
    service, publisher = _service(release_window_nodes=0)  # all of the way to 12 released
    created = service.create_order(
        _request({"destination": "12", "actions": [PICK]}, {"destination": "14", "actions": [DROP]})
    )
    cancelling = service.cancel_order(created.order_id)
    assert isinstance(cancelling, OrderTrack)
    cancel = cancelling.cancel_action_id
    assert cancel is not None
    sent = len(publisher.orders())
    end = cancelling.released_end  # it stops at the end of its base (§6.6.3), here the stop
    assert end == cancelling.plan.last_index
    picked = plan_state(  # at the stop, the pick done, the cancel not yet taken in
        cancelling.plan,
        update_id=cancelling.update_id,
        passed=end,
        actions=_all(cancelling, ActionStatus.FINISHED),
    )
    _report(service, picked)
    assert _track(service, created.order_id).plan.destination == "12"
    stopped = plan_state(
        cancelling.plan,
        update_id=cancelling.update_id,
        passed=end,
        released_end=end,
        actions={**_all(cancelling, ActionStatus.FINISHED), cancel: ActionStatus.FINISHED},
        node_states=[],
        edge_states=[],
    )
    _report(service, stopped)
    ended = _track(service, created.order_id)
    assert ended.status is OrderStatus.CANCELLED
    assert ended.plan.destination == "12"
    assert len(publisher.orders()) == sent


def test_r51_a_stitching_node_s_actions_listed_again_or_twice_are_a_rerun() -> None:
    """R51: the actions of an update's stitching node are neither run again nor listed twice;
    the pure judgement master control uses after each update stitched at a stop."""
    done = frozenset({"p1", "p2"})

    def listed(*pairs: tuple[str, ActionStatus]) -> State:
        states = [{"action_id": i, "action_status": s} for i, s in pairs]
        return make_state(action_states=states)

    assert (
        reran_actions(done, listed(("p1", ActionStatus.FINISHED), ("d1", ActionStatus.WAITING)))
        == ()
    )
    assert reran_actions(done, listed(("p1", ActionStatus.WAITING))) == ("p1",)
    twice = listed(("p2", ActionStatus.FINISHED), ("p2", ActionStatus.FINISHED))
    assert reran_actions(done, twice) == ("p2",)
