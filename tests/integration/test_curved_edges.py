"""A curved edge end to end: master control sends the graph's NURBS trajectory to a simulated
vehicle whose factsheet lists it (§6.6.6, R112), and the vehicle drives along the curve, not
the chord, to the end node; the order finishes, and ``vda-inspect`` finds nothing against the
standard in the traffic."""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from tests.integration.master_helpers import (
    SIMULATED_BODY,
    master_with_simulated_vehicle,
    order_status,
)
from tests.system.stack import capturing
from vda_master.graph import build_graph
from vda_master.testing import quarter_circle

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration

RADIUS = 6.0
#: A quarter circle round the origin from a (6, 0) to b (0, 6): a rational degree 2 NURBS.
GRAPH = {
    "mapId": "hall",
    "nodes": [
        {"nodeId": "a", "x": RADIUS, "y": 0.0, "theta": math.pi / 2},
        {"nodeId": "b", "x": 0.0, "y": RADIUS},
    ],
    "edges": [
        {
            "edgeId": "ab",
            "startNodeId": "a",
            "endNodeId": "b",
            "trajectory": quarter_circle(RADIUS),
        },
        {"edgeId": "ba", "startNodeId": "b", "endNodeId": "a"},
    ],
}


async def test_the_vehicle_drives_the_graphs_curve_to_the_end_node(
    embedded_broker: BrokerAddress, unique_interface_name: str, tmp_path: Path
) -> None:
    path = tmp_path / "hall.json"
    path.write_text(json.dumps(GRAPH), encoding="utf-8")
    async with (
        capturing(embedded_broker, unique_interface_name) as captured,
        master_with_simulated_vehicle(
            embedded_broker,
            unique_interface_name,
            graph=str(path),
            start_node="a",
            map_id="hall",
            master_graph=build_graph(GRAPH, source=str(path)),
        ) as (_, vehicle, client),
    ):
        created = await client.post("/orders", json={**SIMULATED_BODY, "destination": "b"})
        assert created.status_code == 201, created.text
        (sent,) = created.json()["order"]["edges"]
        assert sent["trajectory"]["degree"] == 2
        assert sent["length"] == pytest.approx(math.pi * RADIUS / 2, rel=1e-3)

        runtime = vehicle.runtimes[0]
        radii = []
        async with asyncio.timeout(15):
            while await order_status(client, created.json()["orderId"]) != "FINISHED":
                pose = runtime.state.pose
                radii.append(math.hypot(pose.x, pose.y))
                await asyncio.sleep(0.01)
        end = runtime.state.pose
        assert (end.x, end.y) == pytest.approx((0.0, RADIUS), abs=1e-6)
        # Every pose on the way lay on the arc (the chord passes 1.76 m inside it).
        assert len(radii) > 20
        assert max(abs(r - RADIUS) for r in radii) < 0.02
        await asyncio.sleep(0.3)  # the last states reach the listener
    # vda-inspect, listening, finds nothing against the standard (§6.6.6 trajectories included).
    assert any(str(m.topic).endswith("/order") for m in captured.messages)
    assert captured.inspect_violations() == []
