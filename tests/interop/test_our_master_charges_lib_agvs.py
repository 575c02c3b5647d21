"""Our master control's energy management (docs/master.md, *Charging*) with a vda-5050-lib
1.4.0 virtual AGV: a low AGV is sent to the charger with startCharging as a node action, its
charge is ended with the instant action stopCharging at charged_pct, and it takes orders
again (VDA 5050 §6.8.2, R77: the AGV's charging flag follows both actions). The AGV speaks
2.0.0 without a factsheet; everything both sides publish is checked against the official
schemas by the ``wire`` fixture."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.interop.node_lib import NodeRuntime
from tests.interop.peers import matching, running_agvs
from tests.interop.services import GRAPH, pose_at, running_our_master
from tests.interop.wire import Side
from tests.mosquitto import Mosquitto
from tests.system.stack import Captured

pytestmark = pytest.mark.interop
OUR_SIDE = Side.MASTER
MANUFACTURER = "vdalib"


def _graph_with_charger(folder: Path) -> Path:
    """The interop graph with node n2 (10 m east of n1) as a charging station."""
    document = json.loads(GRAPH.read_text())
    for node in document["nodes"]:
        if node["nodeId"] == "n2":
            node["stationType"] = "charging"
    path = folder / "graph-with-charger.json"
    path.write_text(json.dumps(document))
    return path


async def test_a_low_lib_agv_is_charged_and_given_orders_again(
    node_runtime: NodeRuntime,
    mosquitto: Mosquitto,
    unique_interface_name: str,
    wire: Captured,
    tmp_path: Path,
) -> None:
    async with (
        running_agvs(
            node_runtime,
            broker_url=mosquitto.address.url,
            interface_name=unique_interface_name,
            manufacturer=MANUFACTURER,
            poses={"agv_1": pose_at("n1")},
            timeLapse=10,
            tickRate=10,
            initialBatteryCharge=20,
            fullBatteryChargeTime=0.05,  # 3 min from empty to full, 18 s at time lapse 10
        ) as agvs,
        running_our_master(
            tmp_path,
            broker_url=mosquitto.address.url,
            interface_name=unique_interface_name,
            graph=_graph_with_charger(tmp_path),
        ) as master,
    ):
        await agvs.wait_for(
            matching("action_state", actionType="startCharging", actionStatus="FINISHED"),
            20.0,
            what="startCharging at n2",
        )
        charging = [
            e for e in agvs.find(matching("state")) if e["state"]["batteryState"]["charging"]
        ]
        assert charging[0]["state"]["lastNodeId"] == "n2"
        await agvs.wait_for(
            matching("action_state", actionType="stopCharging", actionStatus="FINISHED"),
            40.0,
            what="stopCharging from master control",
        )
        stopped = agvs.find(matching("state"))[-1]["state"]["batteryState"]
        assert not stopped["charging"]
        assert 80.0 <= stopped["batteryCharge"] < 100.0  # ours ended it, not a full battery
        await master.wait_available(["agv_1"], timeout=10.0)
        created = await master.order(
            manufacturer=MANUFACTURER, serialNumber="agv_1", destination="n3"
        )
        await master.wait_order(created["orderId"], "FINISHED", timeout=15.0)
