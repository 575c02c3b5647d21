"""Fixtures of the system tests: a broker process (embedded amqtt or Mosquitto), the stack."""

from __future__ import annotations

from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest

from tests.mosquitto import Mosquitto, free_port, require_mosquitto, run_mosquitto
from tests.system.stack import AmqttBroker, Broker, Captured, Stack, capturing
from vda5050.broker import BrokerAddress

BROKERS = [
    pytest.param("amqtt", marks=pytest.mark.integration),
    pytest.param("mosquitto", marks=pytest.mark.mosquitto),
]


@pytest.fixture
def mosquitto(tmp_path: Path) -> Iterator[Mosquitto]:
    """A private Mosquitto (skipped without the binary unless VDA_REQUIRE_MOSQUITTO is set)."""
    require_mosquitto()
    with run_mosquitto(tmp_path / "mosquitto") as broker:
        yield broker


@pytest.fixture(params=BROKERS)
def broker(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Broker]:
    """A broker process on a free port: the project's amqtt broker, or a private Mosquitto."""
    if request.param == "mosquitto":
        with run_mosquitto(tmp_path / "mosquitto") as mosquitto:
            yield mosquitto
        return
    amqtt = AmqttBroker(BrokerAddress("127.0.0.1", free_port()), tmp_path / "broker.log")
    amqtt.start()
    try:
        yield amqtt
    finally:
        amqtt.stop()


@pytest.fixture
async def capture(broker: Broker, unique_interface_name: str) -> AsyncIterator[Captured]:
    """Every message of the test's interface, checked against schemas/ when the test ends."""
    async with capturing(broker.address, unique_interface_name) as captured:
        yield captured
    problems = captured.schema_problems()
    assert not problems, "messages that fail schemas/:\n" + "\n".join(problems[:10])


@pytest.fixture
async def stack(
    broker: Broker, unique_interface_name: str, tmp_path: Path, request: pytest.FixtureRequest
) -> AsyncIterator[Stack]:
    """Master and vehicles started by the test; all stopped (SIGTERM) at the end."""
    created = Stack(broker, unique_interface_name, tmp_path)
    try:
        yield created
    finally:
        await created.stop_all()
        report = request.node.stash.get(_FAILED, False)
        if report:
            print(created.logs_text())  # noqa: T201 - shown with the failure


_FAILED = pytest.StashKey[bool]()


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> object:
    report = yield
    if getattr(report, "failed", False):
        item.stash[_FAILED] = True
    return report
