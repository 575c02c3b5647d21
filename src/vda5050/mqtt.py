"""The MQTT session: the only module that talks to aiomqtt.

One :class:`MqttSession` per MQTT client (a vehicle, or master control). It

- connects with an optional last will and retries the first connection as well as later ones,
  with capped, fully jittered exponential backoff;
- after every (re)connect subscribes again and runs the ``on_connected`` hook;
- dispatches each received message to the handlers whose filter matches its topic, and drops
  messages on topics it did not subscribe to;
- publishes with the QoS and retain flag of each VDA 5050 topic (digest §1.3) through an
  :class:`Outbox`, so publishing never raises into the caller, connected or not; a
  visualization goes to the socket at once while nothing waits in the outbox;
- sets TCP_NODELAY on its socket (Nagle adds ~25 ms per message, see mqtt-notes);
- leaves paho's keep-alive housekeeping to one timer per process (:mod:`vda5050.misc_ticker`)
  instead of aiomqtt's task per connection;
- reads several packets per wake-up through a buffer of its own (:mod:`vda5050.socket_reader`)
  and takes received messages from paho into a queue of its own, handled in batches by one
  loop (aiomqtt's message iterator costs a task and three loop turns per message); it stops
  reading while that queue is over a bound, so a flood cannot grow its memory without limit;
- writes each packet to the socket when it is published, and watches the socket for
  writability only while the kernel's buffer is full (:mod:`vda5050.socket_writer`), instead of
  aiomqtt's register-a-writer-per-packet;
- speaks TLS for ``mqtts://`` with the ``tls_*`` files (:mod:`vda5050.tls`), with a hint in the
  log when the handshake fails;
- makes refusals loud (:mod:`vda5050.access`): a SUBACK 0x80 is logged as ERROR
  ``mqtt.subscribe_denied``, and a publication on a :meth:`MqttSession.verify_echo` filter that
  does not come back as ERROR ``mqtt.publish_denied``; both are kept in
  :attr:`MqttSession.access_problems` and passed to the ``on_access_changed`` hook.

The outbox policy is in :mod:`vda5050.outbox`.
"""

from __future__ import annotations

import array
import asyncio
import fcntl
import functools
import logging
import math
import random
import socket
import ssl
import termios
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import aiomqtt
import structlog
from paho.mqtt import client as mqtt

from vda5050.access import AccessChange, AccessMonitor, AccessProblem, topic_matches
from vda5050.errors import ConfigError
from vda5050.misc_ticker import serve_misc
from vda5050.mqtt_connect import LoopConnectClient
from vda5050.mqtt_settings import BrokerEndpoint, MqttSettings
from vda5050.outbox import OFFLINE_POLICY, OfflinePolicy, Outbox, Outgoing, Payload
from vda5050.socket_reader import SocketReader
from vda5050.socket_writer import SocketWriter
from vda5050.tls import TransportErrors, tls_context, tls_hint
from vda5050.topics import DELIVERY, Topic

__all__ = [
    "OFFLINE_POLICY",
    "AccessHook",
    "BrokerEndpoint",
    "ConnectedHook",
    "InboundMessage",
    "MessageHandler",
    "MqttSession",
    "MqttSettings",
    "OfflinePolicy",
    "Outbox",
    "Outgoing",
    "Payload",
    "Will",
]

log = structlog.get_logger()

MessageHandler = Callable[["InboundMessage"], Awaitable[None]]
ConnectedHook = Callable[[], Awaitable[None]]
AccessHook = Callable[[tuple[AccessProblem, ...]], None]

_NOT_AUTHORISED_CODES = frozenset({4, 5, 134, 135})
#: Topics whose matching handlers a session remembers at most.
_HANDLER_CACHE_LIMIT = 100_000
#: Publications the drain loop hands over before it lets other tasks run: a QoS 0 publication
#: is written without suspending (vda5050.socket_writer), so a long outbox would otherwise hold
#: the event loop until it is empty.
_PUBLISH_BURST = 64
#: QoS 1/2 publications on the wire awaiting their acknowledgement at most: the messages behind
#: one go out without waiting a round trip (_publish_acknowledged).
_UNACKED_LIMIT = 100
#: Received messages handled in a row before the receive loop lets other tasks run (twice the
#: reader's READ_BURST: handling keeps up with reading, so the queue stays short).
_RECEIVE_BURST = 128
#: Read but unhandled messages (count, payload bytes) above which the session stops reading
#: the socket (the broker is held back by TCP), and below which it reads again.
_INBOUND_PAUSE = (20_000, 32 * 1024 * 1024)
_INBOUND_RESUME = (5_000, 8 * 1024 * 1024)
#: Seconds between two log lines about reading paused.
_PAUSE_LOG_S = 60.0


@dataclass(frozen=True, slots=True)
class Will:
    """A last will, registered in CONNECT (§6.14: CONNECTIONBROKEN, QoS 1, retained)."""

    topic: str
    payload: bytes
    qos: int = 1
    retain: bool = True


@dataclass(frozen=True, slots=True)
class InboundMessage:
    """A message received on a subscribed topic."""

    topic: str
    payload: bytes
    retain: bool = False
    qos: int = 0


def _return_code(error: BaseException) -> int | None:
    """The CONNACK return code (MQTT 3.1.1) or reason code (MQTT 5) of a refused connect."""
    rc = getattr(error, "rc", None)
    value = getattr(rc, "value", rc)
    return value if isinstance(value, int) else None


@dataclass(slots=True)
class _Subscription:
    topic_filter: str
    handler: MessageHandler
    qos: int
    #: Subscribed at the broker (set_subscribed turns it off and on).
    active: bool = True


class MqttSession:
    """One MQTT client connection with reconnects, an outbox and topic dispatch."""

    def __init__(
        self,
        settings: MqttSettings,
        *,
        will: Will | Callable[[], Will] | None = None,
        on_connected: ConnectedHook | None = None,
        on_access_changed: AccessHook | None = None,
        name: str = "mqtt",
    ) -> None:
        self._settings = settings
        self._endpoint = settings.endpoint
        self._tls = _tls_context(settings, self._endpoint)
        self._access = AccessMonitor(check_s=settings.publish_check_s)
        self._expiry: asyncio.TimerHandle | None = None
        self._on_access_changed = on_access_changed
        #: TLS hints logged as ERROR since the last successful connect (each once).
        self._tls_problems: set[str] = set()
        self._transport_errors = TransportErrors()
        # The library's logger, one per session so a late TLS alert is told to the right one;
        # not registered by name (getLogger would share it between equally named sessions).
        self._library_log = logging.Logger(f"mqtt.{name}")  # noqa: LOG001
        self._library_log.parent = logging.getLogger("mqtt")
        self._library_log.addHandler(self._transport_errors)
        self._will = will
        self._on_connected = on_connected
        self._name = name
        self._subscriptions: list[_Subscription] = []
        self._handlers: dict[str, list[MessageHandler]] = {}
        self._outbox = Outbox(limit=settings.outbox_limit)
        self._wake = asyncio.Event()
        self._connected = asyncio.Event()
        self._stopping = asyncio.Event()
        self._finished = asyncio.Event()
        self._in_hook = False
        self._running = False
        self._was_connected = False
        #: Whether the last connection ended before the broker's CONNACK (for the TLS hint).
        self._ended_before_connack = False
        self._live_client: aiomqtt.Client | None = None
        #: The write and read hooks of the live connection's paho client (diagnostics, tests).
        self.writer: SocketWriter | None = None
        self.reader: SocketReader | None = None
        #: Times reading was paused for a backlog, and when that was last logged.
        self.read_pauses = 0
        self._pause_logged_at = -math.inf
        #: Echo-check SUBSCRIBEs and UNSUBSCRIBEs under way (references keep them alive).
        self._background: set[asyncio.Future[object]] = set()
        #: Messages read from the socket and not yet handled, oldest first (paho's, and the
        #: QoS 0 ones the socket reader read without paho), their payload bytes, and the
        #: receive loop's wake-up while it waits for more.
        self._inbound: deque[mqtt.MQTTMessage | InboundMessage] = deque()
        #: Echo-checked topics whose check the current receive burst completed.
        self._echoes_done: list[str] = []
        self._queued_bytes = 0
        self._inbound_arrived: asyncio.Future[None] | None = None
        #: QoS 1/2 publications written and not acknowledged yet, oldest first.
        self._unacked: dict[asyncio.Future[None], Outgoing] = {}
        self.connect_count = 0

    # -- public API ------------------------------------------------------------------------

    @property
    def connected(self) -> bool:
        """True while the session is connected and its hook has run."""
        return self._connected.is_set()

    @property
    def outbox(self) -> Outbox:
        return self._outbox

    @property
    def access_problems(self) -> tuple[AccessProblem, ...]:
        """What the broker refuses this client now (refused subscriptions, publications that
        did not come back); empty when all is well."""
        return self._access.problems

    async def wait_connected(self) -> None:
        """Return once the session is connected (bound it with asyncio.timeout)."""
        await self._connected.wait()

    def subscribe(
        self, topic_filter: str, handler: MessageHandler, qos: int = 0, *, active: bool = True
    ) -> None:
        """Register ``handler`` for ``topic_filter``; call before :meth:`run`. With
        ``active=False`` the broker is asked for it only once :meth:`set_subscribed` says so."""
        if self._running:
            msg = "subscribe() must be called before run()"
            raise RuntimeError(msg)
        self._subscriptions.append(_Subscription(topic_filter, handler, qos, active))

    def set_subscribed(self, topic_filter: str, *, subscribed: bool) -> None:
        """Subscribe to a filter registered with :meth:`subscribe`, or unsubscribe from it:
        at once when connected (SUBSCRIBE or UNSUBSCRIBE, not waited for; a refused SUBACK is
        reported as for the other filters), and on every later connect. For topics wanted only
        at times (master control's visualization, while a live map is open)."""
        matching = [s for s in self._subscriptions if s.topic_filter == topic_filter]
        if not matching:
            msg = f"{topic_filter!r} was not registered with subscribe()"
            raise KeyError(msg)
        if all(s.active == subscribed for s in matching):
            return
        for registered in matching:
            registered.active = subscribed
        client = self._live_client
        if client is None:
            return  # the next connect subscribes what is active
        if subscribed:
            qos = max(s.qos for s in matching)
            self._in_background(
                client.subscribe(topic_filter, qos=qos), self._subacked(topic_filter)
            )
        else:
            self._in_background(client.unsubscribe(topic_filter), None)

    def verify_echo(self, topic_filter: str, *, after_evidence: bool = False) -> None:
        """Check that the first message this client publishes on each topic matching
        ``topic_filter`` after a connect comes back within ``publish_check_s`` (else ERROR
        ``mqtt.publish_denied``): the session subscribes to that topic just before and
        unsubscribes when it came back. With ``after_evidence`` the check waits for the
        second message, unless :meth:`delivered` proved the first (:mod:`vda5050.access`). The
        ACL must let the client read these topics back; call before :meth:`run`."""
        if self._running:
            msg = "verify_echo() must be called before run()"
            raise RuntimeError(msg)
        self._access.watch(topic_filter, after_evidence=after_evidence)

    def delivered(self, topic: str) -> None:
        """A reader's reaction proves that a message published on ``topic`` got through the
        broker: no echo check of it on this connection (:meth:`AccessMonitor.delivered`)."""
        change, open_check = self._access.delivered(topic)
        self._report(change)
        if open_check:
            self._check_done(topic)

    def publish(self, topic: str, kind: Topic, payload: Payload) -> None:
        """Queue a VDA 5050 message for ``topic``; QoS and retain follow ``kind`` (§1.3)."""
        if kind is Topic.VISUALIZATION and self._publish_at_once(topic, payload):
            return
        self._outbox.put(Outgoing(topic, kind, payload), online=self.connected, front=self._in_hook)
        self._wake.set()

    def _publish_at_once(self, topic: str, payload: Payload) -> bool:
        """A visualization (QoS 0, dropped while offline, no order to keep with the other
        topics) goes to paho at once when nothing waits in the outbox and no echo check watches
        its topic: a vehicle publishes one a second, and the drain loop's wake-up for it was a
        task switch per message. False when it must take the outbox's way."""
        client = self._live_client
        if (
            client is None
            or not self._connected.is_set()
            or len(self._outbox)
            or self._access.watching(topic)
        ):
            return False
        body = payload() if callable(payload) else payload
        retain = DELIVERY[Topic.VISUALIZATION].retain
        if self.writer is not None and self.writer.write_qos0(topic, body, retain=retain):
            return True
        info = client._client.publish(topic, body, 0, retain)  # noqa: SLF001
        if info.rc != mqtt.MQTT_ERR_SUCCESS:  # the connection just ended: the outbox's way
            self._outbox.put(Outgoing(topic, Topic.VISUALIZATION, body), online=self.connected)
            self._wake.set()
        return True

    async def stop(self, *final: Outgoing, timeout_s: float = 5.0) -> None:
        """Publish ``final`` (e.g. OFFLINE) if connected, disconnect cleanly and end :meth:`run`."""
        for item in final:
            self._outbox.put(item, online=self.connected)
        self._stopping.set()
        self._wake.set()
        if not self._running:
            return
        try:
            async with asyncio.timeout(timeout_s):
                await self._finished.wait()
        except TimeoutError:
            log.warning("mqtt.stop_timed_out", session=self._name, timeout_s=timeout_s)

    async def run(self) -> None:
        """Connect, serve and reconnect until :meth:`stop` is called."""
        self._running = True
        attempt = 0
        try:
            while not self._stopping.is_set():
                error = await self._serve_until_disconnected()
                if error is None:
                    attempt = 0
                elif not self._stopping.is_set():
                    attempt += 1
                    await self._back_off(error, attempt)
        finally:
            self._connected.clear()
            self._finished.set()

    # -- connection ------------------------------------------------------------------------

    async def _serve_until_disconnected(self) -> aiomqtt.MqttError | None:
        """Serve one connection; return the transport error that ended it, if any."""
        errors: list[aiomqtt.MqttError] = []
        try:
            await self._serve_one_connection()
        except* aiomqtt.MqttError as group:
            errors.extend(e for e in group.exceptions if isinstance(e, aiomqtt.MqttError))
        self._live_client = None
        if not errors:
            return None
        self._connected.clear()
        self._ended_before_connack = not self._was_connected
        if self._was_connected:
            log.warning("mqtt.disconnected", session=self._name, reason=str(errors[0]))
        self._was_connected = False
        return errors[0]

    def _client(self) -> LoopConnectClient:
        will = self._will() if callable(self._will) else self._will
        endpoint = self._endpoint
        client = LoopConnectClient(
            endpoint.host,
            endpoint.port,
            username=endpoint.username,
            password=endpoint.password,
            identifier=self._settings.client_id,
            will=aiomqtt.Will(will.topic, will.payload, will.qos, will.retain) if will else None,
            clean_session=self._settings.clean_session,
            keepalive=self._settings.keepalive_s,
            timeout=self._settings.connect_timeout_s,
            tls_context=self._tls,
            logger=self._library_log,
            socket_options=[(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)],
        )

        def broken(error: Exception) -> None:  # what aiomqtt's own write hook does
            disconnected = client._disconnected  # noqa: SLF001
            if not disconnected.done():
                disconnected.set_exception(error)

        client.pending_calls_threshold = _UNACKED_LIMIT + 20  # else a warning per publication
        paho_client = client._client  # noqa: SLF001 - aiomqtt exposes no public accessor
        pending = client._pending_publishes  # noqa: SLF001 - see vda5050.socket_writer
        self.writer = SocketWriter(
            paho_client, asyncio.get_running_loop(), broken, awaited=lambda: bool(pending)
        )
        self.reader = SocketReader(
            paho_client, asyncio.get_running_loop(), broken, on_publish=self._on_raw_publish
        )
        # keep-alive housekeeping on one timer for all sessions (vda5050.misc_ticker)
        client._misc_loop = functools.partial(serve_misc, paho_client)  # type: ignore[method-assign]  # noqa: SLF001
        # What an earlier connection received and did not get to handle stays queued: it is
        # handled on this one (with aiomqtt's queue it was lost with the connection).
        paho_client.on_message = self._on_message  # instead of aiomqtt's queue
        return client

    def _on_message(self, paho: mqtt.Client, userdata: Any, message: mqtt.MQTTMessage) -> None:  # noqa: ANN401, ARG002 - paho's signature
        """paho's callback (in the loop's reader): queue the message for the receive loop."""
        self._queue(message, len(message.payload))

    def _on_raw_publish(self, topic: str, payload: bytes, retain: bool) -> None:  # noqa: FBT001 - the reader's callback
        """A QoS 0 publication the socket reader read without paho (vda5050.socket_reader)."""
        self._queue(InboundMessage(topic, payload, retain, 0), len(payload))

    def _queue(self, message: mqtt.MQTTMessage | InboundMessage, size: int) -> None:
        self._inbound.append(message)
        self._queued_bytes += size
        if len(self._inbound) > _INBOUND_PAUSE[0] or self._queued_bytes > _INBOUND_PAUSE[1]:
            self._pause_reading()
        self._wake_receiver()

    def _pause_reading(self) -> None:
        reader = self.reader
        if reader is None or reader.paused:
            return
        reader.pause()
        self.read_pauses += 1
        now = asyncio.get_running_loop().time()
        if now - self._pause_logged_at >= _PAUSE_LOG_S:
            self._pause_logged_at = now
            log.warning(
                "mqtt.reading_paused",
                session=self._name,
                unhandled_messages=len(self._inbound),
                unhandled_bytes=self._queued_bytes,
                pauses=self.read_pauses,
                detail="handling lags behind receiving; the broker is held back until it caught up",
            )

    def _resume_reading(self) -> None:
        reader = self.reader
        if (
            reader is not None
            and reader.paused
            and len(self._inbound) <= _INBOUND_RESUME[0]
            and self._queued_bytes <= _INBOUND_RESUME[1]
        ):
            reader.resume()

    def _wake_receiver(self, _: object = None) -> None:
        arrived = self._inbound_arrived
        if arrived is not None and not arrived.done():
            arrived.set_result(None)

    def backlog(self) -> tuple[int, int]:
        """How far the session lags: (inbound bytes not handled yet, messages not sent yet)."""
        return self.inbound_backlog_bytes(), len(self._outbox)

    def inbound_backlog_bytes(self) -> int:
        """Bytes the broker has sent that this client has not handled yet: the kernel's receive
        queue of the connection (FIONREAD) plus the payloads read from the socket that wait in
        the client's message queue for the handlers (the socket is read more eagerly than the
        handlers run: thousands of messages can wait there while the socket looks drained).
        Above a few messages' worth, what the session handles lags behind what the broker
        delivered. 0 when not connected."""
        sock = self._current_socket()
        if sock is None:
            return 0
        try:
            waiting = array.array("i", [0])
            fcntl.ioctl(sock.fileno(), termios.FIONREAD, waiting)
        except OSError:
            return 0
        buffered = self.reader.buffered if self.reader is not None else 0
        return int(waiting[0]) + buffered + self._queued_bytes

    def _current_socket(self) -> socket.socket | None:
        """The TCP socket of the live connection (diagnostics and tests)."""
        client = self._live_client
        if client is None:
            return None
        raw = client._client.socket()  # noqa: SLF001 - aiomqtt exposes no public accessor
        return raw if isinstance(raw, socket.socket) else None

    async def _serve_one_connection(self) -> None:
        async with self._client() as client:
            self._live_client = client
            self._tls_problems.clear()
            self._echoes_done = []  # the subscriptions of an earlier connection are gone
            await self._subscribe_all(client)
            self.connect_count += 1
            log.info(
                "mqtt.connected",
                session=self._name,
                broker=self._endpoint.display,
                connects=self.connect_count,
            )
            await self._run_hook()
            self._connected.set()
            self._was_connected = True
            try:
                async with asyncio.TaskGroup() as group:
                    receiver = group.create_task(
                        self._receive_loop(client), name=f"{self._name}.receive_loop"
                    )
                    await self._drain_loop(client)
                    receiver.cancel()
            finally:
                self._stop_expiry()
                self._requeue_unacknowledged()
            log.info("mqtt.disconnected", session=self._name, reason="stopped")

    async def _subscribe_all(self, client: aiomqtt.Client) -> None:
        """Subscribe to the handlers' filters, and to the plain topics of echo checks (a
        vehicle's own ``connection`` and ``state``): one SUBSCRIBE and one round trip per
        connect instead of one more per checked topic before its first publication (a
        thousand vehicles connect at once); report refused ones (SUBACK)."""
        self._access.connected()
        wanted = [(s.topic_filter, s.qos) for s in self._subscriptions if s.active]
        handled = {s.topic_filter for s in self._subscriptions}
        echoes = [t for t in self._access.exact_topics() if t not in handled]
        for topic in echoes:
            self._access.echo_subscribing(topic)  # before the SUBACK: a retained echo may come
        if not wanted and not echoes:
            return
        codes = list(await client.subscribe(wanted + [(topic, 0) for topic in echoes]))
        self._report(self._access.subscribed([f for f, _ in wanted], codes[: len(wanted)]))
        for topic, code in zip(echoes, codes[len(wanted) :], strict=False):
            self._report(self._access.echo_subscribed(topic, code))

    def _report(self, change: AccessChange) -> None:
        """One ERROR per refusal found, one INFO per refusal that ended; then the hook."""
        if not change:
            return
        for problem in change.raised:
            log.error(
                problem.kind.event,
                session=self._name,
                topic=problem.topic,
                broker=self._endpoint.display,
                username=self._endpoint.username,
                hint=problem.description,
            )
        for problem in change.cleared:
            log.info(
                "mqtt.access_restored",
                session=self._name,
                kind=problem.kind.value,
                topic=problem.topic,
            )
        if self._on_access_changed is not None:
            self._on_access_changed(self._access.problems)

    def _expire_echoes(self) -> None:
        """Publications whose echo is overdue become ``publish_denied``. A timer callback, set
        only while an echo is awaited (a task per session would cost a fleet of a thousand
        vehicles in one process memory and collector time for nothing)."""
        loop = asyncio.get_running_loop()
        self._expiry = None
        self._report(self._access.expire(loop.time()))
        deadline = self._access.next_deadline()
        if deadline is not None:
            self._expiry = loop.call_at(deadline, self._expire_echoes)

    def _stop_expiry(self) -> None:
        if self._expiry is not None:
            self._expiry.cancel()
            self._expiry = None

    async def _run_hook(self) -> None:
        if self._on_connected is None:
            return
        self._in_hook = True
        try:
            await self._on_connected()
        finally:
            self._in_hook = False

    async def _back_off(self, error: BaseException, attempt: int) -> None:
        ceiling = min(
            self._settings.reconnect_max_s, self._settings.reconnect_min_s * 2 ** min(attempt, 20)
        )
        delay = random.uniform(self._settings.reconnect_min_s, max(ceiling, 0.0))  # noqa: S311
        hint = self._hint(error)
        log.warning(
            "mqtt.reconnect_scheduled",
            session=self._name,
            broker=self._endpoint.display,
            error=str(error) or type(error).__name__,
            hint=hint,
            attempt=attempt,
            delay_s=round(delay, 2),
        )
        try:
            async with asyncio.timeout(delay):
                await self._stopping.wait()
        except TimeoutError:
            pass

    def _hint(self, error: BaseException) -> str | None:
        """What to change for a refused connect; a TLS problem is also logged once as ERROR."""
        if _return_code(error) in _NOT_AUTHORISED_CODES:
            return "the broker refused the credentials: check username and password"
        text = f"{error} {self._transport_errors.last or ''}"
        self._transport_errors.last = None
        hint = (
            tls_hint(text, self._settings.tls_files, before_connack=self._ended_before_connack)
            if self._endpoint.tls
            else None
        )
        if hint is not None and hint not in self._tls_problems:
            self._tls_problems.add(hint)
            log.error(
                "mqtt.tls_failed",
                session=self._name,
                broker=self._endpoint.display,
                error=str(error),
                hint=hint,
            )
        return hint

    # -- traffic ---------------------------------------------------------------------------

    async def _drain_loop(self, client: aiomqtt.Client) -> None:
        """Publish queued messages until stopping with an empty outbox."""
        burst = 0
        while True:
            if burst >= _PUBLISH_BURST:
                burst = 0
                await asyncio.sleep(0)  # before taking the next item: a cancel loses nothing
            item = self._outbox.pop()
            if item is None:
                if self._stopping.is_set():
                    await self._acknowledged()  # e.g. the final OFFLINE, before DISCONNECT
                    return
                self._wake.clear()
                burst = 0
                await self._wake.wait()
                continue
            burst += 1
            delivery = DELIVERY[item.kind]
            body = item.body()
            item.payload = body  # a retry sends the same bytes, stamped once
            if self._access.wants_subscription(item.topic):
                # Not waiting for the SUBACK (a round trip per new topic would serialise a burst
                # of orders to a thousand vehicles): the SUBSCRIBE goes out before the PUBLISH.
                self._access.echo_subscribing(item.topic)
                _subscribe_at_once(client, item.topic, self._echo_subacked(item.topic))
            # Noted before the send: the echo may arrive before the PUBACK is processed.
            loop = asyncio.get_running_loop()
            if self._access.published(item.topic, body, loop.time()) and self._expiry is None:
                self._expiry = loop.call_at(loop.time() + self._access.check_s, self._expire_echoes)
            try:
                if delivery.qos == 0:
                    if self.writer is None or not self.writer.write_qos0(
                        item.topic, body, retain=delivery.retain
                    ):
                        await client.publish(item.topic, body, qos=0, retain=delivery.retain)
                else:
                    await self._publish_acknowledged(client, item, body)
            except aiomqtt.MqttError:
                self._outbox.push_back(item)
                raise

    async def _publish_acknowledged(
        self, client: aiomqtt.Client, item: Outgoing, body: bytes
    ) -> None:
        """Write a QoS 1/2 publication and await its acknowledgement in the background: the
        broker handles one connection's packets in order, so what is queued behind it goes
        out at once (a vehicle's factsheet and state behind its ONLINE waited a round trip,
        seconds when a thousand vehicles connect at once). At most _UNACKED_LIMIT wait; those
        not acknowledged when the connection ends are published again on the next one
        (_requeue_unacknowledged), as a publication that failed is."""
        while len(self._unacked) >= _UNACKED_LIMIT:
            waiting = [f for f in self._unacked if not f.done()]
            if not waiting:
                break
            await asyncio.wait(waiting, return_when=asyncio.FIRST_COMPLETED)
        delivery = DELIVERY[item.kind]
        publishing = asyncio.ensure_future(
            client.publish(
                item.topic, body, qos=delivery.qos, retain=delivery.retain, timeout=math.inf
            )
        )
        self._unacked[publishing] = item
        publishing.add_done_callback(self._acknowledgement)
        await asyncio.sleep(0)  # the new task writes its PUBLISH before the next one goes out
        if publishing.done() and not publishing.cancelled():
            error = publishing.exception()
            if isinstance(error, aiomqtt.MqttError):
                self._unacked.pop(publishing, None)
                raise error

    def _acknowledgement(self, publishing: asyncio.Future[None]) -> None:
        """An acknowledged publication is done with; a failed one stays for the requeue."""
        if not publishing.cancelled() and publishing.exception() is None:
            self._unacked.pop(publishing, None)

    async def _acknowledged(self) -> None:
        """Wait until every publication written so far is acknowledged (or failed)."""
        waiting = [f for f in self._unacked if not f.done()]
        if waiting:
            await asyncio.wait(waiting)

    def _requeue_unacknowledged(self) -> None:
        """The connection ended: publications it did not acknowledge go first on the next
        one, in their order, unless a newer message of the same topic already waits (state,
        connection and factsheet keep only the latest, vda5050.outbox)."""
        for publishing, item in reversed(list(self._unacked.items())):
            publishing.cancel()
            if not self._outbox.replaced(item):
                self._outbox.push_back(item)
        self._unacked.clear()

    async def _receive_loop(self, client: aiomqtt.Client) -> None:
        """Handle received messages in order, _RECEIVE_BURST in a row; MqttError when the
        connection ends (as aiomqtt's message iterator raises it)."""
        loop = asyncio.get_running_loop()
        disconnected = client._disconnected  # noqa: SLF001 - aiomqtt exposes no public accessor
        disconnected.add_done_callback(self._wake_receiver)
        inbound = self._inbound
        try:
            while True:
                for _ in range(_RECEIVE_BURST):
                    if not inbound:
                        break
                    await self._handle(inbound.popleft())
                if self._echoes_done:
                    # One UNSUBSCRIBE for the checks this burst completed (a vehicle's ONLINE
                    # and first state come back together), not waiting for the UNSUBACK: that
                    # would stall every message behind.
                    _unsubscribe_at_once(client, self._echoes_done)
                    self._echoes_done = []
                self._resume_reading()
                if inbound:
                    await asyncio.sleep(0)
                    continue
                if disconnected.done():
                    msg = "Disconnected during message iteration"
                    raise aiomqtt.MqttError(msg) from disconnected.exception()
                self._inbound_arrived = loop.create_future()
                await self._inbound_arrived
        finally:
            self._inbound_arrived = None
            disconnected.remove_done_callback(self._wake_receiver)

    async def _handle(self, message: mqtt.MQTTMessage | InboundMessage) -> None:
        if isinstance(message, InboundMessage):
            inbound = message
        else:
            body = bytes(message.payload)  # paho reads bytes: no copy
            inbound = InboundMessage(message.topic, body, bool(message.retain), message.qos)
        self._queued_bytes -= len(inbound.payload)
        topic = inbound.topic
        handlers = self._handlers.get(topic)
        if handlers is None:
            handlers = self._handlers_for(topic)
        echo = await self._check_echo(inbound)
        if not handlers and not echo:
            log.debug(
                "message.dropped",
                session=self._name,
                topic=inbound.topic,
                reason="no subscription matches the topic",
            )
        for handler in handlers:
            await self._dispatch(handler, inbound)

    def _handlers_for(self, topic: str) -> list[MessageHandler]:
        """The handlers whose filter matches ``topic``, remembered per topic (the filters are
        fixed once the session runs; a fleet's topics are a few per vehicle)."""
        if len(self._handlers) >= _HANDLER_CACHE_LIMIT:
            self._handlers.clear()  # made-up topics must not grow the cache for ever
        handlers = [s.handler for s in self._subscriptions if topic_matches(s.topic_filter, topic)]
        self._handlers[topic] = handlers
        return handlers

    async def _check_echo(self, message: InboundMessage) -> bool:
        """Note the echo of an own publication; True when ``message`` is on a checked topic."""
        if not self._access.is_checked(message.topic):
            return False
        change, done = self._access.received(message.topic, message.payload)
        self._report(change)
        if done:
            self._check_done(message.topic)
        return True

    def _check_done(self, topic: str) -> None:
        """An echo check of ``topic`` ended: its subscription goes after this receive burst
        (unless the client subscribes to the topic for itself)."""
        if not any(topic == s.topic_filter for s in self._subscriptions):
            self._echoes_done.append(topic)

    def _in_background(
        self, call: Awaitable[object], on_codes: Callable[[object], None] | None
    ) -> None:
        """Run a SUBSCRIBE (``on_codes`` gets its SUBACK's first code) or UNSUBSCRIBE without
        waiting for it; a lost connection ends it (the next connection subscribes afresh)."""
        task = asyncio.ensure_future(call)
        self._background.add(task)

        def done(finished: asyncio.Future[object]) -> None:
            self._background.discard(task)
            if on_codes is not None:
                _first_code(finished, on_codes)

        task.add_done_callback(done)

    def _echo_subacked(self, topic: str) -> Callable[[object], None]:
        """The SUBACK of an echo check's subscription is reported."""
        return lambda code: self._report(self._access.echo_subscribed(topic, code))

    def _subacked(self, topic_filter: str) -> Callable[[object], None]:
        """The SUBACK of a set_subscribed subscription is reported."""
        return lambda code: self._report(self._access.subscribed([topic_filter], [code]))

    async def _dispatch(self, handler: MessageHandler, message: InboundMessage) -> None:
        try:
            await handler(message)
        except Exception:  # the per-message boundary: one bad message never stops the loop
            log.exception("message.handling_failed", session=self._name, topic=message.topic)


def _tls_context(settings: MqttSettings, endpoint: BrokerEndpoint) -> ssl.SSLContext | None:
    """The SSL context for mqtts:// (ConfigError for unusable files, or tls_* without TLS)."""
    files = settings.tls_files
    if not endpoint.tls:
        if files.given:
            msg = (
                f"tls_ca_file/tls_cert_file/tls_key_file are set but the broker url "
                f"{endpoint.display} is not mqtts://: use mqtts:// for TLS or drop the tls_* keys"
            )
            raise ConfigError(msg)
        return None
    return tls_context(files)


def _subscribe_at_once(
    client: aiomqtt.Client, topic: str, on_code: Callable[[object], None]
) -> None:
    """SUBSCRIBE ``topic`` at QoS 0 through paho, now (paho hands the packet to the socket
    writer before it returns, so it precedes whatever is published next); ``on_code`` gets the
    SUBACK's code. aiomqtt's ``subscribe`` costs a task, a second one in ``wait_for`` and a
    timer per call, and an echo check sends one per vehicle topic: here the SUBACK resolves a
    future registered where aiomqtt's own SUBACK callback looks (``_pending_subscribes``). A
    connection that is going answers nothing; the next one subscribes afresh."""
    result, mid = client._client.subscribe(topic, 0)  # noqa: SLF001 - see vda5050.socket_writer
    if result != mqtt.MQTT_ERR_SUCCESS or mid is None:
        return
    suback: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
    client._pending_subscribes[mid] = suback  # noqa: SLF001 - popped by aiomqtt's _on_subscribe
    suback.add_done_callback(functools.partial(_first_code, on_codes=on_code))


def _first_code(finished: asyncio.Future[Any], on_codes: Callable[[object], None]) -> None:
    """Pass the first code of a finished SUBACK (its reason codes) to ``on_codes``; nothing
    for a call that failed or was cancelled."""
    if finished.cancelled() or finished.exception() is not None:
        return
    codes = finished.result()
    if isinstance(codes, (tuple, list)) and codes:
        on_codes(codes[0])


def _unsubscribe_at_once(client: aiomqtt.Client, topics: list[str]) -> None:
    """UNSUBSCRIBE ``topics`` (one packet) through paho, now, without waiting for the UNSUBACK
    (see :func:`_subscribe_at_once`); the event is what aiomqtt's UNSUBACK callback sets."""
    result, mid = client._client.unsubscribe(topics)  # noqa: SLF001
    if result == mqtt.MQTT_ERR_SUCCESS and mid is not None:
        client._pending_unsubscribes[mid] = asyncio.Event()  # noqa: SLF001
