"""The outbox of an MQTT session: messages waiting to be published.

Outbox policy while a message waits (for the connection, or behind other messages):

============================  ===================================================================
order, instantActions         kept, in order (commands must not be lost); bounded, oldest dropped
state, connection, factsheet  the latest per MQTT topic is kept (each message is a full snapshot)
visualization                 dropped while offline (display only)
============================  ===================================================================

A payload may be given as a callable that is called when the message is really handed to the
client, so headers are stamped at send time: a snapshot that a newer one replaced was never sent
and takes no headerId (R15).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

from vda5050.topics import Topic

Payload = bytes | Callable[[], bytes]


@dataclass(slots=True)
class Outgoing:
    """A message waiting in the outbox."""

    topic: str
    kind: Topic
    payload: Payload

    def body(self) -> bytes:
        return self.payload() if callable(self.payload) else self.payload


class OfflinePolicy(Enum):
    KEEP_ALL = "keep all, in order"
    KEEP_LATEST = "keep the latest per topic"
    DROP = "drop while offline"


OFFLINE_POLICY: dict[Topic, OfflinePolicy] = {
    Topic.ORDER: OfflinePolicy.KEEP_ALL,
    Topic.INSTANT_ACTIONS: OfflinePolicy.KEEP_ALL,
    Topic.STATE: OfflinePolicy.KEEP_LATEST,
    Topic.CONNECTION: OfflinePolicy.KEEP_LATEST,
    Topic.FACTSHEET: OfflinePolicy.KEEP_LATEST,
    Topic.VISUALIZATION: OfflinePolicy.DROP,
    Topic.ZONE_SET: OfflinePolicy.KEEP_ALL,
    Topic.RESPONSES: OfflinePolicy.KEEP_ALL,
}


@dataclass
class Outbox:
    """Messages waiting to be published, under the per-topic policy of :data:`OFFLINE_POLICY`."""

    limit: int = 10_000
    _queue: OrderedDict[object, Outgoing] = field(default_factory=OrderedDict)
    _front: list[Outgoing] = field(default_factory=list)
    _serial: int = 0
    dropped: int = 0

    def put(self, item: Outgoing, *, online: bool, front: bool = False) -> None:
        """Queue ``item``; ``front`` puts it before everything queued earlier (connect hook)."""
        policy = OFFLINE_POLICY[item.kind]
        if policy is OfflinePolicy.DROP and not online:
            self.dropped += 1
            return
        key: object
        if policy is OfflinePolicy.KEEP_LATEST:
            key = ("latest", item.topic)
            self._queue.pop(key, None)
            self._front = [queued for queued in self._front if queued.topic != item.topic]
        else:
            self._serial += 1
            key = ("seq", self._serial)
        if front:
            self._front.append(item)
            return
        self._queue[key] = item
        while len(self._queue) > self.limit:
            self._queue.popitem(last=False)
            self.dropped += 1

    def pop(self) -> Outgoing | None:
        """Take the next message to publish, or None when empty."""
        if self._front:
            return self._front.pop(0)
        if self._queue:
            return self._queue.popitem(last=False)[1]
        return None

    def push_back(self, item: Outgoing) -> None:
        """Return a message whose publish failed to the head of the queue."""
        self._front.insert(0, item)

    def replaced(self, item: Outgoing) -> bool:
        """Whether a newer message that keeps only the latest per topic replaced ``item``:
        one of the same topic waits already (then ``item`` is not to be sent again)."""
        if OFFLINE_POLICY[item.kind] is not OfflinePolicy.KEEP_LATEST:
            return False
        return ("latest", item.topic) in self._queue or any(
            queued.topic == item.topic for queued in self._front
        )

    def __len__(self) -> int:
        return len(self._queue) + len(self._front)
