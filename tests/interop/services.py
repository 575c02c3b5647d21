"""Our services as processes for the interoperability tests, on the interop graph.

``running_our_master`` starts ``python -m vda_master`` with a config file written for the test
(graph ``graph.json``, no robots listed: vehicles are found through their retained connection
topic) and gives an HTTP client for its API. ``running_our_vehicle`` starts
``python -m vda_vehicle`` speaking 2.0.0. Every wait is bounded; failures quote the order's
reason or the service's log.
"""

from __future__ import annotations

import asyncio
import functools
import json
import math
import time
from collections.abc import AsyncIterator, Iterable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from tests.interop.peers import StartPose
from tests.mosquitto import free_port
from tests.system.stack import ServiceProcess

GRAPH = Path(__file__).resolve().parent / "graph.json"
TERMINAL = frozenset({"FINISHED", "FAILED", "REJECTED", "CANCELLED"})


@functools.cache
def graph_nodes() -> dict[str, tuple[float, float]]:
    """nodeId -> (x, y) of the interop graph."""
    document = json.loads(GRAPH.read_text())
    return {n["nodeId"]: (n["x"], n["y"]) for n in document["nodes"]}


def map_id() -> str:
    return str(json.loads(GRAPH.read_text())["mapId"])


def pose_at(node_id: str, theta: float = 0.0) -> StartPose:
    """A start pose exactly on ``node_id``."""
    x, y = graph_nodes()[node_id]
    return StartPose(x, y, theta, map_id(), node_id)


def distance_to_nearest_node(x: float, y: float) -> float:
    return min(math.hypot(x - nx, y - ny) for nx, ny in graph_nodes().values())


def log_tail(service: ServiceProcess, chars: int = 4000) -> str:
    return f"\n--- last lines of {service.name}'s log:\n{service.log()[-chars:]}"


@dataclass
class OurMaster:
    """``python -m vda_master`` and an HTTP client for its API."""

    service: ServiceProcess
    api: str
    http: httpx.AsyncClient
    started_at: float

    async def vehicles(self) -> list[dict[str, Any]]:
        answer = await self.http.get(f"{self.api}/vehicles")
        answer.raise_for_status()
        return list(answer.json())

    async def wait_available(self, serials: Iterable[str], timeout: float) -> float:
        """Seconds from the master's start until every vehicle in ``serials`` is available."""
        wanted = set(serials)
        seen: list[dict[str, Any]] = []
        try:
            async with asyncio.timeout(timeout):
                while True:
                    self._check_running()
                    try:
                        seen = await self.vehicles()
                    except httpx.TransportError:
                        seen = []  # the API is not up yet
                    available = {v["serialNumber"] for v in seen if v["available"]}
                    if wanted <= available:
                        return time.monotonic() - self.started_at
                    await asyncio.sleep(0.05)
        except TimeoutError:
            views = [
                {k: v.get(k) for k in ("serialNumber", "available", "unavailableReason")}
                for v in seen
            ]
            msg = f"not all of {sorted(wanted)} available within {timeout} s: GET /vehicles {views}"
            raise AssertionError(msg + log_tail(self.service)) from None

    async def order(self, **body: object) -> dict[str, Any]:
        """``POST /orders``; the 201 answer, else AssertionError with the API's detail."""
        answer = await self.http.post(f"{self.api}/orders", json=body)
        if answer.status_code != 201:
            msg = f"POST /orders {body} answered {answer.status_code}: {answer.text}"
            raise AssertionError(msg + log_tail(self.service))
        return dict(answer.json())

    async def cancel(self, order_id: str) -> dict[str, Any]:
        answer = await self.http.delete(f"{self.api}/orders/{order_id}")
        if answer.status_code != 202:
            msg = f"DELETE /orders/{order_id} answered {answer.status_code}: {answer.text}"
            raise AssertionError(msg + log_tail(self.service))
        return dict(answer.json())

    async def wait_order(self, order_id: str, status: str, timeout: float = 15.0) -> dict[str, Any]:
        """The order once it has ``status``; AssertionError at once if it ends otherwise."""
        info: dict[str, Any] = {}
        try:
            async with asyncio.timeout(timeout):
                while True:
                    answer = await self.http.get(f"{self.api}/orders/{order_id}")
                    info = dict(answer.json())
                    if info.get("status") == status:
                        return info
                    if info.get("status") in TERMINAL:
                        msg = f"order {order_id} ended {info['status']}, not {status}: {info}"
                        raise AssertionError(msg + log_tail(self.service))
                    await asyncio.sleep(0.05)
        except TimeoutError:
            msg = f"order {order_id} not {status} within {timeout} s, last seen: {info}"
            raise AssertionError(msg + log_tail(self.service)) from None

    def _check_running(self) -> None:
        if not self.service.running:
            raise AssertionError("our master exited" + log_tail(self.service))


def _master_config(
    path: Path, broker_url: str, interface_name: str, api_port: int, graph: Path
) -> Path:
    lines = [
        f"broker_url: {broker_url}",
        f"interface_name: {interface_name}",
        f"graph: {graph}",
        "api_host: 127.0.0.1",
        f"api_port: {api_port}",
        "log_level: INFO",
        "log_json: true",
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


@asynccontextmanager
async def running_our_master(
    logs: Path, *, broker_url: str, interface_name: str, graph: Path = GRAPH
) -> AsyncIterator[OurMaster]:
    """``python -m vda_master`` on ``graph`` (default: the interop graph); SIGTERM at the end
    (bounded)."""
    api_port = free_port()
    config = _master_config(logs / "master.yaml", broker_url, interface_name, api_port, graph)
    service = ServiceProcess("our master", ["vda_master", "--config", str(config)], logs / "m.log")
    started_at = time.monotonic()
    service.start()
    try:
        async with httpx.AsyncClient(timeout=5.0) as http:
            yield OurMaster(service, f"http://127.0.0.1:{api_port}", http, started_at)
    finally:
        await service.stop()


@asynccontextmanager
async def running_our_vehicle(
    logs: Path,
    *extra: str,
    broker_url: str,
    interface_name: str,
    manufacturer: str,
    serial_number: str,
    time_lapse: float,
) -> AsyncIterator[ServiceProcess]:
    """``python -m vda_vehicle --vda-version 2.0.0`` with ``extra`` flags (graph or map id)."""
    args = [
        "vda_vehicle",
        "--broker-url",
        broker_url,
        "--interface-name",
        interface_name,
        "--manufacturer",
        manufacturer,
        "--serial-number",
        serial_number,
        "--vda-version",
        "2.0.0",
        "--time-lapse",
        str(time_lapse),
        *extra,
    ]
    service = ServiceProcess("our vehicle", args, logs / f"{serial_number}.log").start()
    try:
        yield service
    finally:
        await service.stop()
