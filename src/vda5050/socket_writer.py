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

A QoS 0 publication can also skip paho altogether (:meth:`SocketWriter.write_qos0`): while
paho holds nothing unwritten, the PUBLISH packet (MQTT 3.1.1 §3.3, 5.0 §3.3: fixed header,
topic, an empty property list in 5.0, payload; no packet identifier at QoS 0) is built here and
handed to the socket at once. paho's per-publication work (topic checks, a message id under a
lock, an ``MQTTMessageInfo`` with its ``threading.Condition``, its packet queue and write loop)
was over half of the vehicle process's time for visualizations. What the kernel does not take
goes to paho's queue as the rest of that packet, so order holds and the loop's writer finishes
it; a socket that refuses everything or fails leaves the publication to paho, which handles it
as ever (and ends the connection on an error).

Checked against paho-mqtt 2.2 and aiomqtt 2.5 (``pyproject.toml`` pins aiomqtt < 3); the
private names used are paho ``Client._in_callback_mutex``, ``_out_packet``, ``_sock``,
``_protocol``, ``_transport``, ``_msgtime_mutex`` and ``_last_msg_out``, and aiomqtt's
``Client._client``, ``Client._disconnected`` and ``Client._pending_publishes`` (and, for the
echo check's SUBSCRIBE and UNSUBSCRIBE in :mod:`vda5050.mqtt`, ``_pending_subscribes``,
``_pending_unsubscribes`` and the callbacks that resolve them), and
``tests/integration/test_socket_writer.py`` fails if they change.
"""

from __future__ import annotations

import asyncio
import ssl
import threading
from collections.abc import Callable
from typing import Any, Final

from paho.mqtt import client as paho

#: MQTT control packet type PUBLISH in the fixed header's high nibble (3.1.1 §2.2.1).
_PUBLISH: Final = 0x30
#: Socket outcomes after which nothing was written and paho should take the publication.
_NOT_NOW: Final = (BlockingIOError, InterruptedError, ssl.SSLWantReadError, ssl.SSLWantWriteError)
#: The longest topic name (a UTF-8 string's two-byte length, §1.5.3) and remaining length
#: (four bytes of seven bits, §2.2.3) MQTT can express.
_MAX_TOPIC_BYTES: Final = 0xFFFF
_MAX_REMAINING: Final = 268_435_455

__all__ = ["SocketWriter", "qos0_publish_packet"]


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
        #: QoS 0 publications written without paho (write_qos0), and how many of them the
        #: kernel took only in part (paho's queue wrote the rest).
        self.raw_writes = 0
        self.raw_partial_writes = 0
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

    def write_qos0(self, topic: str, payload: bytes, *, retain: bool) -> bool:
        """Write a QoS 0 PUBLISH of ``payload`` on ``topic`` straight to the socket (see the
        module doc); False when paho must take it (not connected, something of paho's still
        unwritten, inside paho's write, another transport, or the socket takes nothing now)."""
        client = self._client
        sock = client._sock  # noqa: SLF001 - see the module doc
        if (
            sock is None
            or self._flushing
            or client._out_packet  # noqa: SLF001 - paho's queue must stay in front
            or client._transport not in ("tcp", "unix")  # noqa: SLF001 - websockets frame it
            or not client.is_connected()
            or threading.get_ident() != self._loop_thread
        ):
            return False
        packet = qos0_publish_packet(
            topic,
            payload,
            retain=retain,
            mqtt5=client._protocol == paho.MQTTv5,  # noqa: SLF001
        )
        if packet is None:
            return False
        try:
            sent = sock.send(packet)
        except _NOT_NOW:
            return False
        except OSError:
            return False  # paho's write meets the error again and ends the connection
        self.raw_writes += 1
        with client._msgtime_mutex:  # noqa: SLF001 - the keep-alive counts our packets too
            client._last_msg_out = paho.time_func()  # noqa: SLF001
        if sent < len(packet):
            self.raw_partial_writes += 1
            client._out_packet.append(  # noqa: SLF001 - the packet's rest, in paho's own form
                {
                    "command": _PUBLISH,
                    "mid": 0,
                    "qos": 0,
                    "pos": sent,
                    "to_process": len(packet) - sent,
                    "packet": packet,
                    "info": paho.MQTTMessageInfo(0),
                }
            )
            self._watch()
        return True

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


def qos0_publish_packet(topic: str, payload: bytes, *, retain: bool, mqtt5: bool) -> bytes | None:
    """The PUBLISH packet at QoS 0 (MQTT 3.1.1 §3.3; 5.0 §3.3 with an empty property list),
    or None for a topic paho would refuse (wildcards, empty, over 65,535 bytes: its check
    then raises the error)."""
    name = topic.encode()
    if not name or len(name) > _MAX_TOPIC_BYTES or "+" in topic or "#" in topic:
        return None
    properties = b"\x00" if mqtt5 else b""
    remaining = 2 + len(name) + len(properties) + len(payload)
    if remaining > _MAX_REMAINING:
        return None
    header = bytearray((_PUBLISH | (1 if retain else 0),))
    while True:  # the remaining length, 7 bits a byte, least significant first (§2.2.3)
        byte, remaining = remaining & 0x7F, remaining >> 7
        header.append(byte | 0x80 if remaining else byte)
        if not remaining:
            break
    return b"".join((header, len(name).to_bytes(2, "big"), name, properties, payload))
