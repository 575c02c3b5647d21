"""Running master control: broker (optional), MQTT session, service loops and the HTTP API in one
event loop and one TaskGroup (house style §3.5).

``MasterProcess.run(stop)`` opens the store and resumes the orders it holds (issue 10), then
serves; it returns after ``stop`` is set: the API stops accepting requests, the MQTT session
disconnects cleanly, what is queued for the store is written, the embedded broker (if any)
shuts down.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import time
from collections.abc import AsyncIterator, Iterator
from datetime import timedelta
from typing import Final

import structlog
import uvicorn

from vda5050.clock import Clock, SystemClock
from vda5050.collector import FULL_COLLECTION_EVERY_S, tuned_collector
from vda5050.errors import ConfigError
from vda5050.mqtt import BrokerEndpoint, MqttSession
from vda5050.net import bind_problem
from vda5050.topics import DELIVERY, Topic, subscription_filter
from vda_master.api import create_app
from vda_master.api_auth import check_exposure
from vda_master.config import MasterConfig, interface_name
from vda_master.graph import Graph, load_graph
from vda_master.journal import Journal
from vda_master.pose_feed import PoseFeed
from vda_master.service import MAJOR_VERSIONS, MasterService
from vda_master.store import SqlStore, Store, StoreError, StoreWriter, open_store

log = structlog.get_logger()

#: Seconds between two prunes of ended orders older than ``order_retention_days``.
PRUNE_EVERY_S: Final = 24 * 3600.0
#: How often what the order estimates learned is written to the data folder (seconds).
KEEP_LEARNED_EVERY_S: Final = 300.0
#: At shutdown, how long queued webhook events may still go out (docs/master.md, *Webhooks*).
_WEBHOOK_DRAIN_S: Final = 2.0


def _check_port_free(host: str, port: int) -> None:
    """ConfigError naming the port when the HTTP API could not listen on it."""
    problem = bind_problem(host, port)
    if problem is not None:
        msg = (
            f"the HTTP API cannot listen on {host}:{port} ({problem}); stop the program using it "
            "or choose another --api-port"
        )
        raise ConfigError(msg)


class _EmbeddedServer(uvicorn.Server):
    """uvicorn without its own signal handling: the master's stop event decides."""

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        yield


class MasterProcess:
    """One master control: owns the session, the service and the API server."""

    def __init__(
        self, config: MasterConfig, *, graph: Graph | None = None, clock: Clock | None = None
    ) -> None:
        self.config = config
        self.graph = graph if graph is not None else load_graph(config.graph)
        settings = config.mqtt_settings(client_id="vda-master")
        self.session = MqttSession(settings, name="master", on_connected=self._on_connected)
        self.service = MasterService(config, self.graph, self.session, clock or SystemClock())
        self.service.backlog = self.session.backlog
        visualization: list[str] = []
        for topic_filter, kind in self.service.subscriptions():
            # At least each topic's own QoS (connection: 1), else the configured one. amqtt raises
            # the delivery QoS to the subscription's, so the default 0 keeps state at QoS 0.
            qos = max(config.qos, DELIVERY[kind].qos)
            # Visualization only while a live map is open (vda_master.pose_feed).
            active = kind is not Topic.VISUALIZATION
            self.session.subscribe(topic_filter, self.service.on_message, qos, active=active)
            if not active:
                visualization.append(topic_filter)
        self.pose_feed = PoseFeed(self.session, visualization)
        self.service.live.on_readers_changed = self.pose_feed.readers_changed
        for kind in (Topic.ORDER, Topic.INSTANT_ACTIONS):  # denied publications are loud
            for major in MAJOR_VERSIONS:
                echo = subscription_filter(interface_name(config, major), major, kind)
                # an order confirmed by the vehicle's state needs no echo (vda5050.access)
                self.session.verify_echo(echo, after_evidence=kind is Topic.ORDER)
        self.service.on_order_delivered = self.session.delivered
        self.app = create_app(self.service, broker=self.session)
        self.service.listening_port = lambda: self.api_port  # map download links
        self.server = _EmbeddedServer(
            uvicorn.Config(
                self.app,
                host=config.api_host,
                port=config.api_port,
                log_config=None,
                access_log=False,
                lifespan="off",
            )
        )

    async def _on_connected(self) -> None:
        await self.service.on_broker_connected()

    @property
    def api_port(self) -> int | None:
        """The port the API really listens on (useful with ``api_port: 0``), once started."""
        for server in self.server.servers:
            for sock in server.sockets:
                port: int = sock.getsockname()[1]
                return port
        return None

    async def run(self, stop: asyncio.Event) -> None:
        """Serve until ``stop`` is set, then shut everything down in order."""
        check_exposure(self.config)
        _check_port_free(self.config.api_host, self.config.api_port)
        self.service.load_learned()
        async with self._store() as (store, writer), self._broker(), asyncio.TaskGroup() as group:
            group.create_task(writer.flush_loop(), name="master.store_flush_loop")
            pruner = group.create_task(self._prune_loop(store), name="master.prune_loop")
            learner = group.create_task(self._keep_learned_loop(), name="master.eta_loop")
            group.create_task(self.session.run(), name="master.connection_loop")
            ticker = group.create_task(self.service.tick_loop(), name="master.tick_loop")
            collector = group.create_task(_collect_loop(), name="master.gc_loop")
            group.create_task(self._serve_api(), name="master.api_loop")
            webhooks = group.create_task(self.service.webhooks.run(), name="master.webhooks")
            log.info(
                "master.started",
                broker=BrokerEndpoint.from_url(self.config.broker_url).display,
                api=f"http://{self.config.api_host}:{self.config.api_port}",
                graph=self.graph.source,
                nodes=len(self.graph.nodes),
                edges=len(self.graph.edges),
            )
            await stop.wait()
            await self.service.webhooks.drain(_WEBHOOK_DRAIN_S)
            webhooks.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await webhooks
            await self.service.webhooks.close()  # what is still queued goes out after a restart
            self.server.should_exit = True
            self.service.live.close()  # ends the map's open streams, else uvicorn waits on them
            self.pose_feed.close()
            ticker.cancel()
            pruner.cancel()
            learner.cancel()
            await self.service.keep_learned()
            collector.cancel()
            await self.session.stop()
            await writer.close()
        log.info("master.stopped")

    @contextlib.asynccontextmanager
    async def _store(self) -> AsyncIterator[tuple[SqlStore, StoreWriter]]:
        """Open (create, migrate) the store, resume what it holds, journal into it."""
        store = open_store(self.config.database_url, self.config.data_dir)
        try:
            await store.__aenter__()
        except StoreError as exc:
            msg = f"cannot open the order store at {store.target.where}: {exc}"
            raise ConfigError(msg) from None
        try:
            writer = StoreWriter(store)
            await self._attach_webhooks(store)  # before recovery: it may emit events
            self.service.attach_journal(Journal(store, writer, self.service.clock))
            await self._recover(store)
            yield store, writer
        finally:
            await store.__aexit__(None, None, None)

    async def _attach_webhooks(self, store: SqlStore) -> None:
        """Webhook events are kept in the store until delivered (docs/master.md, *Webhooks*)."""
        try:
            await self.service.webhooks.attach(store)
        except StoreError as exc:
            msg = f"cannot read the webhook events kept at {store.target.where}: {exc}"
            raise ConfigError(msg) from None

    async def _recover(self, store: SqlStore) -> None:
        """Resume what an earlier run left: vehicles, headerId counters, open orders."""
        started = time.monotonic()
        resumed = await self.service.resume_from(store)
        log.info(
            "master.store_opened",
            store=store.target.where,
            orders_resumed=len(resumed),
            load_s=round(time.monotonic() - started, 3),
        )

    async def _prune_loop(self, store: Store) -> None:
        """Forever: delete ended orders older than ``order_retention_days`` (at start, then
        daily). A failure is logged and tried again next time."""
        while True:
            before = self.service.clock.now() - timedelta(days=self.config.order_retention_days)
            try:
                pruned = await store.prune(before)
            except StoreError as exc:
                log.warning("store.prune_failed", reason=str(exc))
            else:
                if pruned:
                    log.info("store.pruned", orders=pruned, before=before.isoformat())
            await asyncio.sleep(PRUNE_EVERY_S)

    async def _keep_learned_loop(self) -> None:
        """Forever: keep what ``expectedFinishAt`` has learned in the data folder, every
        :data:`KEEP_LEARNED_EVERY_S` (and once more at shutdown)."""
        while True:
            await asyncio.sleep(KEEP_LEARNED_EVERY_S)
            await self.service.keep_learned()

    async def _serve_api(self) -> None:
        """uvicorn until ``should_exit``. A stop during uvicorn's start-up makes it return
        without closing its listening sockets, so they are closed here in every case."""
        try:
            await self.server.serve()
        finally:
            for server in self.server.servers:
                server.close()
                await server.wait_closed()

    @contextlib.asynccontextmanager
    async def _broker(self) -> AsyncIterator[None]:
        if not self.config.embedded_broker:
            yield
            return
        # Imported here: amqtt is heavy and only needed with --embedded-broker.
        from vda5050.broker import EmbeddedBroker  # noqa: PLC0415

        endpoint = self.config.mqtt_settings().endpoint
        login = endpoint.username is not None
        broker = EmbeddedBroker(
            host=endpoint.host,
            port=endpoint.port,
            username=endpoint.username,
            password=(endpoint.password or "") if login else None,
        )
        try:
            await broker.start()
        except OSError:
            msg = (
                f"cannot start the embedded broker on {endpoint.host}:{endpoint.port}: the port "
                "is in use (another broker?); stop that program or choose another port in "
                "--broker-url"
            )
            raise ConfigError(msg) from None
        try:
            yield
        finally:
            await broker.stop()


async def _collect_loop() -> None:
    """While master control serves: the collector tuned for a large fleet, a full collection
    every :data:`~vda5050.collector.FULL_COLLECTION_EVERY_S` (:mod:`vda5050.collector`)."""
    with tuned_collector():
        while True:
            await asyncio.sleep(FULL_COLLECTION_EVERY_S)
            gc.collect()
