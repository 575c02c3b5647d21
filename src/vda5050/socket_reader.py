"""Reading an MQTT client's packets in the asyncio loop: a buffer of our own, several packets
per wake-up, and a pause while the application lags.

aiomqtt registers ``loop.add_reader(sock, callback)`` when paho opens the socket; the callback
calls paho's ``loop_read()``, which reads one packet (for QoS 0 traffic) with three to four
``recv`` calls: the fixed header's first byte, the remaining length byte by byte, then the rest.
A burst of states thus costs a loop wake-up and four system calls per message.

:class:`SocketReader` gives paho a buffered ``_sock_recv`` (one ``recv`` of up to 64 KiB
refills it; paho takes its bytes from there) and replaces aiomqtt's reader callback with one
that reads packets while the buffer holds some, up to :data:`READ_BURST` per wake-up (then it
goes on in a later loop turn, so other tasks keep running). Since data in the buffer does not
wake the loop, the reader also goes on by itself whenever it stops with data left.

Back-pressure: :meth:`SocketReader.pause` stops reading (the reader is removed from the loop);
what the broker sends meanwhile waits in the kernel's buffers, then TCP holds the broker back,
which applies its own queue limits. :meth:`SocketReader.resume` reads again. The MQTT session
pauses while the messages read but not handled pass a bound (a flood against a slow service
must not grow its memory without limit), and resumes once it has caught up.

QoS 0 PUBLISH packets (states, visualizations: most of what a master receives) are taken
from the buffer without paho: :func:`qos0_publish_at` parses one whole packet, and the reader
hands topic, payload and retain flag to ``on_publish`` and notes the bytes' arrival for paho's
keep-alive as paho would. paho's own parse builds a message object with a ``threading.Condition``
for each, and reads it with three ``_sock_recv`` calls. Everything else (QoS 1 and 2, the
acknowledgements, a packet not yet whole in the buffer, MQTT 5, a topic that is not UTF-8) is
read by paho as before; packets stay in stream order, since both read the one buffer in turn
and the fast path takes a packet only while paho is between packets.

Errors are paho's as before: ``recv`` errors propagate into paho's ``_packet_read``, which
reports a lost connection (an error or the socket's end met by the reader's own refill is
kept and handed to paho's next read); an exception escaping ``loop_read`` ends the connection
the way aiomqtt's own callback does (``on_error``).

Checked against paho-mqtt 2.2 and aiomqtt 2.5 (``pyproject.toml`` pins aiomqtt < 3); the
private names used are paho's ``Client._sock_recv`` (replaced per instance), ``_in_packet``,
``_msgtime_mutex`` and ``_last_bytes_received``, and its ``on_socket_open`` hook as aiomqtt
sets it; ``tests/integration/test_socket_writer.py`` fails if they change.
"""

from __future__ import annotations

import asyncio
import ssl
from collections.abc import Callable
from typing import Any

from paho.mqtt import client as paho

__all__ = ["READ_BURST", "RECV_SIZE", "SocketReader", "qos0_publish_at"]

#: Bytes asked of the kernel per ``recv`` (a TLS socket returns at most one record, 16 KiB).
RECV_SIZE = 65536
#: Packets read per loop wake-up before the reader lets other callbacks run.
READ_BURST = 64


#: A PUBLISH at QoS 0 without DUP, retained or not (MQTT 3.1.1 §3.3.1): the first byte & 0xFE.
_QOS0_PUBLISH = 0x30


def qos0_publish_at(buffer: bytes, offset: int) -> tuple[str, bytes, bool, int] | None:
    """The QoS 0 PUBLISH packet (MQTT 3.1.1 §3.3) that starts at ``offset``, if it is whole in
    ``buffer``: (topic, payload, retain, offset after it); None for any other packet, one not
    whole yet, an empty topic or one that is not UTF-8 (paho reads those, and reports them)."""
    end = len(buffer)
    if offset + 2 > end or buffer[offset] & 0xFE != _QOS0_PUBLISH:
        return None
    remaining, shift, position = 0, 0, offset + 1
    while True:  # the remaining length: 7 bits a byte, least significant first, 4 bytes at most
        if position >= end or shift > 21:  # noqa: PLR2004 - 4 bytes of 7 bits
            return None
        byte = buffer[position]
        remaining |= (byte & 0x7F) << shift
        position += 1
        if not byte & 0x80:
            break
        shift += 7
    stop = position + remaining
    if stop > end or remaining < 2:  # noqa: PLR2004 - the topic's length field
        return None
    length = buffer[position] << 8 | buffer[position + 1]
    topic_end = position + 2 + length
    if length == 0 or topic_end > stop:
        return None
    try:
        topic = buffer[position + 2 : topic_end].decode()
    except UnicodeDecodeError:
        return None
    return topic, buffer[topic_end:stop], bool(buffer[offset] & 1), stop


class SocketReader:
    """paho-mqtt's reads for a client driven by an asyncio loop (see the module doc).

    Args:
        client: The paho client, before it connects; its ``_sock_recv`` and
            ``on_socket_open`` are replaced (the latter wraps aiomqtt's).
        loop: The running loop.
        on_error: Called with an exception that escaped ``loop_read`` (the connection is
            broken).
        on_publish: Called with (topic, payload, retain) of each QoS 0 PUBLISH read without
            paho (MQTT 3.1.1 only); None: paho reads every packet.
    """

    def __init__(
        self,
        client: paho.Client,
        loop: asyncio.AbstractEventLoop,
        on_error: Callable[[Exception], None],
        on_publish: Callable[[str, bytes, bool], None] | None = None,
    ) -> None:
        self._client = client
        self._loop = loop
        self._on_error = on_error
        self._on_publish = on_publish if client._protocol != paho.MQTTv5 else None  # noqa: SLF001
        #: QoS 0 publications read without paho (for tests and diagnostics).
        self.raw_reads = 0
        #: Set when a refill of the buffer met the socket's end or an error: paho meets it
        #: on its next read, as if it had read the socket itself.
        self._refill_problem: OSError | None = None
        self._at_end = False
        self._buffer = b""
        self._offset = 0
        self._fd: int | None = None
        self._sock: Any = None
        self._paused = False
        self._going_on = False
        self._recv = client._sock_recv  # noqa: SLF001 - see the module doc
        client._sock_recv = self._buffered_recv  # type: ignore[method-assign]  # noqa: SLF001
        opened = client.on_socket_open

        def socket_open(paho_client: paho.Client, userdata: Any, sock: Any) -> None:  # noqa: ANN401 - paho's callback signature
            if opened is not None:
                opened(paho_client, userdata, sock)  # aiomqtt's: its reader and its misc task
            # paho calls this from the thread that connects; queued after aiomqtt's add_reader,
            # so that ours replaces it
            loop.call_soon_threadsafe(self._opened, sock)

        client.on_socket_open = socket_open

    @property
    def buffered(self) -> int:
        """Bytes read from the socket that paho has not taken yet."""
        return len(self._buffer) - self._offset

    @property
    def paused(self) -> bool:
        return self._paused

    def pause(self) -> None:
        """Stop reading until :meth:`resume`."""
        if self._paused:
            return
        self._paused = True
        if self._fd is not None:
            self._loop.remove_reader(self._fd)

    def resume(self) -> None:
        """Read again (at once, since buffered data does not wake the loop)."""
        if not self._paused:
            return
        self._paused = False
        if self._fd is not None and self._client.socket() is self._sock:
            self._loop.add_reader(self._fd, self.read)
            self._go_on_later()

    def _opened(self, sock: Any) -> None:  # noqa: ANN401 - paho's socket type
        current = self._client.socket()
        if current is None or current is not sock:
            return  # closed again before the loop got here
        self._sock = current
        self._fd = current.fileno()
        if self._paused:
            self._loop.remove_reader(self._fd)
        else:
            self._loop.add_reader(self._fd, self.read)

    def read(self) -> None:
        """The loop's reader callback: packets while there are buffered bytes, READ_BURST at
        most; goes on in a later loop turn when it stopped with bytes left."""
        client = self._client
        try:
            for _ in range(READ_BURST):
                if not self._take_publish():
                    client.loop_read()
                if self._paused or not self._has_more():
                    return
        except Exception as exc:  # noqa: BLE001 - as aiomqtt's callback: the connection is broken
            self._on_error(exc)
            return
        self._go_on_later()

    def _go_on_later(self) -> None:
        if not self._going_on:
            self._going_on = True
            self._loop.call_soon(self._go_on)

    def _go_on(self) -> None:
        self._going_on = False
        if not self._paused and self._client.socket() is self._sock and self._has_more():
            self.read()

    def _take_publish(self) -> bool:
        """Hand the QoS 0 PUBLISH at the buffer's start to ``on_publish`` without paho; False
        when paho must read the next packet (see the module doc)."""
        on_publish = self._on_publish
        client = self._client
        if on_publish is None or client._in_packet["command"]:  # noqa: SLF001 - paho mid-packet
            return False
        if self._offset >= len(self._buffer) and not self._refill():
            return False
        packet = qos0_publish_at(self._buffer, self._offset)
        if packet is None:
            return False
        topic, payload, retain, self._offset = packet
        self.raw_reads += 1
        with client._msgtime_mutex:  # noqa: SLF001 - the keep-alive, as paho's read sets it
            client._last_bytes_received = paho.time_func()  # noqa: SLF001
        on_publish(topic, payload, retain)
        return True

    def _refill(self) -> bool:
        """One ``recv`` into the empty buffer; False when it got nothing (paho then reads, and
        meets the socket's end or error that this read met, see :meth:`_buffered_recv`)."""
        if self._refill_problem is not None or self._at_end:
            return False
        try:
            data = self._recv(RECV_SIZE)
        except BlockingIOError:
            return False
        except OSError as exc:
            self._refill_problem = exc
            return False
        if not data:
            self._at_end = True
            return False
        self._buffer, self._offset = data, 0
        return True

    def _has_more(self) -> bool:
        if self._offset < len(self._buffer):
            return True
        sock = self._client.socket()
        return isinstance(sock, ssl.SSLSocket) and sock.pending() > 0

    def _buffered_recv(self, bufsize: int) -> bytes:
        """paho's ``_sock_recv``: up to ``bufsize`` bytes from the buffer, refilled with one
        ``recv`` when empty (BlockingIOError when the socket has nothing, b"" at its end)."""
        if self._offset >= len(self._buffer):
            problem, self._refill_problem = self._refill_problem, None
            if problem is not None:
                raise problem
            if self._at_end:
                return b""
            data = self._recv(RECV_SIZE)
            if len(data) <= bufsize:
                self._buffer, self._offset = b"", 0
                return data
            self._buffer, self._offset = data, 0
        start = self._offset
        self._offset = min(start + bufsize, len(self._buffer))
        return self._buffer[start : self._offset]
