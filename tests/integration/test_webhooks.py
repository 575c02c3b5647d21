"""Webhooks (docs/master.md, *Webhooks*): a plant's system hears every order status change and
every vehicle connection change, in order, signed, and a receiver that fails is retried without
holding master control up."""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import itertools
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from structlog.testing import capture_logs

from tests.integration.master_helpers import (
    SIMULATED_BODY,
    master_with_simulated_vehicle,
    running_master,
    wait_status,
)
from tests.mosquitto import free_port
from tests.webhook_receiver import Received, receiving
from vda5050.clock import SystemClock
from vda5050.models import EStop
from vda_master.config import MasterConfig
from vda_master.store import open_store
from vda_master.testing import parse_exposition
from vda_master.webhook_events import order_event
from vda_master.webhooks import Webhooks
from vda_vehicle.model import RobotMode
from vda_vehicle.vehicle_status import StackStatus

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration

SECRET = "plant-secret"


async def _until(received: Received, done: Any, timeout: float = 10.0) -> list[dict[str, Any]]:
    async with asyncio.timeout(timeout):
        while not done(events := received.events()):
            await asyncio.sleep(0.02)
    return events


def _statuses(events: list[dict[str, Any]], order_id: str) -> list[tuple[str | None, str]]:
    return [
        (e["previousStatus"], e["status"])
        for e in events
        if e["type"] == "order.status" and e["orderId"] == order_id
    ]


async def test_a_receiver_hears_each_order_from_queued_to_finished_signed_and_in_order(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    with receiving() as received:
        settings: dict[str, object] = {"webhook_urls": [received.url], "webhook_secret": SECRET}
        async with master_with_simulated_vehicle(
            embedded_broker, unique_interface_name, master_settings=settings
        ) as (_, _vehicle, client):
            first = await client.post("/orders", json={**SIMULATED_BODY, "destination": "10"})
            assert first.status_code == 201, first.text
            second = await client.post(
                "/orders", json={**SIMULATED_BODY, "destination": "7", "queue": True}
            )
            assert second.status_code == 202, second.text  # the vehicle is busy: it waits
            first_id, second_id = first.json()["orderId"], second.json()["orderId"]
            await wait_status(client, second_id, "FINISHED", timeout=20)
            events = await _until(
                received, lambda es: ("RUNNING", "FINISHED") in _statuses(es, second_id)
            )
            metrics = parse_exposition((await client.get("/metrics")).text)

    # Every event heard was counted, but maybe the last: counted once its answer is read.
    assert metrics["vda_master_webhook_events_delivered_total"] >= len(events) - 1 > 0
    assert metrics["vda_master_webhook_events_dropped_total"] == 0
    connection = next(e for e in events if e["type"] == "vehicle.connection")
    assert connection["connectionState"] == "ONLINE"
    assert (connection["manufacturer"], connection["serialNumber"]) == ("acme", "r1")
    assert connection["previousConnectionState"] is None
    for order_id, start in ((first_id, (None, "SENT")), (second_id, (None, "QUEUED"))):
        chain = _statuses(events, order_id)
        assert chain[0] == start
        assert chain[-1][1] == "FINISHED"
        assert all(b[0] == a[1] for a, b in itertools.pairwise(chain)), chain
    assert ("QUEUED", "SENT") in _statuses(events, second_id)
    # under way, each event says when master control expects the order done; once ended, not
    for event in (e for e in events if e["type"] == "order.status"):
        under_way = event["status"] in {"SENT", "ACCEPTED", "RUNNING"}
        assert (event["expectedFinishAt"] is not None) == under_way, event
    ids = [e["eventId"] for e in events]
    assert ids == sorted(ids)
    assert len(set(ids)) == len(ids)
    for headers, body in received.requests:
        expected = hmac.new(SECRET.encode(), body, hashlib.sha256).hexdigest()
        assert headers["x-vda-signature"] == f"sha256={expected}"
        assert headers["content-type"] == "application/json"
        assert headers["x-vda-event"] in {"order.status", "vehicle.connection"}


async def test_a_receiver_hears_a_vehicle_s_emergency_stop_and_errors(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """§6.10.5, §6.10.6: an operator presses the e-stop and releases it; a cancelOrder sent
    while the vehicle has no order makes it report an error (noOrderToCancel, R64). The
    receiver hears each change once, with the previous values."""
    with receiving() as received:
        settings: dict[str, object] = {"webhook_urls": [received.url]}
        async with master_with_simulated_vehicle(
            embedded_broker, unique_interface_name, master_settings=settings
        ) as (_, vehicle, client):
            runtime = vehicle.runtimes[0]
            runtime.on_stack_status(StackStatus(RobotMode.AUTOMATIC, e_stop=EStop.REMOTE))
            await _until(received, lambda es: _of_type(es, "vehicle.safety"))
            runtime.on_stack_status(StackStatus(RobotMode.AUTOMATIC))
            await _until(received, lambda es: len(_of_type(es, "vehicle.safety")) == 2)
            answer = await client.post(
                "/vehicles/acme/r1/instantActions",
                json={"actions": [{"actionType": "cancelOrder"}]},
            )
            assert answer.status_code == 202, answer.text
            events = await _until(received, lambda es: _of_type(es, "vehicle.errors"))

    pressed, released = _of_type(events, "vehicle.safety")
    assert (pressed["eStop"], pressed["previousEStop"]) == ("REMOTE", "NONE")
    assert (released["eStop"], released["previousEStop"]) == ("NONE", "REMOTE")
    assert (pressed["manufacturer"], pressed["serialNumber"]) == ("acme", "r1")
    [errors] = _of_type(events, "vehicle.errors")
    assert [e["errorType"] for e in errors["raised"]] == ["noOrderToCancel"]
    assert errors["errors"] == errors["raised"]
    assert errors["cleared"] == []


async def test_events_not_yet_delivered_survive_a_restart_of_master_control(
    embedded_broker: BrokerAddress, unique_interface_name: str, tmp_path: Path
) -> None:
    """The receiver refuses everything (503) while the first master control runs; after a
    restart on the same store it takes the kept events, with their ids, and then the new ones,
    whose ids go on from there."""
    with receiving([503] * 1_000) as received:
        settings: dict[str, object] = {"webhook_urls": [received.url], "data_dir": str(tmp_path)}
        async with running_master(embedded_broker, unique_interface_name, **settings) as master:
            for n in range(3):
                master.service.webhooks.emit(order_event(f"o{n}", "SENT", None, None, None))
            async with asyncio.timeout(5):
                while not received.requests:
                    await asyncio.sleep(0.02)
        assert received.events() == []
        with received.lock:
            received.answers.clear()
        async with running_master(embedded_broker, unique_interface_name, **settings) as master:
            master.service.webhooks.emit(order_event("o3", "SENT", None, None, None))
            events = await _until(received, lambda es: len(es) >= 4)
    async with open_store(None, tmp_path) as store:
        outbox = await store.load_webhook_outbox()

    assert [(e["eventId"], e["orderId"]) for e in events] == [
        (1, "o0"),
        (2, "o1"),
        (3, "o2"),
        (4, "o3"),
    ]
    assert (outbox.events, outbox.last_event_id) == ((), 4)  # delivered: forgotten


def _of_type(events: list[dict[str, Any]], kind: str) -> list[dict[str, Any]]:
    return [e for e in events if e["type"] == kind]


def _webhooks(url: str, attempts: int) -> Webhooks:
    config = MasterConfig.model_validate({"webhook_urls": [url], "webhook_max_attempts": attempts})

    async def no_wait(_seconds: float) -> None:
        await asyncio.sleep(0)

    return Webhooks(config, SystemClock(), sleep=no_wait)


async def test_a_failing_receiver_is_retried_a_refusal_is_dropped_and_order_is_kept() -> None:
    """503, 503, then 200: the first event arrives on its third attempt; a 400 drops the
    second (logged); the third follows. Events reach the receiver in the order emitted."""
    with receiving([503, 503, 200, 400]) as received:
        webhooks = _webhooks(received.url, attempts=5)
        for n in range(3):
            webhooks.emit(order_event(f"o{n}", "SENT", None, None, None))
        with capture_logs() as logs:
            sender = asyncio.create_task(webhooks.run())
            await webhooks.drain(10)
            sender.cancel()
    assert [e["orderId"] for e in received.events()] == ["o0", "o2"]
    assert [int(h["x-answer"]) for h, _ in received.requests] == [503, 503, 200, 400, 200]
    (dropped,) = [entry for entry in logs if entry["event"] == "webhook.dropped"]
    assert dropped["event_id"] == 2
    assert dropped["attempts"] == 1
    assert dropped["why"].startswith("HTTP 400")
    assert (webhooks.delivered, webhooks.dropped, webhooks.queued()) == (2, 1, 0)


async def test_with_no_limit_on_attempts_an_event_waits_until_the_receiver_takes_it() -> None:
    """``webhook_max_attempts: 0``: a receiver that answers 503 for a long while (here 25
    times, past the default's 10 attempts) gets the event at last, and the next after it."""
    with receiving([503] * 25) as received:
        webhooks = _webhooks(received.url, attempts=0)
        webhooks.emit(order_event("o1", "FINISHED", "RUNNING", None, None))
        webhooks.emit(order_event("o2", "SENT", None, None, None))
        sender = asyncio.create_task(webhooks.run())
        await webhooks.drain(10)
        sender.cancel()
    assert [e["orderId"] for e in received.events()] == ["o1", "o2"]
    assert len(received.requests) == 27
    assert (webhooks.delivered, webhooks.dropped) == (2, 0)


async def test_an_unreachable_receiver_costs_its_attempts_then_the_event_is_dropped() -> None:
    webhooks = _webhooks(f"http://127.0.0.1:{free_port()}/hooks", attempts=3)
    webhooks.emit(order_event("o1", "FAILED", "RUNNING", None, "the vehicle lost its order"))
    with capture_logs() as logs:
        sender = asyncio.create_task(webhooks.run())
        await webhooks.drain(10)
        sender.cancel()
    assert (webhooks.delivered, webhooks.dropped, webhooks.queued()) == (0, 1, 0)
    (dropped,) = [entry for entry in logs if entry["event"] == "webhook.dropped"]
    assert dropped["attempts"] == 3
    assert "ConnectError" in dropped["why"]
