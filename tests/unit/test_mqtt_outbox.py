"""The MQTT session's outbox policy and broker URL parsing (pure parts of vda5050.mqtt)."""

from __future__ import annotations

import pytest

from vda5050.errors import ConfigError
from vda5050.mqtt import BrokerEndpoint, Outbox, Outgoing
from vda5050.topics import Topic


def drain(outbox: Outbox) -> list[bytes]:
    bodies = []
    while (item := outbox.pop()) is not None:
        bodies.append(item.body())
    return bodies


def test_commands_are_kept_in_order_while_offline() -> None:
    """Orders and instant actions queued while offline are all sent, in order."""
    outbox = Outbox()
    for index in range(3):
        outbox.put(Outgoing("t/order", Topic.ORDER, b"o%d" % index), online=False)
        outbox.put(
            Outgoing("t/instantActions", Topic.INSTANT_ACTIONS, b"i%d" % index), online=False
        )
    assert drain(outbox) == [b"o0", b"i0", b"o1", b"i1", b"o2", b"i2"]


def test_snapshots_keep_only_the_latest_per_topic() -> None:
    """State, connection and factsheet keep only their newest message per topic."""
    outbox = Outbox()
    outbox.put(Outgoing("a/state", Topic.STATE, b"s1"), online=False)
    outbox.put(Outgoing("b/state", Topic.STATE, b"b1"), online=False)
    outbox.put(Outgoing("a/connection", Topic.CONNECTION, b"c1"), online=False)
    outbox.put(Outgoing("a/state", Topic.STATE, b"s2"), online=False)
    assert drain(outbox) == [b"b1", b"c1", b"s2"]


def test_visualization_is_dropped_while_offline_but_sent_online() -> None:
    """Visualization is display-only: dropped offline, queued when online."""
    outbox = Outbox()
    outbox.put(Outgoing("a/visualization", Topic.VISUALIZATION, b"v1"), online=False)
    assert len(outbox) == 0
    assert outbox.dropped == 1
    outbox.put(Outgoing("a/visualization", Topic.VISUALIZATION, b"v2"), online=True)
    assert drain(outbox) == [b"v2"]


def test_connect_hook_messages_go_first() -> None:
    """Messages published by the on-connect hook (ONLINE) precede older queued ones."""
    outbox = Outbox()
    outbox.put(Outgoing("a/order", Topic.ORDER, b"old"), online=False)
    outbox.put(Outgoing("a/state", Topic.STATE, b"stale"), online=False)
    outbox.put(Outgoing("a/connection", Topic.CONNECTION, b"ONLINE"), online=True, front=True)
    outbox.put(Outgoing("a/state", Topic.STATE, b"fresh"), online=True, front=True)
    assert drain(outbox) == [b"ONLINE", b"fresh", b"old"]


def test_outbox_is_bounded_and_drops_the_oldest() -> None:
    """Beyond its limit the outbox drops its oldest message and counts it."""
    outbox = Outbox(limit=2)
    for index in range(4):
        outbox.put(Outgoing("a/order", Topic.ORDER, b"%d" % index), online=False)
    assert drain(outbox) == [b"2", b"3"]
    assert outbox.dropped == 2


def test_callable_payload_is_built_only_when_taken() -> None:
    """A replaced snapshot's payload builder never runs, so it takes no headerId (R15)."""
    built: list[str] = []

    def builder(name: str) -> bytes:
        built.append(name)
        return name.encode()

    outbox = Outbox()
    outbox.put(Outgoing("a/state", Topic.STATE, lambda: builder("first")), online=False)
    outbox.put(Outgoing("a/state", Topic.STATE, lambda: builder("second")), online=False)
    assert drain(outbox) == [b"second"]
    assert built == ["second"]


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("mqtt://127.0.0.1:1883", BrokerEndpoint("127.0.0.1", 1883)),
        ("mqtt://broker", BrokerEndpoint("broker", 1883)),
        ("mqtts://u:p%40ss@host:8884", BrokerEndpoint("host", 8884, "u", "p@ss", tls=True)),
        ("mqtts://host", BrokerEndpoint("host", 8883, tls=True)),
    ],
)
def test_broker_url_parsing(url: str, expected: BrokerEndpoint) -> None:
    """mqtt://[user:password@]host:port and mqtts:// URLs parse into their parts."""
    assert BrokerEndpoint.from_url(url) == expected


@pytest.mark.parametrize(
    ("url", "fragment"),
    [("http://x:1", "scheme"), ("mqtt://:1883", "no host"), ("mqtt://h:99999", "invalid port")],
)
def test_bad_broker_urls_are_refused(url: str, fragment: str) -> None:
    """A broker URL that cannot be used fails with what is wrong."""
    with pytest.raises(ConfigError, match=fragment):
        BrokerEndpoint.from_url(url)


def test_display_hides_the_password() -> None:
    """Logs show the broker without its password."""
    assert BrokerEndpoint.from_url("mqtt://user:secret@h:1").display == "mqtt://user@h:1"
