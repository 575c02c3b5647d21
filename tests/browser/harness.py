"""A fleet for browser tests: embedded broker, master and simulated vehicles in this process,
and a headless Debian chromium driven by Playwright that may only talk to 127.0.0.1.

Tests that need chromium skip when it is missing, unless ``VDA_REQUIRE_CHROMIUM`` is set (CI sets
it), in which case they fail instead of hiding behind a skip (the tests/mosquitto.py pattern).
Playwright's own browser download is never used: it cannot work here.
"""

from __future__ import annotations

import asyncio
import os
import shutil
import statistics
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

import pytest
from playwright.async_api import (
    Browser,
    ConsoleMessage,
    Locator,
    Page,
    Route,
    async_playwright,
)

from tests.integration.master_helpers import api_client, running_master, wait_until
from vda5050.broker import BrokerAddress
from vda5050.graph_file import GraphFile
from vda5050.topics import AgvId
from vda_master.runtime import MasterProcess
from vda_vehicle.config import VehicleSettings
from vda_vehicle.service import VehicleService

REPO = Path(__file__).resolve().parents[2]
DEMO_GRAPH = REPO / "config" / "graphs" / "demo.json"
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
LOCAL_HOSTS = frozenset({"127.0.0.1"})


def chromium_binary() -> str | None:
    """Debian's chromium (``/usr/bin/chromium``), or whatever ``chromium`` is on PATH."""
    if Path("/usr/bin/chromium").is_file():
        return "/usr/bin/chromium"
    return shutil.which("chromium")


def require_chromium() -> str:
    """The binary, or skip (fail when VDA_REQUIRE_CHROMIUM is set) when it is missing."""
    binary = chromium_binary()
    if binary is None:
        if os.environ.get("VDA_REQUIRE_CHROMIUM"):
            pytest.fail("chromium is required (VDA_REQUIRE_CHROMIUM is set) but not installed")
        pytest.skip("chromium is not installed (apt-get install chromium)")
    return binary


@asynccontextmanager
async def launched_browser() -> AsyncIterator[Browser]:
    """Headless chromium, closed afterwards."""
    binary = require_chromium()
    async with async_playwright() as playwright:
        browser = await playwright.chromium.launch(executable_path=binary, args=CHROMIUM_FLAGS)
        try:
            yield browser
        finally:
            await browser.close()


@dataclass
class PageWatch:
    """What a page did that a test must check: console errors and requests off 127.0.0.1."""

    console_errors: list[str] = field(default_factory=list)
    foreign_requests: list[str] = field(default_factory=list)

    def clean(self) -> None:
        assert not self.console_errors, self.console_errors
        assert not self.foreign_requests, self.foreign_requests


async def open_map(browser: Browser, url: str) -> tuple[Page, PageWatch]:
    """A page on the map at ``url`` with every non-local request aborted and recorded, and
    console errors recorded; returns once the first snapshot was painted."""
    page = await browser.new_page(viewport={"width": 1400, "height": 900})
    watch = PageWatch()

    def on_console(message: ConsoleMessage) -> None:
        if message.type == "error":
            watch.console_errors.append(message.text)

    async def guard(route: Route) -> None:
        host = urlsplit(route.request.url).hostname
        if host in LOCAL_HOSTS:
            await route.continue_()
        else:
            watch.foreign_requests.append(route.request.url)
            await route.abort()

    page.on("console", on_console)
    page.on("pageerror", lambda error: watch.console_errors.append(str(error)))
    await page.route("**/*", guard)
    await page.goto(url)
    await page.wait_for_function("() => window.vdaMap && window.vdaMap.ready", timeout=10_000)
    return page, watch


@dataclass
class Fleet:
    """A running master with its vehicles."""

    master: MasterProcess
    vehicles: VehicleService
    url: str

    @property
    def serials(self) -> list[str]:
        return [r.agv.serial_number for r in self.vehicles.runtimes]


def vehicle_settings(
    address: BrokerAddress, interface_name: str, **overrides: object
) -> VehicleSettings:
    settings: dict[str, object] = {
        "broker_url": address.url,
        "interface_name": interface_name,
        "manufacturer": "acme",
        "serial_number": "robot",
        "graph": DEMO_GRAPH,
        "start_node": "7",
        "count": 2,
        "time_lapse": 4.0,
        "tick_hz": 10.0,
        "visualization_interval_s": 0.25,
        "log_level": "WARNING",
        **overrides,
    }
    return VehicleSettings.model_validate(settings)


@asynccontextmanager
async def running_fleet(
    address: BrokerAddress, interface_name: str, **vehicle_overrides: object
) -> AsyncIterator[Fleet]:
    """Master (API on a free port) and simulated vehicles on the demo graph, all reported."""
    settings = vehicle_settings(address, interface_name, **vehicle_overrides)
    graph = GraphFile.model_validate_json(DEMO_GRAPH.read_bytes())
    vehicles = VehicleService(settings, graph)
    # Traffic control off: on the demo graph every edge has its opposite (one-lane), so it would
    # release whole routes at once and the page would never show a horizon. The traffic overlay
    # tests feed the snapshot themselves.
    master_running = running_master(address, interface_name, traffic_control=False)
    async with master_running as master, asyncio.TaskGroup() as group:
        group.create_task(vehicles.run(), name="test.vehicles")
        try:
            agvs = [r.agv for r in vehicles.runtimes]
            await wait_until(lambda: all(_available(master, agv) for agv in agvs), timeout=10)
            yield Fleet(master, vehicles, f"http://127.0.0.1:{master.api_port}/")
        finally:
            vehicles.stop()


def _available(master: MasterProcess, agv: AgvId) -> bool:
    return master.service.availability_of(agv) is None


def percentile(samples: list[float], fraction: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(fraction * len(ordered)))]


def summary(samples: list[float]) -> str:
    return (
        f"n={len(samples)} p50={statistics.median(samples):.1f} ms "
        f"p95={percentile(samples, 0.95):.1f} ms max={max(samples):.1f} ms"
    )


def node(page: Page, node_id: str) -> Locator:
    """The clickable shape of a graph node (its circle, or a station's square)."""
    return page.locator(f'[data-node-id="{node_id}"] > :is(circle, rect)')


async def post_order(fleet: Fleet, serial: str, destination: str, **more: object) -> str:
    """Send ``acme/<serial>`` to ``destination`` through the API (``more``: further request
    fields); the new orderId."""
    body = {"manufacturer": "acme", "serialNumber": serial, "destination": destination, **more}
    async with api_client(fleet.master) as client:
        answer = await client.post("/orders", json=body)
    assert answer.status_code == 201, answer.text
    order_id: str = answer.json()["orderId"]
    return order_id


async def wait_order(fleet: Fleet, order_id: str, status: str, timeout: float = 10.0) -> None:
    """Until the master reports ``status`` for the order."""
    tracks = fleet.master.service.tracks
    await wait_until(lambda: tracks[order_id].status == status, timeout=timeout)
