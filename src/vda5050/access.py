"""Noticing what the broker refuses without saying so (issue 14, "denied operations are loud").

With MQTT 3.1.1 a broker has two ways to refuse a client, and neither raises anything:

- a refused SUBSCRIBE is answered with the SUBACK return code 0x80 (MQTT 3.1.1 §3.9.3; MQTT 5
  reason codes >= 0x80), and the client then simply receives nothing;
- a refused PUBLISH is dropped (Mosquitto even sends PUBACK for a refused QoS 1 message).

:class:`AccessMonitor` turns both into :class:`AccessProblem` values. Refused subscriptions come
from the SUBACK codes. Refused publications are found by an echo check: before the first message
on a watched topic after each connect (the vehicle's own ``connection`` and ``state``, the
master's ``order`` and ``instantActions`` per vehicle) the client subscribes to exactly that
topic and expects the message back with the same bytes within ``check_s``; then it unsubscribes.
One that does not come back is reported as ``publish_denied`` (the ACL denies writing the topic,
or reading it back). A problem lasts until the broker shows otherwise (a later SUBACK grants the
filter, an echo arrives).

A filter watched ``after_evidence`` (the master's ``order`` topics) is checked more cheaply: its
first message on a topic goes out unchecked, and the reader's reaction is the proof
(:meth:`AccessMonitor.delivered`: a vehicle's state confirming the order). Only when the next
message on that topic goes out without that proof (a resend) is it echo-checked. A burst of
orders to a thousand vehicles then costs no SUBSCRIBE, SUBACK, echo and UNSUBSCRIBE per vehicle
(docs/performance.md, lever 52); a denied topic is reported one confirmation timeout later.

Mosquitto's ``acl_file`` grants every SUBSCRIBE and filters at delivery time, so there a missing
read right is silent; only the echo check (and the dynamic-security plugin, or another broker)
makes it visible.

The monitor is plain data and rules: no I/O, no clock reads (``now`` is passed in).
:class:`vda5050.mqtt.MqttSession` feeds it and logs what changed.
"""

from __future__ import annotations

import functools
import re
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Final

#: SUBACK return codes (3.1.1) and reason codes (5) from this value on mean "refused".
_REFUSED_FROM: Final = 0x80
#: How a topic is watched (AccessMonitor._watched): from its first publication, or after evidence.
_WATCHED: Final = 1
_AFTER_EVIDENCE: Final = 2


class AccessKind(StrEnum):
    """What the broker refused; the value is the log event's suffix (``mqtt.<kind>``)."""

    SUBSCRIBE_DENIED = "subscribe_denied"
    PUBLISH_DENIED = "publish_denied"

    @property
    def event(self) -> str:
        """The ERROR log event: ``mqtt.subscribe_denied`` or ``mqtt.publish_denied``."""
        return f"mqtt.{self.value}"


@dataclass(frozen=True, slots=True)
class AccessProblem:
    """One refused operation: a subscription filter or a topic this client publishes on."""

    kind: AccessKind
    topic: str

    @property
    def description(self) -> str:
        """What happened and the likely cause, for logs, the vehicle's state and /health."""
        if self.kind is AccessKind.SUBSCRIBE_DENIED:
            return (
                f"the broker refused the subscription to {self.topic} (SUBACK 0x80): its ACL "
                "probably does not let this client read it"
            )
        return (
            f"messages this client published on {self.topic} did not come back from the broker: "
            "its ACL probably does not let this client write (or read back) this topic"
        )


@dataclass(frozen=True, slots=True)
class AccessChange:
    """Problems that appeared and problems that ended with one observation."""

    raised: tuple[AccessProblem, ...] = ()
    cleared: tuple[AccessProblem, ...] = ()

    def __bool__(self) -> bool:
        return bool(self.raised or self.cleared)

    def __add__(self, other: AccessChange) -> AccessChange:
        return AccessChange(self.raised + other.raised, self.cleared + other.cleared)


def is_refused(code: object) -> bool:
    """True for a SUBACK code that refuses the subscription (an int, or a paho ReasonCode)."""
    value = getattr(code, "value", code)
    return isinstance(value, int) and value >= _REFUSED_FROM


def topic_matches(topic_filter: str, topic: str) -> bool:
    """MQTT topic matching (MQTT 3.1.1 §4.7): ``+`` is one level, a final ``#`` the rest
    (none included: ``a/#`` matches ``a``)."""
    if "+" not in topic_filter and "#" not in topic_filter:
        # a vehicle's own filters name one topic each: thousands of them in a fleet process,
        # more than the compiled patterns' cache holds
        return topic_filter == topic
    return filter_pattern(topic_filter).fullmatch(topic) is not None


@functools.lru_cache(maxsize=1024)
def filter_pattern(topic_filter: str) -> re.Pattern[str]:
    """``topic_filter`` (one with wildcards) as a regular expression that matches the whole of a
    matching topic: compiled once per filter, a match costs a fraction of comparing level by
    level (a master meets thousands of new topics, three per vehicle, as a fleet connects)."""
    parts: list[str] = []
    for level in topic_filter.split("/"):
        if level == "#":  # the rest, if any
            return re.compile("/".join(parts) + "(?:/.*)?" if parts else ".*", re.DOTALL)
        parts.append("[^/]*" if level == "+" else re.escape(level))
    return re.compile("/".join(parts), re.DOTALL)


@dataclass
class AccessMonitor:
    """Refused subscriptions and publications of one MQTT client, per connection.

    A topic matching a watched filter is checked on its first publication after each connect:
    the client subscribes to exactly that topic just before (:meth:`wants_subscription`,
    :meth:`echo_subscribed`), and unsubscribes once the message came back (:meth:`received`).
    A topic whose message did not come back stays subscribed and checked, so the problem ends
    with the first message that does. Nothing else is subscribed: a flood on a watched topic
    reaches the client only while a check of it is open.

    Args:
        check_s: Seconds within which a published message must come back.
        max_pending: Messages remembered per topic while waiting for their echo.
        max_problems: Problems kept (and reported); later ones are not recorded.
    """

    check_s: float = 3.0
    max_pending: int = 64
    max_problems: int = 100
    _filters: list[str] = field(default_factory=list)
    _problems: dict[tuple[AccessKind, str], AccessProblem] = field(default_factory=dict)
    _pending: dict[str, deque[tuple[float, bytes]]] = field(default_factory=dict)
    _subscribed: set[str] = field(default_factory=set)
    _confirmed: set[str] = field(default_factory=set)
    #: Per topic: 0 not watched, _WATCHED, or _AFTER_EVIDENCE.
    _watched: dict[str, int] = field(default_factory=dict)
    _after_evidence: list[str] = field(default_factory=list)
    #: Topics of after-evidence filters published on once since the connect, not yet proven.
    _unproven: set[str] = field(default_factory=set)

    # -- set-up -----------------------------------------------------------------------------

    def watch(self, topic_filter: str, *, after_evidence: bool = False) -> None:
        """Check that this client's publications on topics matching ``topic_filter`` come
        back (the first one per topic after each connect; with ``after_evidence``, the second
        one, unless :meth:`delivered` proved the first)."""
        self._filters.append(topic_filter)
        if after_evidence:
            self._after_evidence.append(topic_filter)
        self._watched.clear()

    def exact_topics(self) -> list[str]:
        """The watched filters that are plain topics (no wildcard): their check subscription
        can be made with the connect's SUBSCRIBE (:meth:`echo_subscribing` before it)."""
        return [f for f in self._filters if "+" not in f and "#" not in f]

    @property
    def problems(self) -> tuple[AccessProblem, ...]:
        """What the broker refuses now, oldest first."""
        return tuple(self._problems.values())

    # -- observations -----------------------------------------------------------------------

    def connected(self) -> None:
        """A new connection: no echo subscriptions, earlier sends no longer count, every topic
        is checked again."""
        self._pending.clear()
        self._subscribed.clear()
        self._confirmed.clear()
        self._unproven.clear()

    def subscribed(self, filters: Sequence[str], codes: Sequence[object]) -> AccessChange:
        """The SUBACK of one SUBSCRIBE of ``filters`` answered ``codes`` (in the same order)."""
        change = AccessChange()
        for topic_filter, code in zip(filters, codes, strict=False):
            problem = AccessProblem(AccessKind.SUBSCRIBE_DENIED, topic_filter)
            change += self._raise(problem) if is_refused(code) else self._clear(problem)
        return change

    def watching(self, topic: str) -> bool:
        """True when ``topic`` matches a watched filter."""
        return self._watch_kind(topic) != 0

    def _watch_kind(self, topic: str) -> int:
        kind = self._watched.get(topic)
        if kind is None:
            if len(self._watched) > 100_000:  # noqa: PLR2004 - a bound, not a rule
                self._watched.clear()
            kind = 0
            if any(topic_matches(f, topic) for f in self._filters):
                later = any(topic_matches(f, topic) for f in self._after_evidence)
                kind = _AFTER_EVIDENCE if later else _WATCHED
            self._watched[topic] = kind
        return kind

    def wants_subscription(self, topic: str) -> bool:
        """True when a publication on ``topic`` is about to be checked and the client must
        subscribe to it first (the first publication on an after-evidence topic is noted as
        unproven instead)."""
        if not self._filters or topic in self._subscribed or topic in self._confirmed:
            return False
        kind = self._watch_kind(topic)
        if kind == _AFTER_EVIDENCE and topic not in self._unproven:
            self._unproven.add(topic)
            return False
        return kind != 0

    def delivered(self, topic: str) -> tuple[AccessChange, bool]:
        """The reader's reaction proves that a message this client published on ``topic`` got
        through the broker (a vehicle's state confirming an order): the topic needs no echo
        check on this connection, and a ``publish_denied`` for it ends. Returns the change and
        whether an open check's subscription can go."""
        self._unproven.discard(topic)
        self._confirmed.add(topic)
        self._pending.pop(topic, None)
        open_check = topic in self._subscribed
        self._subscribed.discard(topic)
        return self._clear(AccessProblem(AccessKind.PUBLISH_DENIED, topic)), open_check

    def echo_subscribing(self, topic: str) -> None:
        """The client sent the SUBSCRIBE to ``topic`` for the check and publishes before the
        SUBACK is back: the broker handles one connection's packets in order, so the echo of
        that publication is already covered by the subscription."""
        self._subscribed.add(topic)

    def echo_subscribed(self, topic: str, code: object) -> AccessChange:
        """The client subscribed to ``topic`` for the check; the SUBACK said ``code``. When it
        refused, no echo can come: the refused subscription is the problem, not the writes.
        A SUBACK handled after the echo itself (the echo is read as soon as it arrives, the
        SUBACK's callback runs a loop turn later) finds the check done: the topic stays
        unchecked, as the client has already unsubscribed it (else every later publication
        would wait for an echo that cannot come, and be reported as denied)."""
        if topic not in self._confirmed:
            self._subscribed.add(topic)
        if is_refused(code):
            self._pending.pop(topic, None)
        return self.subscribed([topic], [code])

    def is_checked(self, topic: str) -> bool:
        """True when messages on ``topic`` arrive because of a check (O(1), per message)."""
        return topic in self._subscribed

    def published(self, topic: str, payload: bytes, now: float) -> bool:
        """This client handed ``payload`` for ``topic`` to the broker at ``now``; True when its
        echo is now awaited."""
        if topic not in self._subscribed:
            return False
        if (AccessKind.SUBSCRIBE_DENIED, topic) in self._problems:
            return False  # the echo cannot come back; the refused subscription is the problem
        pending = self._pending.get(topic)
        if pending is None:
            pending = self._pending[topic] = deque(maxlen=self.max_pending)
        pending.append((now, payload))
        return True

    def received(self, topic: str, payload: bytes) -> tuple[AccessChange, bool]:
        """A message arrived on a checked topic; when it is the echo of one of this client's
        publications, the topic is writable. Returns the change and whether the topic's check
        is done (the client can unsubscribe it)."""
        pending = self._pending.get(topic)
        if not pending or all(sent != payload for _, sent in pending):
            return AccessChange(), False
        del self._pending[topic]
        self._subscribed.discard(topic)
        self._confirmed.add(topic)
        return self._clear(AccessProblem(AccessKind.PUBLISH_DENIED, topic)), True

    def next_deadline(self) -> float | None:
        """When the oldest awaited echo is due, or None when none is awaited."""
        if not self._pending:
            return None
        return min(sent[0][0] for sent in self._pending.values()) + self.check_s

    def expire(self, now: float) -> AccessChange:
        """Topics whose oldest unanswered publication is older than ``check_s``."""
        late = [t for t, sent in self._pending.items() if now - sent[0][0] >= self.check_s]
        change = AccessChange()
        for topic in late:
            del self._pending[topic]
            change += self._raise(AccessProblem(AccessKind.PUBLISH_DENIED, topic))
        return change

    # -- the problem set --------------------------------------------------------------------

    def _raise(self, problem: AccessProblem) -> AccessChange:
        key = (problem.kind, problem.topic)
        if key in self._problems or len(self._problems) >= self.max_problems:
            return AccessChange()
        self._problems[key] = problem
        return AccessChange(raised=(problem,))

    def _clear(self, problem: AccessProblem) -> AccessChange:
        if self._problems.pop((problem.kind, problem.topic), None) is None:
            return AccessChange()
        return AccessChange(cleared=(problem,))
