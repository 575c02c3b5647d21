"""Writing an MQTT client's packets from the asyncio loop: at once, not one loop turn later.

aiomqtt drives paho-mqtt from the event loop through paho's socket hooks: when paho queues a
packet it calls ``on_socket_register_write``, aiomqtt answers with ``loop.add_writer`` (through
``call_soon_threadsafe``, which also writes to the loop's self-pipe), the loop wakes once more to
find the socket writable, ``loop_write`` sends the packet, and ``on_socket_unregister_write``
removes the writer again. Per publication that is two ``epoll_ctl`` calls, a self-pipe write and
read, and two more loop iterations; and since the packet is not sent when ``publish`` returns,
aiomqtt makes every QoS 0 publish wait for paho's ``on_publish`` through an ``asyncio.Event``
under ``asyncio.wait_for``. With a thousand vehicles in one process at 1 Hz visualization this
was a quarter to a third of the process's CPU (docs/performance.md).

:class:`SocketWriter` replaces those two hooks with what paho itself does when no external loop
is registered (``Client._packet_queue``): call ``loop_write()`` right away, unless paho is inside
one of its callbacks (its ``_in_callback_mutex`` is held, where paho itself says "don't call
loop_write"). The loop's writer is registered only while data remains that the kernel did not
take (the socket buffer is full), and removed when paho says everything is written. So a QoS 0
publication is on the wire when ``publish`` returns and aiomqtt returns at once; QoS 1 and 2
still wait for their acknowledgement as before. Packets leave in paho's queue order in every
case, so ordering is unchanged; a send error is handled by paho as before (it closes the socket
and reports the disconnect to aiomqtt), and an exception escaping ``loop_write`` ends the
connection the way aiomqtt's own hook does.

paho calls the register hook from the executor thread that runs ``connect()`` (the CONNECT
packet): from another thread the write is handed to the loop with ``call_soon_threadsafe``.

While no publication awaits a confirmation (aiomqtt's pending publishes are empty), the write
runs with paho's ``on_publish`` unset: paho would build a ``ReasonCode`` and a ``Properties``
object per QoS 0 packet just to tell aiomqtt, which has nothing to confirm then.

Checked against paho-mqtt 2.2 and aiomqtt 2.5 (``pyproject.toml`` pins aiomqtt < 3); the
private names used are ``paho Client._in_callback_mutex`` and aiomqtt's ``Client._client``,
``Client._disconnected`` and ``Client._pending_publishes``, and
``tests/integration/test_socket_writer.py`` fails if they change.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from typing import Any

from paho.mqtt import client as paho

__all__ = ["SocketWriter"]


class SocketWriter:
    """paho-mqtt's write hooks for a client driven by an asyncio loop (see the module doc).

    Args:
        client: The paho client; its ``on_socket_register_write`` and
            ``on_socket_unregister_write`` hooks are replaced.
        loop: The running loop that reads the client's socket.
        on_error: Called with an exception that escaped ``loop_write`` (the connection is
            broken; aiomqtt's hook sets its ``_disconnected`` future with it).
        awaited: True while some publication awaits paho's ``on_publish`` (aiomqtt's
            pending publishes); while none does, writes skip that callback.
    """

    def __init__(
        self,
        client: paho.Client,
        loop: asyncio.AbstractEventLoop,
        on_error: Callable[[Exception], None],
        awaited: Callable[[], bool] = lambda: True,
    ) -> None:
        self._client = client
        self._awaited = awaited
        self._loop = loop
        self._loop_thread = threading.get_ident()
        self._on_error = on_error
        #: The file descriptor registered with ``loop.add_writer`` while data remains, or None.
        self._watched: int | None = None
        self._flush_scheduled = False
        self._flushing = False
        #: Counters for tests and diagnostics: writes done at once, and times the loop's writer
        #: had to be registered because the kernel did not take everything.
        self.direct_writes = 0
        self.writer_registrations = 0
        client.on_socket_register_write = self._register
        client.on_socket_unregister_write = self._unregister

    def _register(self, client: paho.Client, userdata: Any, sock: Any) -> None:  # noqa: ANN401, ARG002 - paho's callback signature
        """paho has data to write (it calls this once until told everything is written)."""
        if threading.get_ident() != self._loop_thread:
            self._loop.call_soon_threadsafe(self.flush)
            return
        if self._flushing:
            return  # inside our own loop_write: flush() looks at what is left afterwards
        mutex = self._client._in_callback_mutex  # noqa: SLF001 - paho's own rule, see module doc
        if not mutex.acquire(blocking=False):
            self._schedule()
            return
        mutex.release()
        self.direct_writes += 1
        self.flush()

    def _unregister(self, client: paho.Client, userdata: Any, sock: Any) -> None:  # noqa: ANN401, ARG002 - paho's callback signature
        """paho has written everything (or is closing the socket)."""
        if self._watched is None:
            return
        if threading.get_ident() != self._loop_thread:
            self._loop.call_soon_threadsafe(self._unwatch)
            return
        self._unwatch()

    def flush(self) -> None:
        """Write what paho holds; watch the socket for writability while some of it remains."""
        self._flush_scheduled = False
        client = self._client
        if self._flushing or client.socket() is None or not client.want_write():
            # Nothing to write: not calling loop_write, which would also move paho's "last
            # message out" time (the keep-alive's) without sending anything.
            return
        self._flushing = True
        try:
            if self._awaited():
                client.loop_write()
            else:
                self._write_unobserved(client)
        except Exception as exc:  # noqa: BLE001 - as aiomqtt's hook: a broken pipe ends the connection
            self._on_error(exc)
            return
        finally:
            self._flushing = False
        if client.want_write():
            self._watch()

    @staticmethod
    def _write_unobserved(client: paho.Client) -> None:
        """loop_write without paho's ``on_publish`` call per QoS 0 packet: paho builds a
        ``ReasonCode`` and a ``Properties`` object for each only to call it, and aiomqtt's
        hook has nothing to confirm while no publication awaits one (a QoS 0 publish written
        at once returns without waiting; QoS 1/2 are confirmed by the PUBACK's path)."""
        hook = client.on_publish
        client.on_publish = None
        try:
            client.loop_write()
        finally:
            client.on_publish = hook

    def _schedule(self) -> None:
        if not self._flush_scheduled:
            self._flush_scheduled = True
            self._loop.call_soon(self.flush)

    def _watch(self) -> None:
        sock = self._client.socket()
        if self._watched is not None or sock is None:
            return
        self._watched = sock.fileno()
        self.writer_registrations += 1
        self._loop.add_writer(self._watched, self.flush)

    def _unwatch(self) -> None:
        if self._watched is not None:
            self._loop.remove_writer(self._watched)
            self._watched = None
