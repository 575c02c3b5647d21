"""Running master control: broker (optional), MQTT session, service loops and the HTTP API in one
event loop and one TaskGroup (house style §3.5).

``MasterProcess.run(stop)`` returns after ``stop`` is set: the API stops accepting requests, the
MQTT session disconnects cleanly, the embedded broker (if any) shuts down.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Iterator

import structlog
import uvicorn

from vda5050.clock import Clock, SystemClock
from vda5050.errors import ConfigError
from vda5050.mqtt import BrokerEndpoint, MqttSession
from vda5050.net import bind_problem
from vda5050.topics import DELIVERY
from vda_master.api import create_app
from vda_master.config import MasterConfig
from vda_master.graph import Graph, load_graph
from vda_master.service import MasterService

log = structlog.get_logger()


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
        for topic_filter, kind in self.service.subscriptions():
            # At least each topic's own QoS (connection: 1), else the configured one. amqtt raises
            # the delivery QoS to the subscription's, so the default 0 keeps state at QoS 0.
            qos = max(config.qos, DELIVERY[kind].qos)
            self.session.subscribe(topic_filter, self.service.on_message, qos)
        self.app = create_app(self.service)
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
        _check_port_free(self.config.api_host, self.config.api_port)
        async with self._broker(), asyncio.TaskGroup() as group:
            group.create_task(self.session.run(), name="master.connection_loop")
            ticker = group.create_task(self.service.tick_loop(), name="master.tick_loop")
            group.create_task(self._serve_api(), name="master.api_loop")
            log.info(
                "master.started",
                broker=BrokerEndpoint.from_url(self.config.broker_url).display,
                api=f"http://{self.config.api_host}:{self.config.api_port}",
                graph=self.graph.source,
                nodes=len(self.graph.nodes),
                edges=len(self.graph.edges),
            )
            await stop.wait()
            self.server.should_exit = True
            self.service.live.close()  # ends the map's open streams, else uvicorn waits on them
            ticker.cancel()
            await self.session.stop()
        log.info("master.stopped")

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
