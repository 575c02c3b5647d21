"""Zones added and removed while master control runs (``POST /zones``, ``DELETE /zones/{id}``;
docs/master.md, Zones), in one process on SQLite with hand-made states: running orders are
re-routed, stopped or re-planned with the new speeds, the zones survive a restart, and the API
says what is wrong with a zone it refuses."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import httpx
import pytest

from tests.integration.service_on_store import (
    AGV,
    cancel_ids,
    drive,
    in_process_api,
    journaled,
    online,
    report,
    stop_after_cancel,
)
from vda5050.graph_file import GraphZone
from vda5050.models import ActionStatus
from vda_master.dispatcher import OrderStatus
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError
from vda_master.testing import demo_graph, demo_graph_with_zones, zone

pytestmark = pytest.mark.integration

#: Round node 10 of the demo warehouse, on aisle A's way from node 2 to node 3.
AROUND_10 = [[13.0, -1.5], [17.0, -1.5], [17.0, 1.5], [13.0, 1.5]]


def _zone(zone_id: str, zone_type: str, vertices: list[list[float]], **more: object) -> GraphZone:
    return GraphZone.model_validate(zone(zone_id, zone_type, vertices, **more))


async def test_a_zone_added_ahead_of_a_running_order_sends_it_round(tmp_path: Path) -> None:
    """robot_0 drives from node 7 along aisle A to node 3, released one node ahead; a BLOCKED
    zone round node 10 comes into force. The order is re-routed from the end of its base (kept,
    R66) round by aisle B, its next update carries the new way, and nothing is cancelled; once
    the zone is lifted, a new order takes aisle A again."""
    async with journaled(tmp_path, graph=demo_graph(), release_window_nodes=1) as (
        service,
        publisher,
        _,
        _,
    ):
        online(service, node="7")
        track = service.create_order(OrderRequest(Target(destination="3"), AGV))
        order_id = track.order_id
        assert [n.node_id for n in track.plan.nodes] == ["7", "1", "2", "10", "3"]
        await service.committed(order_id)
        drive(service, order_id, passed=0)
        released = service.tracks[order_id].released_end
        assert released < 2  # the edge 2 -> 10 is not released yet

        await service.add_zone(_zone("spill", "BLOCKED", AROUND_10))
        nodes = [n.node_id for n in service.tracks[order_id].plan.nodes]
        assert nodes[: released + 1] == ["7", "1", "2"][: released + 1]
        assert "10" not in nodes
        assert nodes[-1] == "3"
        await service.committed(order_id)
        drive(service, order_id, passed=released)  # at the base's end: the window slides on
        update = publisher.orders()[-1]
        assert update["nodes"][0]["nodeId"] == nodes[released]  # stitched at the base's end
        assert "10" not in [n["nodeId"] for n in update["nodes"]]
        assert cancel_ids(publisher) == []

        while service.tracks[order_id].released_end < service.tracks[order_id].plan.last_index:
            await service.committed(order_id)
            drive(service, order_id, passed=service.tracks[order_id].released_end)
        plan = service.tracks[order_id].plan
        done = dict.fromkeys(plan.action_ids(), ActionStatus.FINISHED)
        drive(service, order_id, passed=plan.last_index, actions=done)
        assert service.tracks[order_id].status is OrderStatus.FINISHED

        await service.remove_zone("spill")
        report(service, last_node_id="7")
        again = service.create_order(OrderRequest(Target(destination="3"), AGV))
        assert [n.node_id for n in again.plan.nodes] == ["7", "1", "2", "10", "3"]


@pytest.mark.parametrize("traffic_control", [False, True])
async def test_a_zone_over_the_released_base_stops_the_order_which_fails_saying_why(
    tmp_path: Path, traffic_control: bool
) -> None:
    """robot_0 drives from n0 to n11 on a line, released up to n5; a BLOCKED zone comes into
    force round n4, inside what the vehicle may already drive. Master control cancels the order
    on the vehicle (it stops at its next node) and releases nothing more; once the vehicle
    confirms the cancel, the order ends FAILED naming the zone."""
    async with journaled(tmp_path, traffic_control=traffic_control) as (service, publisher, _, _):
        online(service)
        order_id = service.create_order(OrderRequest(Target(destination="n11"), AGV)).order_id
        await service.committed(order_id)
        drive(service, order_id, passed=2)
        assert service.tracks[order_id].released_end >= 5  # all of it with traffic control
        sent = len(publisher.orders())

        await service.add_zone(_zone("spill", "BLOCKED", [[7.5, -1.0], [8.5, -1.0], [8.0, 1.0]]))
        (cancel,) = cancel_ids(publisher)
        drive(service, order_id, passed=3)
        assert len(publisher.orders()) == sent  # nothing more released

        stop_after_cancel(service, order_id, cancel, passed=3)
        ended = service.tracks[order_id]
    assert ended.status is OrderStatus.FAILED
    assert "edge 'e3' enters BLOCKED zone 'spill'" in ended.reason


async def test_an_order_to_a_node_a_new_zone_holds_is_stopped(tmp_path: Path) -> None:
    """The destination itself comes to lie in a BLOCKED zone: no way leads there any more, and
    the reason says so."""
    async with journaled(tmp_path, release_window_nodes=1) as (service, publisher, _, _):
        online(service)
        order_id = service.create_order(OrderRequest(Target(destination="n11"), AGV)).order_id
        await service.committed(order_id)
        drive(service, order_id, passed=0)
        await service.add_zone(_zone("spill", "BLOCKED", [[21.5, -1.0], [22.5, -1.0], [22.0, 1.0]]))
        assert len(cancel_ids(publisher)) == 1
        assert service.tracks[order_id].cancel_reason == (
            "master control stopped it: its destination 'n11' lies in BLOCKED zone 'spill' "
            "(the graph changed since the order was planned)"
        )


async def test_a_speed_limit_added_reaches_the_next_release_only(tmp_path: Path) -> None:
    """A SPEED_LIMIT zone of 0.3 m/s comes into force over n7-n9 while robot_0 drives n0 -> n11
    released up to n5: the released edges keep what they were sent with (R66); the next update
    carries 0.3 m/s on the edges touching the zone."""
    async with journaled(tmp_path) as (service, publisher, _, _):
        online(service)
        order_id = service.create_order(OrderRequest(Target(destination="n11"), AGV)).order_id
        await service.committed(order_id)
        drive(service, order_id, passed=2)
        first_speeds = {e["edgeId"]: e.get("maxSpeed") for e in publisher.orders()[-1]["edges"]}

        slow = [[13.5, -1.0], [18.5, -1.0], [18.5, 1.0], [13.5, 1.0]]
        await service.add_zone(_zone("works", "SPEED_LIMIT", slow, maximumSpeed=0.3))
        drive(service, order_id, passed=5)  # confirms the update in flight: re-planned now
        await service.committed(order_id)  # the new plan is written ahead of its messages
        update = publisher.orders()[-1]
        speeds = {e["edgeId"]: e.get("maxSpeed") for e in update["edges"]}
        assert {speeds[e] for e in ("e6", "e7", "e8", "e9") if e in speeds} == {0.3}
        assert speeds.get("e5") == first_speeds.get("e5")  # n5 -> n6 lies outside


async def test_zones_added_are_kept_across_a_restart_until_lifted(tmp_path: Path) -> None:
    """A zone added (and changed) in one run is in force in the next, as changed (before any
    order is recovered); lifted there, it is gone in the run after."""
    async with journaled(tmp_path, graph=demo_graph()) as (service, _, _, _):
        await service.add_zone(_zone("spill", "BLOCKED", AROUND_10, description="oil"))
        grown = [[8.0, -1.5], [17.0, -1.5], [17.0, 1.5], [8.0, 1.5]]
        await service.replace_zone(_zone("spill", "BLOCKED", grown, description="oil, spreading"))

    async with journaled(tmp_path, graph=demo_graph()) as (service, _, store, _):
        await service.resume_from(store)
        assert [(z.zone_id, z.description) for z in service.runtime_zones()] == [
            ("spill", "oil, spreading")
        ]
        assert set(service.graph.blocked_nodes) == {"2", "10"}
        online(service, node="7")
        with pytest.raises(RequestError, match="node '10' lies in BLOCKED zone 'spill'"):
            service.create_order(OrderRequest(Target(destination="10"), AGV))
        await service.remove_zone("spill")

    async with journaled(tmp_path, graph=demo_graph()) as (service, _, store, _):
        await service.resume_from(store)
        assert service.runtime_zones() == ()
        assert service.graph.blocked_nodes == {}


FILE_ZONE = zone("file", "SPEED_LIMIT", AROUND_10, maximumSpeed=0.5)
SPILL = zone("spill", "BLOCKED", AROUND_10)


@asynccontextmanager
async def _api(tmp_path: Path) -> AsyncIterator[httpx.AsyncClient]:
    """The master's API in process, on the demo graph with a SPEED_LIMIT zone ``file``."""
    graph = demo_graph_with_zones(FILE_ZONE)
    async with (
        journaled(tmp_path, graph=graph) as (service, _, _, _),
        in_process_api(service) as client,
    ):
        yield client


async def test_the_api_adds_lists_and_lifts_zones_and_says_what_it_refuses(
    tmp_path: Path,
) -> None:
    """POST /zones answers 201 with what the zone does; a zoneId in use, a zone the graph file
    defines, an unknown one, a SPEED_LIMIT without speed, a crossing polygon and an unknown key
    are refused, each saying why."""
    async with _api(tmp_path) as client:
        added = await client.post("/zones", json=SPILL)
        assert added.status_code == 201, added.text
        body = added.json()
        assert body["source"] == "api"
        assert body["nodesInside"] == ["10"]
        assert set(body["closedEdges"]) == {"11", "21", "45"}

        listed = (await client.get("/zones")).json()
        assert [(z["zoneId"], z["source"]) for z in listed] == [
            ("file", "graph file"),
            ("spill", "api"),
        ]
        again = await client.post("/zones", json=SPILL)
        assert again.status_code == 409
        assert again.json()["detail"] == ("zone 'spill' is in force already: delete it first")
        no_speed = await client.post("/zones", json=zone("z", "SPEED_LIMIT", AROUND_10))
        assert no_speed.status_code == 422
        assert "a SPEED_LIMIT zone needs maximumSpeed" in no_speed.json()["detail"]
        bow_tie = zone("bow", "BLOCKED", [[13.0, -1.5], [17.0, 1.5], [17.0, -1.5], [13.0, 1.5]])
        crossed = await client.post("/zones", json=bow_tie)
        assert crossed.status_code == 422
        assert crossed.json()["detail"] == (
            "zone 'bow': its sides 1 and 3 cross; a zone is a simple polygon"
        )
        unknown_key = await client.post("/zones", json={**SPILL, "zoneId": "x", "colour": 1})
        assert unknown_key.status_code == 422
        assert "colour" in unknown_key.text

        file_zone = await client.delete("/zones/file")
        assert file_zone.status_code == 409
        assert "defined in the graph file" in file_zone.json()["detail"]
        assert (await client.delete("/zones/nope")).status_code == 404
        lifted = await client.delete("/zones/spill")
        assert lifted.status_code == 204
        assert [z["zoneId"] for z in (await client.get("/zones")).json()] == ["file"]


async def test_a_zone_is_shown_and_changed_by_its_id(tmp_path: Path) -> None:
    """GET and PUT /zones/{zoneId} (a zoneId with a slash too): a spill that grew is changed
    in one step; a body naming another zone, one of the file's and an unknown one are
    refused."""
    async with _api(tmp_path) as client:
        await client.post("/zones", json=SPILL)
        one = await client.get("/zones/spill")
        assert (one.status_code, one.json()["zoneId"]) == (200, "spill")
        assert (await client.get("/zones/nope")).status_code == 404
        grown = zone("spill", "BLOCKED", [[8.0, -1.5], [17.0, -1.5], [17.0, 1.5], [8.0, 1.5]])
        changed = await client.put("/zones/spill", json=grown)
        assert changed.status_code == 200, changed.text
        assert changed.json()["nodesInside"] == ["10", "2"]
        assert (await client.get("/zones/spill")).json()["nodesInside"] == ["10", "2"]
        mismatch = await client.put("/zones/other", json=grown)
        assert mismatch.status_code == 422
        assert mismatch.json()["detail"] == "the body's zoneId 'spill' is not the path's 'other'"
        file_change = await client.put("/zones/file", json={**grown, "zoneId": "file"})
        assert file_change.status_code == 409
        unknown = await client.put("/zones/new", json={**grown, "zoneId": "new"})
        assert unknown.status_code == 404

        slash = zone("aisle C/north", "BLOCKED", [[0.0, 9.0], [1.0, 9.0], [1.0, 10.0]])
        assert (await client.post("/zones", json=slash)).status_code == 201
        named = await client.get("/zones/aisle C/north")
        assert named.json()["zoneId"] == "aisle C/north"
        assert (await client.delete("/zones/aisle C/north")).status_code == 204
