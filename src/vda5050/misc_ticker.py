"""paho-mqtt's once-a-second housekeeping for every connection of a process, on one timer.

paho's ``loop_misc()`` sends PINGREQ when the keep-alive is due and closes a connection whose
PINGRESP is overdue; aiomqtt calls it from a task per client that sleeps one second between
calls. A process with a thousand vehicle sessions thus woke its event loop a thousand times a
second for this alone (each wake-up a loop iteration with its ``epoll_wait``: a third of an idle
vehicle process's CPU). :class:`MiscTicker` calls ``loop_misc()`` for every registered client
from one timer per event loop, once a second; :func:`serve_misc` is the coroutine that replaces
aiomqtt's per-client loop: it registers the client for as long as aiomqtt keeps its task (until
the socket closes) and costs nothing meanwhile.

Checked against paho-mqtt 2.2 and aiomqtt 2.5: the private name used is aiomqtt's
``Client._misc_loop`` (replaced per instance); ``tests/integration/test_socket_writer.py`` fails
if it changes.
"""

from __future__ import annotations

import asyncio
import weakref

from paho.mqtt import client as paho

__all__ = ["MiscTicker", "serve_misc"]

#: Seconds between two rounds, as aiomqtt's own loop.
PERIOD_S = 1.0

_TICKERS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, MiscTicker] = (
    weakref.WeakKeyDictionary()
)


class MiscTicker:
    """Calls ``loop_misc()`` of each registered paho client every PERIOD_S seconds."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._clients: dict[paho.Client, None] = {}  # insertion-ordered set
        self._timer: asyncio.TimerHandle | None = None
        self.rounds = 0

    @classmethod
    def of(cls, loop: asyncio.AbstractEventLoop) -> MiscTicker:
        """The ticker of ``loop`` (one per event loop)."""
        ticker = _TICKERS.get(loop)
        if ticker is None:
            ticker = _TICKERS[loop] = cls(loop)
        return ticker

    def __len__(self) -> int:
        return len(self._clients)

    def add(self, client: paho.Client) -> None:
        client.loop_misc()  # as aiomqtt's loop does first
        self._clients[client] = None
        if self._timer is None:
            self._timer = self._loop.call_later(PERIOD_S, self._round)

    def remove(self, client: paho.Client) -> None:
        self._clients.pop(client, None)
        if not self._clients and self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _round(self) -> None:
        self._timer = None
        self.rounds += 1
        for client in list(self._clients):
            if client.loop_misc() != paho.MQTT_ERR_SUCCESS:
                # the connection is gone: aiomqtt's loop would end here too
                self._clients.pop(client, None)
        if self._clients:
            self._timer = self._loop.call_later(PERIOD_S, self._round)


async def serve_misc(client: paho.Client) -> None:
    """In place of aiomqtt's ``_misc_loop`` for ``client``: registered with the loop's ticker
    until the task is cancelled (aiomqtt cancels it when the socket closes)."""
    ticker = MiscTicker.of(asyncio.get_running_loop())
    ticker.add(client)
    try:
        await asyncio.get_running_loop().create_future()
    finally:
        ticker.remove(client)
