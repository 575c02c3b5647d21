"""Fixtures of the integration tests."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from tests.mosquitto import run_mosquitto
from vda5050.broker import BrokerAddress, EmbeddedBroker


@pytest.fixture(params=["amqtt", pytest.param("mosquitto", marks=pytest.mark.mosquitto)])
async def broker(request: pytest.FixtureRequest, tmp_path: Path) -> AsyncIterator[BrokerAddress]:
    """The embedded amqtt broker, or a private Mosquitto (skipped when it is not installed
    unless VDA_REQUIRE_MOSQUITTO is set): the MQTT session's tests run against both."""
    if request.param == "amqtt":
        async with EmbeddedBroker() as address:
            yield address
    else:
        with run_mosquitto(tmp_path) as mosquitto:
            yield mosquitto.address
