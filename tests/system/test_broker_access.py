"""The stack on a Mosquitto with logins and the ACL of config/mosquitto/make-credentials: it
runs the reference scenario, a vehicle cannot speak for another, a stranger cannot command a
vehicle, and a right the ACL lacks is logged and shown (issue 14, item 5)."""

from __future__ import annotations

import asyncio
import json
import shutil
import subprocess
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import asynccontextmanager, contextmanager
from pathlib import Path
from typing import Any

import aiomqtt
import httpx
import pytest

from tests.integration.mqtt_helpers import Watcher, client_for
from tests.mosquitto import DynsecClient, Mosquitto, run_mosquitto
from tests.system.stack import REPO, Stack
from vda5050.codec import encode
from vda5050.testing import make_order, make_state

pytestmark = pytest.mark.mosquitto

MAKE_CREDENTIALS = REPO / "config" / "mosquitto" / "make-credentials"
USERS = ("vda-master", "observer", "robot_0", "robot_1")
IDENTITY: dict[str, Any] = {"manufacturer": "vda-sim", "serial_number": "robot_0"}


def login(broker: Mosquitto, user: str) -> str:
    """The broker URL with ``user``'s login (every test password is ``pw-<user>``)."""
    return f"mqtt://{user}:pw-{user}@{broker.address.host}:{broker.address.port}"


@contextmanager
def secured_mosquitto(
    directory: Path, interface: str, edit: Callable[[str], str] = lambda acl: acl
) -> Iterator[Mosquitto]:
    """Mosquitto with the password file and ACL make-credentials writes for the master, an
    observer and robot_0/robot_1 of vda-sim, plus a login 'intruder' the ACL names nowhere;
    ``edit`` changes the ACL first."""
    files = directory / "credentials"
    subprocess.run(  # noqa: S603 - the repository's own script
        [
            str(MAKE_CREDENTIALS),
            "--out",
            str(files),
            "--interface",
            interface,
            "--master",
            "vda-master:pw-vda-master",
            "--observer",
            "observer:pw-observer",
            "--vehicle",
            "vda-sim/robot_0:pw-robot_0",
            "--vehicle",
            "vda-sim/robot_1:pw-robot_1",
        ],
        check=True,
        capture_output=True,
    )
    subprocess.run(  # noqa: S603 - mosquitto_passwd on our own file
        [
            shutil.which("mosquitto_passwd") or "mosquitto_passwd",
            "-b",
            str(files / "passwords"),
            "intruder",
            "pw-intruder",
        ],
        check=True,
        capture_output=True,
    )
    acl = files / "acl"
    acl.write_text(edit(acl.read_text()))
    with run_mosquitto(
        directory / "mosquitto", password_file=files / "passwords", acl_file=acl
    ) as broker:
        yield broker


@asynccontextmanager
async def observing(
    broker: Mosquitto, interface: str, user: str = "observer"
) -> AsyncIterator[Watcher]:
    """Everything the broker delivers on ``<interface>/#`` to a read-only login."""
    async with client_for(broker.address, username=user, password=f"pw-{user}") as client:
        watcher = Watcher(client)
        await client.subscribe(f"{interface}/#", qos=1)

        async def collect() -> None:
            async for message in client.messages:
                watcher.messages.append(message)
                watcher.arrived.set()

        async with asyncio.TaskGroup() as group:
            task = group.create_task(collect(), name="test.observe")
            try:
                yield watcher
            finally:
                task.cancel()


async def publish_as(broker: Mosquitto, user: str, topic: str, payload: bytes) -> None:
    """One QoS 1 publication by ``user`` (Mosquitto acknowledges even a refused one)."""
    async with client_for(broker.address, username=user, password=f"pw-{user}") as client:
        await client.publish(topic, payload, qos=1)


def payloads(watcher: Watcher, topic: str) -> list[dict[str, object]]:
    return [json.loads(m.payload) for m in watcher.on(topic)]


async def test_reference_scenario_on_password_and_acl_mosquitto(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """With one login per service and the generated ACL, POST /orders over 17, 12, 11 for
    robot_0 FINISHES and nobody reports a refused subscription or publication."""
    with secured_mosquitto(tmp_path, unique_interface_name) as broker:
        stack = Stack(broker, unique_interface_name, tmp_path)
        try:
            stack.start_master(url=login(broker, "vda-master"))
            stack.start_vehicle("robot_0", url=login(broker, "robot_0"))
            async with httpx.AsyncClient(timeout=5) as http:
                await stack.wait_vehicle(http, "robot_0", lambda v: bool(v.get("available")))
                answer = await http.post(
                    f"{stack.api}/orders",
                    json={
                        "manufacturer": "vda-sim",
                        "serialNumber": "robot_0",
                        "route": ["17", "12", "11"],
                    },
                )
                assert answer.status_code == 201, answer.text
                await stack.wait_order(http, answer.json()["orderId"], "FINISHED")
                health = (await http.get(f"{stack.api}/health")).json()
                view = await stack.vehicle(http, "robot_0")
        finally:
            await stack.stop_all()
    assert health["broker"] == {"connected": True, "problems": []}
    assert view["lastNodeId"] == "10"
    assert "_denied" not in stack.logs_text()


async def test_a_vehicle_cannot_publish_another_vehicles_state(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """robot_1's login publishing a state on robot_0's topic is dropped by the broker: neither
    an observer nor the master ever sees it, while robot_0's own states go through."""
    topic = f"{unique_interface_name}/v2/vda-sim/robot_0/state"
    own = encode(make_state(**IDENTITY, header_id=1, last_node_id="7"))
    spoofed = encode(make_state(**IDENTITY, header_id=2, last_node_id="2", order_id="spoofed"))
    after = encode(make_state(**IDENTITY, header_id=3, last_node_id="1"))
    with secured_mosquitto(tmp_path, unique_interface_name) as broker:
        stack = Stack(broker, unique_interface_name, tmp_path)
        try:
            stack.start_master(url=login(broker, "vda-master"))
            async with (
                httpx.AsyncClient(timeout=5) as http,
                observing(broker, unique_interface_name) as observer,
            ):
                await _wait_health(http, stack, lambda h: _broker(h)["connected"])
                await publish_as(broker, "robot_0", topic, own)
                await stack.wait_vehicle(http, "robot_0", lambda v: v["lastNodeId"] == "7")
                await publish_as(broker, "robot_1", topic, spoofed)
                await publish_as(broker, "robot_0", topic, after)  # sent after the spoof
                await stack.wait_vehicle(http, "robot_0", lambda v: v["lastNodeId"] == "1")
                await observer.wait_for(topic, count=2)
                detail = await stack.vehicle(http, "robot_0")
        finally:
            await stack.stop_all()
    assert [p["headerId"] for p in payloads(observer, topic)] == [1, 3]
    assert _errors(detail, "brokerAccessDenied") == []
    assert isinstance(detail["state"], dict)
    assert detail["state"]["headerId"] == 3
    assert "spoofed" not in stack.logs_text()


async def test_a_stranger_cannot_send_orders_to_a_vehicle(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """Anonymous clients are refused; a login the ACL does not name ('intruder') and another
    vehicle's login publish an order to robot_0 that never reaches it, while the same kind of
    order from the master's login is accepted."""
    topic = f"{unique_interface_name}/v2/vda-sim/robot_0/order"
    state_topic = f"{unique_interface_name}/v2/vda-sim/robot_0/state"

    def order(order_id: str) -> bytes:
        return encode(
            make_order(["7"], order_id=order_id, positions=[(0.0, 0.0)], map_id="demo", **IDENTITY)
        )

    with secured_mosquitto(tmp_path, unique_interface_name) as broker:
        stack = Stack(broker, unique_interface_name, tmp_path)
        try:
            with pytest.raises(aiomqtt.MqttError):
                async with client_for(broker.address):
                    pass
            vehicle = stack.start_vehicle("robot_0", url=login(broker, "robot_0"))
            async with observing(broker, unique_interface_name) as observer:
                await observer.wait_for(state_topic)
                await publish_as(broker, "intruder", topic, order("from-intruder"))
                await publish_as(broker, "robot_1", topic, order("from-robot_1"))
                await publish_as(broker, "vda-master", topic, order("from-master"))
                await observer.wait_for(topic)
                await _wait_until(
                    lambda: any(
                        s["orderId"] == "from-master" for s in payloads(observer, state_topic)
                    )
                )
        finally:
            await stack.stop_all()
    assert [p["orderId"] for p in payloads(observer, topic)] == ["from-master"]
    seen_orders = {s["orderId"] for s in payloads(observer, state_topic)}
    assert seen_orders == {"", "from-master"}
    assert "from-intruder" not in vehicle.log()
    assert "from-robot_1" not in vehicle.log()


async def test_missing_rights_are_logged_and_shown(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """An ACL that lets the master only read orders and robot_1 only read its connection: the
    master logs mqtt.publish_denied for robot_0's order topic and /health lists it; robot_1
    logs it for its connection topic and reports a brokerAccessDenied warning in its state.
    (publish_check_s 3: with 1 s a permitted echo delayed by a busy machine was flagged too.)"""
    interface = unique_interface_name
    order_topic = f"{interface}/v2/vda-sim/robot_0/order"
    connection_topic = f"{interface}/v2/vda-sim/robot_1/connection"

    def edit(acl: str) -> str:
        pattern = f"pattern readwrite {interface}/v2/vda-sim/%u/connection"
        acl = acl.replace(
            f"topic readwrite {interface}/v2/+/+/order", f"topic read {interface}/v2/+/+/order"
        )
        acl = acl.replace(pattern, pattern.replace("readwrite", "read"))
        return acl + f"user robot_0\ntopic write {interface}/v2/vda-sim/robot_0/connection\n"

    with secured_mosquitto(tmp_path, interface, edit) as broker:
        stack = Stack(broker, interface, tmp_path)
        try:
            master = stack.start_master("--publish-check-s", "3", url=login(broker, "vda-master"))
            robot_1 = stack.start_vehicle(
                "robot_1", "--publish-check-s", "3", url=login(broker, "robot_1")
            )
            stack.start_vehicle("robot_0", url=login(broker, "robot_0"))
            async with httpx.AsyncClient(timeout=5) as http:
                await stack.wait_vehicle(http, "robot_0", lambda v: bool(v.get("available")))
                answer = await http.post(
                    f"{stack.api}/orders",
                    json={"manufacturer": "vda-sim", "serialNumber": "robot_0", "route": ["17"]},
                )
                assert answer.status_code == 201, answer.text
                robot_1_view = await stack.wait_vehicle(
                    http, "robot_1", lambda v: _errors(v, "brokerAccessDenied")
                )
                health = await _wait_health(http, stack, lambda h: _broker(h)["problems"])
        finally:
            await stack.stop_all()
    (problem,) = _broker(health)["problems"]
    assert (problem["kind"], problem["topic"]) == ("publish_denied", order_topic)
    assert "ACL" in problem["description"]
    assert _broker(health)["connected"] is True
    assert '"event": "mqtt.publish_denied"' in master.log()
    assert order_topic in master.log()
    (warning,) = _errors(robot_1_view, "brokerAccessDenied")
    assert warning["errorLevel"] == "WARNING"
    assert warning["errorReferences"] == [
        {"referenceKey": "topic", "referenceValue": connection_topic}
    ]
    assert '"event": "mqtt.publish_denied"' in robot_1.log()


async def test_refused_subscription_is_logged_and_reported_in_the_state(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """On a broker that answers SUBACK 0x80 (Mosquitto's dynamic-security plugin) for robot_0's
    order topic, the vehicle logs mqtt.subscribe_denied naming it, keeps running, and its
    state carries a brokerAccessDenied warning about that topic."""
    prefix = f"{unique_interface_name}/v2/vda-sim/robot_0"
    robot_0 = DynsecClient(
        "robot_0",
        "pw-robot_0",
        (
            ("publishClientSend", f"{prefix}/#", True),
            ("subscribePattern", f"{prefix}/instantActions", True),
            ("subscribePattern", f"{prefix}/connection", True),
            ("subscribePattern", f"{prefix}/state", True),
        ),
    )
    observer = DynsecClient("observer", "pw-observer", (("subscribePattern", "#", True),))
    with run_mosquitto(tmp_path / "mosquitto", dynsec=[robot_0, observer]) as broker:
        stack = Stack(broker, unique_interface_name, tmp_path)
        try:
            vehicle = stack.start_vehicle("robot_0", url=login(broker, "robot_0"))
            async with observing(broker, unique_interface_name) as watcher:
                await _wait_until(
                    lambda: any(
                        _errors({"state": s}, "brokerAccessDenied")
                        for s in payloads(watcher, f"{prefix}/state")
                    )
                )
                assert vehicle.running
        finally:
            await stack.stop_all()
    state = next(
        s
        for s in payloads(watcher, f"{prefix}/state")
        if _errors({"state": s}, "brokerAccessDenied")
    )
    (warning,) = _errors({"state": state}, "brokerAccessDenied")
    assert warning["errorReferences"] == [
        {"referenceKey": "topic", "referenceValue": f"{prefix}/order"}
    ]
    assert '"event": "mqtt.subscribe_denied"' in vehicle.log()
    assert "SUBACK 0x80" in vehicle.log()


def _errors(view: dict[str, object], error_type: str) -> list[dict[str, object]]:
    state = view.get("state")
    errors = state.get("errors", []) if isinstance(state, dict) else []
    return [e for e in errors if isinstance(e, dict) and e.get("errorType") == error_type]


async def _wait_until(predicate: Callable[[], bool], timeout: float = 10.0) -> None:
    async with asyncio.timeout(timeout):
        while not predicate():
            await asyncio.sleep(0.05)


def _broker(health: dict[str, Any]) -> dict[str, Any]:
    broker: dict[str, Any] = health["broker"]
    return broker


async def _wait_health(
    http: httpx.AsyncClient, stack: Stack, predicate: Callable[[dict[str, Any]], object]
) -> dict[str, Any]:
    async with asyncio.timeout(10):
        while True:
            try:
                health: dict[str, Any] = (await http.get(f"{stack.api}/health")).json()
            except httpx.TransportError:
                health = {"broker": {"connected": False, "problems": []}}
            if predicate(health):
                return health
            await asyncio.sleep(0.1)
