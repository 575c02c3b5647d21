"""The live map in a real browser: it loads offline, shows the fleet and follows it live."""

from __future__ import annotations

import pytest
from playwright.async_api import Browser

from tests.browser.harness import Fleet, open_map

pytestmark = [pytest.mark.browser, pytest.mark.integration]


async def test_page_shows_graph_and_every_vehicle_without_errors_or_foreign_requests(
    browser: Browser, fleet: Fleet
) -> None:
    """The page draws every node and every vehicle, logs no error and loads nothing off-host."""
    page, watch = await open_map(browser, fleet.url)
    graph = fleet.master.graph
    assert await page.locator("[data-node-id]").count() == len(graph.nodes)
    for serial in fleet.serials:
        marker = page.locator(f'[data-vehicle="acme/{serial}"]')
        await marker.wait_for()
        assert await marker.get_attribute("data-status") == "idle"
    await page.screenshot(path="/tmp/map-test.png")
    watch.clean()
