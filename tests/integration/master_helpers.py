"""Running a master against the embedded broker in a test, and talking to its API."""

from __future__ import annotations

import asyncio
import tempfile
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import httpx

from tests.integration.master_vehicle import ScriptedVehicle, running_vehicle
from vda5050.graph_file import GraphFile
from vda5050.topics import AgvId
from vda_master.config import MasterConfig
from vda_master.graph import Graph
from vda_master.runtime import MasterProcess
from vda_master.testing import DEMO_GRAPH, demo_graph
from vda_vehicle.config import VehicleSettings
from vda_vehicle.service import VehicleService

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress


@asynccontextmanager
async def running_master(
    address: BrokerAddress, interface_name: str, **overrides: object
) -> AsyncIterator[MasterProcess]:
    """A master with a fast resend timeout and the API on a free port, stopped afterwards; on
    the demo graph unless ``graph=`` gives another."""
    graph = overrides.pop("graph", None)
    assert graph is None or isinstance(graph, Graph)
    data_dir = tempfile.TemporaryDirectory(prefix="vda-master-")
    settings: dict[str, object] = {
        "broker_url": address.url,
        "interface_name": interface_name,
        "client_id": f"{interface_name}-master",
        "api_port": 0,
        "confirm_timeout_s": 0.3,
        "tick_s": 0.02,
        "data_dir": data_dir.name,
        **overrides,
    }
    process = MasterProcess(MasterConfig.model_validate(settings), graph=graph or demo_graph())  # type: ignore[redundant-expr,unused-ignore]
    stop = asyncio.Event()
    with data_dir:
        async with _serving(process, stop):
            yield process


@asynccontextmanager
async def _serving(process: MasterProcess, stop: asyncio.Event) -> AsyncIterator[None]:
    async with asyncio.TaskGroup() as group:
        group.create_task(process.run(stop), name="test.master")
        try:
            async with asyncio.timeout(5):
                await process.session.wait_connected()
            yield
        finally:
            stop.set()


@asynccontextmanager
async def api_client(process: MasterProcess) -> AsyncIterator[httpx.AsyncClient]:
    """An HTTP client that calls the master's app in-process (no socket)."""
    transport = httpx.ASGITransport(app=process.app)
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
        yield client


async def wait_until(predicate: Callable[[], bool], timeout: float = 5.0) -> None:
    """Poll ``predicate`` every 10 ms until it holds; TimeoutError after ``timeout`` s."""
    async with asyncio.timeout(timeout):
        while not predicate():
            await asyncio.sleep(0.01)


async def order_status(client: httpx.AsyncClient, order_id: str) -> str:
    """The status the API reports for ``order_id``."""
    response = await client.get(f"/orders/{order_id}")
    assert response.status_code == 200, response.text
    status: str = response.json()["status"]
    return status


async def wait_status(
    client: httpx.AsyncClient, order_id: str, wanted: str, timeout: float = 5.0
) -> None:
    """Poll the API until the order reaches ``wanted``."""
    async with asyncio.timeout(timeout):
        while (status := await order_status(client, order_id)) != wanted:
            await asyncio.sleep(0.02)
    assert status == wanted


async def wait_reported(process: MasterProcess, *agvs: AgvId) -> None:
    """Wait until the master's fleet view holds a state of every vehicle in ``agvs``."""

    def reported() -> bool:
        views = [process.service.fleet.get(agv) for agv in agvs]
        return all(view is not None and view.state is not None for view in views)

    await wait_until(reported)


def has_factsheet(process: MasterProcess, agv: AgvId) -> bool:
    """Whether the master holds a valid factsheet of ``agv``."""
    view = process.service.fleet.get(agv)
    return view is not None and view.factsheet is not None


@asynccontextmanager
async def serving(
    vehicle: ScriptedVehicle, address: BrokerAddress, interface_name: str, **overrides: object
) -> AsyncIterator[tuple[MasterProcess, httpx.AsyncClient]]:
    """A master, ``vehicle`` running against it and an API client, once the master holds the
    vehicle's state."""
    async with (
        running_master(address, interface_name, **overrides) as master,
        running_vehicle(vehicle),
        api_client(master) as client,
    ):
        await wait_reported(master, vehicle.agv)
        yield master, client


#: The simulated vehicle of :func:`simulated_vehicle`, and its identity in API requests.
SIMULATED = AgvId("acme", "r1")
SIMULATED_BODY = {"manufacturer": "acme", "serialNumber": "r1"}


@asynccontextmanager
async def simulated_vehicle(
    address: BrokerAddress, interface: str, **changes: object
) -> AsyncIterator[VehicleService]:
    """One simulated vehicle ``acme/r1`` on node 7 of the demo graph (time lapse 4), in this
    event loop; ``changes`` override its settings (``graph``: another graph file)."""
    settings = VehicleSettings.model_validate(
        {
            "broker_url": address.url,
            "interface_name": interface,
            "manufacturer": SIMULATED.manufacturer,
            "serial_number": SIMULATED.serial_number,
            "graph": DEMO_GRAPH,
            "start_node": "7",
            "time_lapse": 4.0,
            "tick_hz": 20.0,
            "visualization_interval_s": 0,
            **changes,
        }
    )
    raw = await asyncio.to_thread(Path(str(changes.get("graph", DEMO_GRAPH))).read_bytes)
    graph = GraphFile.model_validate_json(raw)
    service = VehicleService(settings, graph)
    async with asyncio.TaskGroup() as group:
        group.create_task(service.run(), name="test.vehicle")
        try:
            yield service
        finally:
            service.stop()


@asynccontextmanager
async def master_with_simulated_vehicle(
    address: BrokerAddress,
    interface: str,
    *,
    master_graph: Graph | None = None,
    master_settings: dict[str, object] | None = None,
    **vehicle_changes: object,
) -> AsyncIterator[tuple[MasterProcess, VehicleService, httpx.AsyncClient]]:
    """A master (on ``master_graph``, else the demo graph; ``master_settings`` override its
    config), :func:`simulated_vehicle` and an API client, once the master may give the vehicle
    an order."""
    async with (
        running_master(address, interface, graph=master_graph, **(master_settings or {})) as master,
        simulated_vehicle(address, interface, **vehicle_changes) as vehicle,
        api_client(master) as client,
    ):
        await wait_until(lambda: master.service.availability_of(SIMULATED) is None, timeout=5)
        yield master, vehicle, client
