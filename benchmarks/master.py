"""Master-control benchmark (issue 4 targets).

1. Ingest: state messages per second the master folds in on one core — topic lookup, decode and
   validation, fleet-view update and order-status update — for a fleet whose every vehicle runs
   an order. Target >= 10,000 states/s.
2. Latency from ``POST /orders`` (real HTTP to the master's uvicorn) to the order being ACCEPTED,
   with a vehicle on the same machine answering over an idle loopback broker.
   Targets p50 < 5 ms, p99 < 20 ms.

Run: python benchmarks/master.py [--vehicles N] [--messages N] [--orders N] [--broker-url URL]
Without --broker-url the project's amqtt broker is started in its own process.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import socket
import statistics
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import httpx
import structlog

from vda5050.clock import SystemClock
from vda5050.codec import HeaderStamper, decode_as, encode
from vda5050.models import (
    AgvPosition,
    Connection,
    ConnectionState,
    Message,
    NodeState,
    Order,
    Velocity,
)
from vda5050.mqtt import InboundMessage, MqttSession, MqttSettings
from vda5050.net import bind_problem
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderStatus, OrderTrack
from vda_master.journal import Journal
from vda_master.planner import Target
from vda_master.requests import OrderRequest
from vda_master.runtime import MasterProcess
from vda_master.service import MasterService
from vda_master.store import StoreWriter, open_store
from vda_master.testing import demo_graph, make_factsheet, plan_state

INTERFACE = "bench"


class NullPublisher:
    """Swallows outbound messages (the ingest benchmark measures inbound work only)."""

    def publish(self, topic: str, kind: Topic, payload: bytes | Callable[[], bytes]) -> None:
        del topic, kind, payload


def _vehicle_messages(agv: AgvId) -> list[tuple[Topic, bytes]]:
    header = {**HEADER, "manufacturer": agv.manufacturer, "serial_number": agv.serial_number}
    online = Connection.model_validate({**header, "connection_state": ConnectionState.ONLINE})
    factsheet = make_factsheet(manufacturer=agv.manufacturer, serial_number=agv.serial_number)
    state = make_state(
        manufacturer=agv.manufacturer, serial_number=agv.serial_number, last_node_id="7"
    )
    return [
        (Topic.CONNECTION, encode(online)),
        (Topic.FACTSHEET, encode(factsheet)),
        (Topic.STATE, encode(state)),
    ]


def _running_state(track: OrderTrack) -> bytes:
    """A ~1.5 KB state of a vehicle driving its order (position, velocity, node/edge states)."""
    state = plan_state(
        track.plan,
        released_end=track.released_end,
        driving=True,
        agv_position=AgvPosition(
            x=2.5,
            y=0.0,
            theta=0.0,
            map_id="demo",
            position_initialized=True,
            localization_score=0.97,
        ),
        velocity=Velocity(vx=1.2, vy=0.0, omega=0.0),
        distance_since_last_node=2.5,
        loads=[],
    )
    return encode(state)


async def bench_ingest(vehicles: int, messages: int, *, store: bool) -> tuple[float, int]:
    """States per second through ``MasterService.ingest`` and the state's size in bytes; with
    ``store`` the master journals into a SQLite store (issue 10) as it does in production."""
    config = MasterConfig(interface_name=INTERFACE)
    service = MasterService(config, demo_graph(), NullPublisher(), SystemClock())
    async with contextlib.AsyncExitStack() as stack:
        if store:
            folder = stack.enter_context(tempfile.TemporaryDirectory())
            opened = await stack.enter_async_context(open_store(None, Path(folder)))
            writer = StoreWriter(opened)
            flushing = asyncio.create_task(writer.flush_loop())
            stack.push_async_callback(_closed, writer, flushing)
            service.attach_journal(Journal(opened, writer, service.clock))
        payloads: list[tuple[str, bytes]] = []
        for index in range(vehicles):
            agv = AgvId("bench", f"r{index}")
            for kind, payload in _vehicle_messages(agv):
                service.ingest(build_topic(INTERFACE, 2, agv, kind), payload)
            track = service.create_order(OrderRequest(Target(destination="18"), agv))
            await service.committed(track.order_id)
            track = service.tracks[track.order_id]
            payloads.append((build_topic(INTERFACE, 2, agv, Topic.STATE), _running_state(track)))
        for topic, payload in payloads:  # warm up: every track confirmed and RUNNING
            service.ingest(topic, payload)
        if not all(t.status == OrderStatus.RUNNING for t in service.tracks.values()):
            raise RuntimeError("warm-up did not bring every order to RUNNING")
        await asyncio.sleep(0.2)  # let the warm-up's writes go out
        batch = [payloads[i % len(payloads)] for i in range(messages)]
        start = time.perf_counter()
        for topic, payload in batch:
            service.ingest(topic, payload)
        elapsed = time.perf_counter() - start
    return messages / elapsed, len(payloads[0][1])


async def _closed(writer: StoreWriter, flushing: asyncio.Task[None]) -> None:
    await writer.close()
    await flushing


# -- latency -----------------------------------------------------------------------------------


class Responder:
    """A vehicle that answers every order at once with a state accepting it, then one that has
    finished it (so it is idle for the next order)."""

    def __init__(self, url: str) -> None:
        self.agv = AgvId("bench", "responder")
        self.stamper = HeaderStamper(self.agv, "2.1.0", SystemClock())
        self.session = MqttSession(
            MqttSettings(url=url, client_id="bench-responder"), on_connected=self._hello
        )
        self.session.subscribe(self._topic(Topic.ORDER), self._on_order)

    def _topic(self, kind: Topic) -> str:
        return build_topic(INTERFACE, 2, self.agv, kind)

    def _send(self, kind: Topic, message: Message) -> None:
        self.session.publish(self._topic(kind), kind, encode(self.stamper.stamp(kind, message)))

    async def _hello(self) -> None:
        header = {**HEADER, "manufacturer": "bench", "serial_number": "responder"}
        online = Connection.model_validate({**header, "connection_state": ConnectionState.ONLINE})
        self._send(Topic.CONNECTION, online)
        self._send(Topic.STATE, self._state("", 0, "7", 0, []))

    def _state(
        self, order_id: str, update: int, last: str, seq: int, rest: list[NodeState]
    ) -> Message:
        return make_state(
            manufacturer="bench",
            serial_number="responder",
            order_id=order_id,
            order_update_id=update,
            last_node_id=last,
            last_node_sequence_id=seq,
            node_states=rest,
        )

    async def _on_order(self, message: InboundMessage) -> None:
        order = decode_as(Order, Topic.ORDER, message.payload)
        if not isinstance(order, Order):
            raise TypeError(order)
        first, last = order.nodes[0], order.nodes[-1]
        rest = [
            NodeState(node_id=n.node_id, sequence_id=n.sequence_id, released=n.released)
            for n in order.nodes[1:]
        ]
        self._send(
            Topic.STATE,
            self._state(
                order.order_id, order.order_update_id, first.node_id, first.sequence_id, rest
            ),
        )
        self._send(
            Topic.STATE,
            self._state(order.order_id, order.order_update_id, last.node_id, last.sequence_id, []),
        )


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


@contextlib.asynccontextmanager
async def _broker(url: str | None) -> AsyncIterator[str]:
    """The given broker, or the project's amqtt broker in its own process (as deployed: a
    broker inside the measured process would compete with the master for its core)."""
    if url is not None:
        yield url
        return
    port = _free_port()
    broker = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "vda5050.broker_service",
        "--port",
        str(port),
        "--log-level",
        "WARNING",
    )
    try:
        async with asyncio.timeout(10):
            while bind_problem("127.0.0.1", port) is None:  # noqa: ASYNC110 - polls a process
                await asyncio.sleep(0.05)
        yield f"mqtt://127.0.0.1:{port}"
    finally:
        broker.terminate()
        await broker.wait()


def _watch_statuses(service: MasterService) -> asyncio.Queue[tuple[str, OrderStatus]]:
    """Report every status change the moment the master stores it (wraps ``_store``)."""
    changes: asyncio.Queue[tuple[str, OrderStatus]] = asyncio.Queue()
    store = service._store  # noqa: SLF001 - measuring the exact moment needs the hook

    def watched(agv: AgvId, track: OrderTrack) -> None:
        old = service.tracks.get(track.order_id)
        store(agv, track)
        if old is None or old.status != track.status:
            changes.put_nowait((track.order_id, track.status))

    service._store = watched  # type: ignore[method-assign]  # noqa: SLF001
    return changes


async def _next_status(
    changes: asyncio.Queue[tuple[str, OrderStatus]], order_id: str, wanted: set[OrderStatus]
) -> None:
    async with asyncio.timeout(5):
        while True:
            changed_id, status = await changes.get()
            if changed_id == order_id and status in wanted:
                return


async def bench_latency(url: str | None, orders: int) -> list[float]:
    """Milliseconds from POST /orders to ACCEPTED, one order at a time."""
    async with _broker(url) as broker_url:
        data_dir = tempfile.mkdtemp(prefix="vda-bench-")
        config = MasterConfig(
            broker_url=broker_url,
            interface_name=INTERFACE,
            api_port=_free_port(),
            log_level="WARNING",
            data_dir=Path(data_dir),
        )
        process = MasterProcess(config, graph=demo_graph())
        changes = _watch_statuses(process.service)
        responder = Responder(broker_url)
        stop = asyncio.Event()
        async with asyncio.TaskGroup() as group:
            group.create_task(process.run(stop), name="bench.master")
            group.create_task(responder.session.run(), name="bench.responder")
            try:
                return await _post_orders(process, responder, changes, orders)
            finally:
                stop.set()
                await responder.session.stop()


async def _post_orders(
    process: MasterProcess,
    responder: Responder,
    changes: asyncio.Queue[tuple[str, OrderStatus]],
    orders: int,
) -> list[float]:
    async with asyncio.timeout(10):
        await process.session.wait_connected()
        while process.service.availability_of(responder.agv) is not None:
            await responder._hello()  # noqa: SLF001 - until the master has seen a state
            await asyncio.sleep(0.2)
    latencies = []
    base = f"http://127.0.0.1:{process.config.api_port}"
    agv = responder.agv
    body = {"manufacturer": agv.manufacturer, "serialNumber": agv.serial_number}
    confirmed = {OrderStatus.ACCEPTED, OrderStatus.RUNNING, OrderStatus.FINISHED}
    async with httpx.AsyncClient(base_url=base) as client:
        for index in range(orders + 20):
            destination = "10" if index % 2 == 0 else "7"
            start = time.perf_counter()
            response = await client.post("/orders", json={**body, "destination": destination})
            if response.status_code != 201:
                raise RuntimeError(response.text)
            order_id = response.json()["orderId"]
            await _next_status(changes, order_id, confirmed)
            if index >= 20:  # the first orders warm up caches and connections
                latencies.append((time.perf_counter() - start) * 1000)
            if process.service.tracks[order_id].status != OrderStatus.FINISHED:
                await _next_status(changes, order_id, {OrderStatus.FINISHED})
    return latencies


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--vehicles", type=int, default=200)
    parser.add_argument("--messages", type=int, default=50_000)
    parser.add_argument("--orders", type=int, default=300)
    parser.add_argument("--broker-url", default=None)
    args = parser.parse_args()
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(30))
    for store in (False, True):
        rate, size = asyncio.run(bench_ingest(args.vehicles, args.messages, store=store))
        print(
            f"ingest{' (SQLite store)' if store else ' (no store)   '}: {rate:,.0f} states/s "
            f"({args.vehicles} vehicles, {size} B per state)"
        )
    latencies = asyncio.run(bench_latency(args.broker_url, args.orders))
    p50 = statistics.median(latencies)
    p99 = statistics.quantiles(latencies, n=100)[98]
    print(f"POST /orders -> ACCEPTED: p50 {p50:.2f} ms, p99 {p99:.2f} ms ({len(latencies)} orders)")


if __name__ == "__main__":
    main()
