"""Fixtures of the browser tests: chromium and a running fleet on the demo graph."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest
from playwright.async_api import Browser

from tests.browser.harness import Fleet, launched_browser, running_fleet
from vda5050.broker import BrokerAddress


@pytest.fixture
async def browser() -> AsyncIterator[Browser]:
    """Headless Debian chromium (skips when missing unless VDA_REQUIRE_CHROMIUM is set)."""
    async with launched_browser() as launched:
        yield launched


@pytest.fixture
async def fleet(
    browser: Browser, embedded_broker: BrokerAddress, unique_interface_name: str
) -> AsyncIterator[Fleet]:
    """Master and two simulated vehicles (acme/robot-1 on node 7, acme/robot-2 on node 1)."""
    del browser  # requested first: a missing chromium skips before the fleet starts
    async with running_fleet(embedded_broker, unique_interface_name) as running:
        yield running
