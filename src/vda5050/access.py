"""Noticing what the broker refuses without saying so (issue 14, "denied operations are loud").

With MQTT 3.1.1 a broker has two ways to refuse a client, and neither raises anything:

- a refused SUBSCRIBE is answered with the SUBACK return code 0x80 (MQTT 3.1.1 §3.9.3; MQTT 5
  reason codes >= 0x80), and the client then simply receives nothing;
- a refused PUBLISH is dropped (Mosquitto even sends PUBACK for a refused QoS 1 message).

:class:`AccessMonitor` turns both into :class:`AccessProblem` values. Refused subscriptions come
from the SUBACK codes. Refused publications are found by an echo check: the client subscribes to
a topic it writes (the vehicle's own ``connection``, the master's ``order``) and expects every
message it published there to come back with the same bytes within ``check_s``; one that does
not is reported as ``publish_denied`` (the ACL denies writing, or reading it back). A problem
lasts until the broker shows otherwise (a later SUBACK grants the filter, an echo arrives).

Mosquitto's ``acl_file`` grants every SUBSCRIBE and filters at delivery time, so there a missing
read right is silent; only the echo check (and the dynamic-security plugin, or another broker)
makes it visible.

The monitor is plain data and rules: no I/O, no clock reads (``now`` is passed in).
:class:`vda5050.mqtt.MqttSession` feeds it and logs what changed.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Final

#: SUBACK return codes (3.1.1) and reason codes (5) from this value on mean "refused".
_REFUSED_FROM: Final = 0x80


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
    """MQTT topic matching (MQTT 3.1.1 §4.7): ``+`` is one level, a final ``#`` the rest."""
    filter_levels = topic_filter.split("/")
    topic_levels = topic.split("/")
    for index, level in enumerate(filter_levels):
        if level == "#":
            return True
        if index >= len(topic_levels):
            return False
        if level not in ("+", topic_levels[index]):
            return False
    return len(filter_levels) == len(topic_levels)


@dataclass(frozen=True, slots=True)
class EchoWatch:
    """A filter whose publications must come back; ``once``: only the first after a connect."""

    topic_filter: str
    once: bool = False


@dataclass
class AccessMonitor:
    """Refused subscriptions and publications of one MQTT client, per connection.

    Args:
        check_s: Seconds within which a published message must come back.
        max_pending: Messages remembered per topic while waiting for their echo.
        max_problems: Problems kept (and reported); later ones are not recorded.
    """

    check_s: float = 3.0
    max_pending: int = 64
    max_problems: int = 100
    _watches: list[EchoWatch] = field(default_factory=list)
    _problems: dict[tuple[AccessKind, str], AccessProblem] = field(default_factory=dict)
    _pending: dict[str, deque[tuple[float, bytes]]] = field(default_factory=dict)
    _confirmed: set[str] = field(default_factory=set)
    _watch_of: dict[str, EchoWatch | None] = field(default_factory=dict)

    # -- set-up -----------------------------------------------------------------------------

    def watch(self, topic_filter: str, *, once: bool = False) -> None:
        """Check that this client's publications on ``topic_filter`` come back."""
        self._watches.append(EchoWatch(topic_filter, once))
        self._watch_of.clear()

    @property
    def filters(self) -> tuple[str, ...]:
        """The echo filters to subscribe to after every connect."""
        return tuple(w.topic_filter for w in self._watches)

    @property
    def problems(self) -> tuple[AccessProblem, ...]:
        """What the broker refuses now, oldest first."""
        return tuple(self._problems.values())

    # -- observations -----------------------------------------------------------------------

    def connected(self) -> None:
        """A new connection: earlier sends no longer count, ``once`` watches start over."""
        self._pending.clear()
        self._confirmed.clear()

    def subscribed(self, filters: Sequence[str], codes: Sequence[object]) -> AccessChange:
        """The SUBACK of one SUBSCRIBE of ``filters`` answered ``codes`` (in the same order)."""
        change = AccessChange()
        for topic_filter, code in zip(filters, codes, strict=False):
            problem = AccessProblem(AccessKind.SUBSCRIBE_DENIED, topic_filter)
            change += self._raise(problem) if is_refused(code) else self._clear(problem)
        return change

    def watching(self, topic: str) -> EchoWatch | None:
        """The watch whose filter matches ``topic``, if any."""
        if topic not in self._watch_of:
            if len(self._watch_of) > 100_000:  # noqa: PLR2004 - a bound, not a rule
                self._watch_of.clear()
            self._watch_of[topic] = next(
                (w for w in self._watches if topic_matches(w.topic_filter, topic)), None
            )
        return self._watch_of[topic]

    def published(self, topic: str, payload: bytes, now: float) -> bool:
        """This client handed ``payload`` for ``topic`` to the broker at ``now``; True when its
        echo is now awaited."""
        watch = self.watching(topic)
        if watch is None or watch.topic_filter in self._confirmed:
            return False
        if (AccessKind.SUBSCRIBE_DENIED, watch.topic_filter) in self._problems:
            return False  # the echo cannot come back; the refused subscription is the problem
        pending = self._pending.get(topic)
        if pending is None:
            pending = self._pending[topic] = deque(maxlen=self.max_pending)
        pending.append((now, payload))
        return True

    def next_deadline(self) -> float | None:
        """When the oldest awaited echo is due, or None when none is awaited."""
        if not self._pending:
            return None
        return min(sent[0][0] for sent in self._pending.values()) + self.check_s

    def received(self, topic: str, payload: bytes) -> tuple[AccessChange, EchoWatch | None]:
        """A message arrived on a watched topic; when it is the echo of one of this client's
        publications, that topic is writable. Returns the change and the ``once`` watch that
        is now confirmed (its filter can be unsubscribed)."""
        watch = self.watching(topic)
        pending = self._pending.get(topic)
        if watch is None or not pending or all(sent != payload for _, sent in pending):
            return AccessChange(), None
        while pending.popleft()[1] != payload:
            pass
        if not pending:
            del self._pending[topic]
        change = self._clear(AccessProblem(AccessKind.PUBLISH_DENIED, topic))
        if not watch.once or watch.topic_filter in self._confirmed:
            return change, None
        self._confirmed.add(watch.topic_filter)
        for other in [t for t in self._pending if self.watching(t) is watch]:
            del self._pending[other]
        return change, watch

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
