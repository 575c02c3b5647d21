"""Fixtures shared by all test layers."""

from __future__ import annotations

import uuid
from typing import TYPE_CHECKING

import pytest

from vda5050.broker import BrokerAddress, EmbeddedBroker

if TYPE_CHECKING:
    from collections.abc import AsyncIterator


@pytest.fixture
async def embedded_broker() -> AsyncIterator[BrokerAddress]:
    """An anonymous in-process MQTT 3.1.1 broker on a free loopback port, stopped afterwards."""
    async with EmbeddedBroker() as address:
        yield address


@pytest.fixture
def unique_interface_name() -> str:
    """A VDA 5050 interface name (the first topic level) that no other test uses."""
    return f"test-{uuid.uuid4().hex[:12]}"
