"""AccessMonitor: refused subscriptions and publications that never come back (issue 14)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vda5050.access import AccessChange, AccessKind, AccessMonitor, AccessProblem, topic_matches

CONNECTION = "uagv/v2/acme/r1/connection"
STATE = "uagv/v2/acme/r1/state"


def denied(topic: str) -> AccessProblem:
    return AccessProblem(AccessKind.PUBLISH_DENIED, topic)


def monitor(*topics: str) -> AccessMonitor:
    """A monitor watching the vehicle's connection and state, connected, with echo
    subscriptions granted for ``topics``."""
    watched = AccessMonitor(check_s=3.0)
    watched.watch(CONNECTION)
    watched.watch(STATE)
    watched.connected()
    for topic in topics:
        assert watched.wants_subscription(topic)
        assert not watched.echo_subscribed(topic, 0)
    return watched


@pytest.mark.parametrize(
    ("topic_filter", "topic", "expected"),
    [
        ("uagv/v2/+/+/order", "uagv/v2/acme/r1/order", True),
        ("uagv/v2/+/+/order", "uagv/v2/acme/r1/state", False),
        ("uagv/#", "uagv/v2/acme/r1/state", True),
        ("uagv/v2/+", "uagv/v2/acme/r1", False),
        ("uagv/v2/acme/r1/state", "uagv/v2/acme/r1/state", True),
        ("uagv/v2/acme/r1/state/x", "uagv/v2/acme/r1/state", False),
    ],
)
def test_topic_matching_follows_mqtt(topic_filter: str, topic: str, *, expected: bool) -> None:
    """``+`` matches exactly one level, a final ``#`` the rest, anything else literally."""
    assert topic_matches(topic_filter, topic) is expected


def test_suback_codes_raise_and_clear_subscribe_problems() -> None:
    """0x80 (an int, or a paho ReasonCode-like object) refuses a filter; a later grant clears
    the problem; a granted QoS never raises one."""

    class ReasonCode:
        value = 0x80

    watched = AccessMonitor()
    change = watched.subscribed(["a/order", "a/instantActions"], [ReasonCode(), 0])
    problem = AccessProblem(AccessKind.SUBSCRIBE_DENIED, "a/order")
    assert change == AccessChange(raised=(problem,))
    assert watched.problems == (problem,)
    assert not watched.subscribed(["a/order"], [128])  # still refused: nothing new
    assert watched.subscribed(["a/order"], [1]) == AccessChange(cleared=(problem,))
    assert not watched.problems


def test_a_watched_topic_is_subscribed_before_its_first_publication_only() -> None:
    """The first publication per topic after a connect needs the echo subscription; once the
    message came back the topic is done (unsubscribe) until the next connect."""
    watched = monitor()
    assert not watched.wants_subscription("uagv/v2/acme/r1/visualization")
    assert watched.wants_subscription(STATE)
    watched.echo_subscribed(STATE, 0)
    assert not watched.wants_subscription(STATE)
    assert watched.published(STATE, b"s1", now=0.0)
    assert watched.is_checked(STATE)
    assert watched.received(STATE, b"s1") == (AccessChange(), True)
    assert not watched.is_checked(STATE)
    assert not watched.wants_subscription(STATE)
    assert not watched.published(STATE, b"s2", now=1.0)
    watched.connected()
    assert watched.wants_subscription(STATE)


def test_a_publication_that_comes_back_in_time_raises_nothing() -> None:
    """The echo with the same bytes confirms the topic; expiry later finds nothing late."""
    watched = monitor(CONNECTION)
    watched.published(CONNECTION, b"ONLINE", now=10.0)
    assert watched.received(CONNECTION, b"ONLINE") == (AccessChange(), True)
    assert not watched.expire(now=20.0)
    assert watched.problems == ()


def test_a_publication_that_never_comes_back_is_denied_once_until_an_echo() -> None:
    """After check_s without its echo the topic is publish_denied, reported once, and stays
    checked; an older retained copy (other bytes) does not clear it, the echo of a later
    publication does."""
    watched = monitor(CONNECTION)
    watched.published(CONNECTION, b"ONLINE-1", now=10.0)
    assert not watched.expire(now=12.9)
    assert watched.expire(now=13.0) == AccessChange(raised=(denied(CONNECTION),))
    assert not watched.wants_subscription(CONNECTION)  # still subscribed
    assert watched.published(CONNECTION, b"ONLINE-2", now=14.0)
    assert not watched.expire(now=17.5)  # already reported
    assert watched.received(CONNECTION, b"CONNECTIONBROKEN") == (AccessChange(), False)
    watched.published(CONNECTION, b"ONLINE-3", now=18.0)
    change, done = watched.received(CONNECTION, b"ONLINE-3")
    assert change == AccessChange(cleared=(denied(CONNECTION),))
    assert done
    assert not watched.problems


def test_an_echo_confirms_earlier_publications_on_its_topic() -> None:
    """Messages on one topic arrive in order: the echo of the second confirms the first."""
    watched = monitor(CONNECTION)
    watched.published(CONNECTION, b"a", now=0.0)
    watched.published(CONNECTION, b"b", now=1.0)
    watched.received(CONNECTION, b"b")
    assert not watched.expire(now=100.0)


ORDER_FILTER = "uagv/v2/+/+/order"
ORDER = "uagv/v2/acme/r1/order"


def after_evidence() -> AccessMonitor:
    """A monitor watching the master's order topics after evidence, connected."""
    watched = AccessMonitor(check_s=3.0)
    watched.watch(ORDER_FILTER, after_evidence=True)
    watched.connected()
    return watched


def test_an_order_confirmed_by_the_vehicle_is_never_echo_checked() -> None:
    """After evidence (lever 52): the first order to a vehicle goes out unchecked; once the
    vehicle's state proves it arrived, no later order on the topic is checked either, until
    the next connect."""
    watched = after_evidence()
    assert watched.watching(ORDER)
    assert not watched.wants_subscription(ORDER)
    assert not watched.published(ORDER, b"order-1", now=0.0)
    assert watched.delivered(ORDER) == (AccessChange(), False)
    assert not watched.wants_subscription(ORDER)
    assert not watched.published(ORDER, b"order-2", now=1.0)
    assert not watched.expire(now=100.0)
    watched.connected()
    assert not watched.wants_subscription(ORDER)  # a first order again: unchecked
    assert watched.wants_subscription(ORDER)  # no proof by the second: checked


def test_an_unconfirmed_order_is_checked_at_its_resend_and_reported_if_denied() -> None:
    """Without the vehicle's proof the second message on the topic (the resend) is
    echo-checked; no echo within check_s is publish_denied; a later confirmation by the
    vehicle ends the problem and the check (its subscription can go)."""
    watched = after_evidence()
    assert not watched.wants_subscription(ORDER)
    watched.published(ORDER, b"order-1", now=0.0)
    assert watched.wants_subscription(ORDER)
    watched.echo_subscribing(ORDER)
    assert watched.published(ORDER, b"order-1 again", now=2.0)
    assert watched.expire(now=5.0) == AccessChange(raised=(denied(ORDER),))
    change, open_check = watched.delivered(ORDER)
    assert change == AccessChange(cleared=(denied(ORDER),))
    assert open_check
    assert not watched.is_checked(ORDER)
    assert not watched.problems


def test_topics_watched_from_the_first_publication_are_unchanged_by_after_evidence() -> None:
    """Only the after-evidence filter waits: a vehicle's connection is checked at once."""
    watched = after_evidence()
    watched.watch(CONNECTION)
    assert watched.wants_subscription(CONNECTION)
    assert not watched.wants_subscription(ORDER)


def test_next_deadline_is_the_oldest_awaited_echo() -> None:
    """Nothing awaited: no deadline (no timer needed); else the oldest send plus check_s."""
    watched = monitor(CONNECTION)
    assert watched.next_deadline() is None
    assert watched.published(CONNECTION, b"a", now=5.0)
    assert not watched.published("uagv/v2/acme/r1/order", b"o", now=1.0)
    assert watched.next_deadline() == 8.0
    watched.received(CONNECTION, b"a")
    assert watched.next_deadline() is None


def test_a_new_connection_forgets_publications_sent_on_the_old_one() -> None:
    """What was sent before a disconnect may be lost with it; it is not held against the ACL."""
    watched = monitor(CONNECTION)
    watched.published(CONNECTION, b"ONLINE", now=0.0)
    watched.connected()
    assert not watched.expire(now=100.0)


def test_a_refused_echo_subscription_is_not_reported_again_as_a_refused_publication() -> None:
    """When the echo subscription itself is refused, the publication is not checked (the echo
    cannot come back) nor subscribed again; the refused subscription is the one problem."""
    watched = monitor()
    change = watched.echo_subscribed(CONNECTION, 0x80)
    assert [p.kind for p in change.raised] == [AccessKind.SUBSCRIBE_DENIED]
    assert not watched.published(CONNECTION, b"ONLINE", now=0.0)
    assert not watched.wants_subscription(CONNECTION)
    assert not watched.expire(now=100.0)
    assert [p.kind for p in watched.problems] == [AccessKind.SUBSCRIBE_DENIED]


def test_publishing_before_the_suback_is_checked_and_a_late_refusal_is_one_problem() -> None:
    """The session publishes right after sending the SUBSCRIBE: the publication is checked at
    once; a SUBACK that then refuses ends the check without a second, publish_denied problem."""
    watched = monitor()
    watched.echo_subscribing(CONNECTION)
    assert not watched.wants_subscription(CONNECTION)
    assert watched.published(CONNECTION, b"ONLINE", now=0.0)
    granted = monitor()
    granted.echo_subscribing(STATE)
    granted.published(STATE, b"s", now=0.0)
    assert not granted.echo_subscribed(STATE, 0)
    assert granted.received(STATE, b"s") == (AccessChange(), True)
    change = watched.echo_subscribed(CONNECTION, 0x80)
    assert [p.kind for p in change.raised] == [AccessKind.SUBSCRIBE_DENIED]
    assert not watched.expire(now=100.0)
    assert [p.kind for p in watched.problems] == [AccessKind.SUBSCRIBE_DENIED]


def test_a_suback_handled_after_the_echo_leaves_the_topic_confirmed() -> None:
    """The echo can be handled before its SUBACK (the SUBACK's callback runs a loop turn
    later). The check is done and the client unsubscribes: later publications on the topic
    await no echo and are never reported as denied (a fleet run logged publish_denied for 7 of
    20 vehicles' order topics this way)."""
    watched = monitor()
    watched.echo_subscribing(STATE)
    assert watched.published(STATE, b"s1", now=0.0)
    assert watched.received(STATE, b"s1") == (AccessChange(), True)
    assert not watched.echo_subscribed(STATE, 0)  # the late SUBACK
    assert not watched.is_checked(STATE)
    assert not watched.wants_subscription(STATE)
    assert not watched.published(STATE, b"s2", now=1.0)
    assert not watched.expire(now=100.0)
    assert watched.problems == ()


def test_unwatched_topics_and_foreign_messages_are_ignored() -> None:
    """Publications on other topics are not tracked; a message nobody here sent changes
    nothing."""
    watched = monitor(CONNECTION)
    assert not watched.published("uagv/v2/acme/r1/visualization", b"v", now=0.0)
    assert watched.received(CONNECTION, b"from someone else") == (AccessChange(), False)
    assert not watched.expire(now=100.0)


def test_problems_are_bounded() -> None:
    """At most max_problems are kept and reported (a fleet-wide refusal stays readable)."""
    watched = AccessMonitor(check_s=1.0, max_problems=3)
    watched.watch("uagv/v2/+/+/order")
    for index in range(5):
        topic = f"uagv/v2/acme/r{index}/order"
        assert watched.wants_subscription(topic)
        watched.echo_subscribed(topic, 0)
        watched.published(topic, b"o", now=0.0)
    assert len(watched.expire(now=5.0).raised) == 3
    assert len(watched.problems) == 3


def test_descriptions_name_the_topic_and_the_acl() -> None:
    """Both kinds of problem say which topic and that the ACL is the likely cause."""
    for kind in AccessKind:
        text = AccessProblem(kind, STATE).description
        assert STATE in text
        assert "ACL" in text
    assert AccessKind.PUBLISH_DENIED.event == "mqtt.publish_denied"


def _matches_level_by_level(topic_filter: str, topic: str) -> bool:
    """MQTT 3.1.1 §4.7 spelled out: level by level, ``+`` any one level, ``#`` the rest."""
    filter_levels, topic_levels = topic_filter.split("/"), topic.split("/")
    for index, level in enumerate(filter_levels):
        if level == "#":
            return True
        if index >= len(topic_levels) or level not in ("+", topic_levels[index]):
            return False
    return len(filter_levels) == len(topic_levels)


_LEVELS = st.text(alphabet="ab+#/.*\\\n", max_size=8)


@given(topic_filter=_LEVELS, topic=st.text(alphabet="ab/.*\\\n", max_size=8))
def test_compiled_filters_match_as_level_by_level_matching(topic_filter: str, topic: str) -> None:
    """The compiled filter (what the sessions use) agrees with the level-by-level reading,
    regular-expression characters and empty levels included."""
    assert topic_matches(topic_filter, topic) is _matches_level_by_level(topic_filter, topic)
