"""The live map draws an edge with a trajectory along its curve (docs/web.md)."""

from __future__ import annotations

import math

import pytest
from playwright.async_api import Browser

from tests.browser.harness import open_map
from tests.integration.master_helpers import running_master
from tests.integration.test_curved_edges import GRAPH, RADIUS
from vda5050.broker import BrokerAddress
from vda_master.graph import build_graph

pytestmark = [pytest.mark.browser, pytest.mark.integration]


async def test_a_curved_edge_is_drawn_through_its_trajectorys_points(
    browser: Browser, embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    async with running_master(
        embedded_broker, unique_interface_name, graph=build_graph(GRAPH)
    ) as master:
        page, watch = await open_map(browser, f"http://127.0.0.1:{master.api_port}/")
        curved = page.locator('polyline.edge[data-edge-id="ab"]')
        straight = page.locator('line.edge[data-edge-id="ba"]')
        assert await curved.count() == 1
        assert await straight.count() == 1
        points = (await curved.get_attribute("points") or "").split()
        assert len(points) > 10
        # SVG y points down: the map's (x, y) is drawn at (x, -y). Inner points lie on the arc.
        for point in points[1:-1]:
            x, y = (float(v) for v in point.split(","))
            assert math.hypot(x, -y) == pytest.approx(RADIUS, abs=0.01)
        watch.clean()
        await page.close()
