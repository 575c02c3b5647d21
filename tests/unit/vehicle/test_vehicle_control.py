"""The control API of simulated vehicles (``--control-port``): operator events set over HTTP
reach the vehicle's state as a real stack's reports would (R104, R105)."""

from __future__ import annotations

import asyncio

import httpx
import pytest

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.errors import ConfigError
from vda5050.testing import make_order, make_order_v3
from vda5050.topics import Topic
from vda_vehicle.control import ControlServer, check_control_exposure, create_control_app
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.runtime3 import VehicleRuntimeV3
from vda_vehicle.testing import Recorder, make_runtime, make_runtime_v3

ORDER_TOPIC = "uagv/v2/acme/robot_0/order"
LINE = [(0.0, 0.0), (10.0, 0.0)]
JSON = {"content-type": "application/json"}


def _client(runtime: VehicleRuntime, key: str | None = None) -> httpx.AsyncClient:
    app = create_control_app([runtime], key=key)
    return httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://vehicle")


def _driving() -> tuple[VehicleRuntime, Recorder, FakeClock]:
    clock = FakeClock()
    runtime, sent = make_runtime(clock)
    runtime.handle_order(ORDER_TOPIC, encode(make_order(["a", "b", "c"])))
    clock.advance(1.0)
    runtime.tick(1.0, clock.monotonic())
    return runtime, sent, clock


async def test_manual_over_http_clears_the_order_and_the_state_says_so() -> None:
    """PATCH operatingMode MANUAL: the answer shows the vehicle in MANUAL, and the state it
    publishes has the order cleared where it stands (orderId kept, nodeStates empty)."""
    runtime, sent, _ = _driving()
    async with _client(runtime) as client:
        response = await client.patch("/vehicles/robot_0/status", json={"operatingMode": "MANUAL"})
    assert response.status_code == 200, response.text
    assert response.json() == {
        "serialNumber": "robot_0",
        "operatingMode": "MANUAL",
        "eStop": "NONE",
        "fieldViolation": False,
        "orderId": "order-1",
        "lastNodeId": "a",
        "driving": False,
        "x": runtime.state.pose.x,
        "y": 0.0,
        "theta": 0.0,
        "mapId": "map",
    }
    state = sent.of(Topic.STATE)[-1]
    assert state["operatingMode"] == "MANUAL"
    assert (state["nodeStates"], state["orderId"]) == ([], "order-1")


async def test_fields_left_out_keep_their_value() -> None:
    """An e-stop set, then a field violation: the e-stop stays; eStop NONE releases it."""
    runtime, sent, clock = _driving()
    async with _client(runtime) as client:
        await client.patch("/vehicles/robot_0/status", json={"eStop": "REMOTE"})
        clock.advance(1.0)
        both = await client.patch("/vehicles/robot_0/status", json={"fieldViolation": True})
        assert (both.json()["eStop"], both.json()["fieldViolation"]) == ("REMOTE", True)
        assert sent.of(Topic.STATE)[-1]["safetyState"] == {
            "eStop": "REMOTE",
            "fieldViolation": True,
        }
        clock.advance(1.0)
        released = await client.patch("/vehicles/robot_0/status", json={"eStop": "NONE"})
        assert released.json()["eStop"] == "NONE"
        listed = await client.get("/vehicles")
    assert [v["serialNumber"] for v in listed.json()] == ["robot_0"]
    assert listed.json()[0]["fieldViolation"] is True


async def test_3_0_modes_in_either_spelling() -> None:
    """A 3.0 vehicle takes INTERVENED (its order kept) and TEACH_IN; a 2.x vehicle reports
    INTERVENED as MANUAL, the nearest 2.x mode (vda_vehicle.vehicle_status)."""
    clock = FakeClock()
    runtime3, sent3 = make_runtime_v3(clock)
    runtime3.handle_order(
        "vda5050/v3/acme/robot_0/order", encode(make_order_v3(["a", "b"], positions=LINE))
    )
    runtime2, _, _ = _driving()
    async with _client(runtime3) as client3, _client(runtime2) as client2:
        intervened = await client3.patch(
            "/vehicles/robot_0/status", json={"operatingMode": "INTERVENED"}
        )
        assert intervened.json()["operatingMode"] == "INTERVENED"
        assert sent3.of(Topic.STATE)[-1]["nodeStates"] != []
        clock.advance(1.0)  # minStateInterval (R94)
        teach = await client3.patch("/vehicles/robot_0/status", json={"operatingMode": "TEACH_IN"})
        assert teach.json()["operatingMode"] == "TEACHIN"
        assert sent3.of(Topic.STATE)[-1]["operatingMode"] == "TEACH_IN"
        manual = await client2.patch(
            "/vehicles/robot_0/status", json={"operatingMode": "INTERVENED"}
        )
        assert (manual.json()["operatingMode"], manual.json()["lastNodeId"]) == ("MANUAL", "a")


async def test_bad_requests_say_what_is_wrong() -> None:
    """An unknown vehicle is a 404 naming it; an unknown mode or field a 422 naming the field;
    nothing changes."""
    runtime, _, _ = _driving()
    async with _client(runtime) as client:
        unknown = await client.patch("/vehicles/robot_9/status", json={"eStop": "REMOTE"})
        assert unknown.status_code == 404
        assert "robot_9" in unknown.json()["detail"]
        bad = await client.patch("/vehicles/robot_0/status", json={"operatingMode": "FLYING"})
        assert bad.status_code == 422
        assert bad.json()["detail"][0]["loc"][-1] == "operatingMode"
        extra = await client.patch("/vehicles/robot_0/status", json={"speed": 3})
        assert extra.status_code == 422
    assert runtime.state.operating_mode.value == "AUTOMATIC"
    assert runtime.state.nodes


async def test_a_key_is_required_when_configured() -> None:
    """With control_key, requests without the bearer key get a 401 and change nothing."""
    runtime, _, _ = _driving()
    async with _client(runtime, key="s3cret") as client:
        denied = await client.patch("/vehicles/robot_0/status", json={"operatingMode": "MANUAL"})
        assert denied.status_code == 401
        assert runtime.state.operating_mode.value == "AUTOMATIC"
        allowed = await client.patch(
            "/vehicles/robot_0/status",
            json={"operatingMode": "MANUAL"},
            headers={"Authorization": "Bearer s3cret"},
        )
        assert allowed.status_code == 200


def test_no_key_less_control_api_beyond_loopback() -> None:
    """Secure by default: another address needs control_key."""
    check_control_exposure("127.0.0.1", None)
    check_control_exposure("0.0.0.0", "k")  # noqa: S104 - the address under test
    with pytest.raises(ConfigError, match="without a key"):
        check_control_exposure("0.0.0.0", None)  # noqa: S104 - the address under test


async def test_the_server_listens_and_closes() -> None:
    """Served by uvicorn on the running loop, on a free port; close() ends it."""
    runtime, _, _ = _driving()
    server = ControlServer([runtime], host="127.0.0.1", port=0, key=None)
    task = asyncio.create_task(server.serve())
    async with asyncio.timeout(5):
        while server.port is None:
            await asyncio.sleep(0.01)
    async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{server.port}") as client:
        response = await client.get("/vehicles/robot_0")
    assert response.json()["orderId"] == "order-1"
    server.close()
    async with asyncio.timeout(5):
        await task


def _at_node_a_v3() -> tuple[VehicleRuntimeV3, Recorder, FakeClock]:
    """A 3.0 vehicle that finished a one-node order at node a, (0, 0)."""
    clock = FakeClock()
    runtime, sent = make_runtime_v3(clock)
    order = make_order_v3(["a"], positions=[(0.0, 0.0)])
    runtime.handle_order("vda5050/v3/acme/robot_0/order", encode(order))
    clock.advance(1.0)
    runtime.tick(1.0, clock.monotonic())
    assert runtime.state.last_node_id == "a"
    return runtime, sent, clock


async def test_an_operator_moves_a_vehicle_by_hand_only_in_manual() -> None:
    """PUT pose: refused (409, naming the mode) in AUTOMATIC; in MANUAL the vehicle stands
    where it was pushed, heading kept unless given, and its visualization says so. A 2.x
    vehicle keeps lastNodeId (2.x has no rule for it)."""
    runtime, sent, clock = _driving()
    async with _client(runtime) as client:
        refused = await client.put("/vehicles/robot_0/pose", json={"x": 3.0, "y": 2.0})
        assert refused.status_code == 409
        assert "operatingMode is AUTOMATIC" in refused.json()["detail"]
        await client.patch("/vehicles/robot_0/status", json={"operatingMode": "MANUAL"})
        moved = await client.put("/vehicles/robot_0/pose", json={"x": 3.0, "y": 2.0})
        assert moved.status_code == 200, moved.text
        assert (moved.json()["x"], moved.json()["y"], moved.json()["theta"]) == (3.0, 2.0, 0.0)
        assert moved.json()["lastNodeId"] == "a"
        turned = await client.put("/vehicles/robot_0/pose", json={"x": 3.0, "y": 2.0, "theta": 1})
        assert turned.json()["theta"] == 1.0
        nan = b'{"x": NaN, "y": 0}'
        bad = await client.put("/vehicles/robot_0/pose", content=nan, headers=JSON)
        assert bad.status_code == 422
        assert bad.json()["detail"][0]["loc"][-1] == "x"
    clock.advance(1.0)
    runtime.tick(1.0, clock.monotonic())
    position = sent.of(Topic.VISUALIZATION)[-1]["agvPosition"]
    assert isinstance(position, dict)
    assert (position["x"], position["y"]) == (3.0, 2.0)


async def test_a_3_0_vehicle_moved_away_in_manual_forgets_its_last_node() -> None:
    """3.0 Table 10 (T62): in MANUAL, a robot moved where lastNodeId can no longer start an
    order reports lastNodeId "" (moved within its deviation, it keeps it), and keeps reporting
    it after AUTOMATIC comes back, until it reaches a node again."""
    runtime, sent, clock = _at_node_a_v3()
    async with _client(runtime) as client:
        await client.patch("/vehicles/robot_0/status", json={"operatingMode": "MANUAL"})
        nudged = await client.put("/vehicles/robot_0/pose", json={"x": 0.1, "y": 0.0})
        assert nudged.json()["lastNodeId"] == "a"
        clock.advance(1.0)
        pushed = await client.put("/vehicles/robot_0/pose", json={"x": 3.0, "y": 0.0})
        assert pushed.json()["lastNodeId"] == ""
        assert sent.of(Topic.STATE)[-1]["lastNodeId"] == ""
        clock.advance(1.0)
        back = await client.patch("/vehicles/robot_0/status", json={"operatingMode": "AUTOMATIC"})
    assert back.json()["lastNodeId"] == ""
    assert sent.of(Topic.STATE)[-1]["lastNodeId"] == ""
