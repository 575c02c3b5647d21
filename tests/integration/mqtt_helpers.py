"""Small helpers for integration tests that watch a broker with a plain aiomqtt client."""

from __future__ import annotations

import asyncio
import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import aiomqtt

from vda5050.broker import BrokerAddress


@dataclass
class Watcher:
    """Collects every message on the filters it subscribed to."""

    client: aiomqtt.Client
    messages: list[aiomqtt.Message] = field(default_factory=list)
    arrived: asyncio.Event = field(default_factory=asyncio.Event)

    async def wait_for(
        self, topic: str, count: int = 1, timeout: float = 5.0
    ) -> list[aiomqtt.Message]:
        """Wait until ``count`` messages on ``topic`` have arrived; return them."""
        async with asyncio.timeout(timeout):
            while True:
                found = [m for m in self.messages if str(m.topic) == topic]
                if len(found) >= count:
                    return found
                self.arrived.clear()
                await self.arrived.wait()

    def on(self, topic: str) -> list[aiomqtt.Message]:
        return [m for m in self.messages if str(m.topic) == topic]


def client_for(address: BrokerAddress, **kwargs: object) -> aiomqtt.Client:
    return aiomqtt.Client(
        address.host,
        address.port,
        socket_options=[(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)],
        **kwargs,  # type: ignore[arg-type]
    )


@asynccontextmanager
async def watching(address: BrokerAddress, *filters: str, qos: int = 1) -> AsyncIterator[Watcher]:
    """A connected watcher subscribed to ``filters``."""
    async with client_for(address) as client:
        watcher = Watcher(client)
        for topic_filter in filters:
            await client.subscribe(topic_filter, qos=qos)

        async def collect() -> None:
            async for message in client.messages:
                watcher.messages.append(message)
                watcher.arrived.set()

        async with asyncio.TaskGroup() as group:
            task = group.create_task(collect(), name="test.watcher")
            try:
                yield watcher
            finally:
                task.cancel()
