"""Order tracks to store records and back (issue 10): what a restart needs survives the trip
through JSON, and a track change becomes the right history entries."""

from __future__ import annotations

from dataclasses import replace

from tests.unit.master.orders import T0, long_order, stored
from vda_master.dispatcher import OrderStatus, extend_track
from vda_master.order_records import from_record, last_passed, track_events
from vda_master.store import OrderEvent, OrderEventKind


def test_a_published_order_comes_back_with_its_plan_and_counters() -> None:
    track = long_order()
    assert track.sent_update_id == 0  # published once

    back = from_record(stored(track), now=50.0)

    assert back.plan.nodes == track.plan.nodes
    assert back.plan.edges == track.plan.edges
    assert back.plan.route == track.plan.route
    assert back.message == track.message  # cut from the plan again: the same message
    assert (back.released_end, back.update_id, back.sent_update_id) == (3, 0, 0)
    assert back.status is OrderStatus.SENT
    assert back.recovering_since == 50.0
    # Published but unconfirmed: counted as sent once now, resent after the confirm timeout.
    assert back.pending is not None
    assert (back.pending.sends, back.pending.last_sent) == (1, 50.0)


def test_an_update_built_but_never_published_goes_out_as_new() -> None:
    track = long_order()
    track = replace(track, confirmed_update_id=0, pending=None, status=OrderStatus.RUNNING)
    extended = extend_track(track, 5)  # built, not yet published
    assert extended.sent_update_id == 0

    back = from_record(stored(extended), now=9.0)

    assert (back.update_id, back.released_end) == (1, 5)
    assert back.message == extended.message  # stitched at the decision point, node 3
    assert back.message.nodes[0].node_id == "n3"
    assert back.pending is not None
    assert back.pending.sends == 0


def test_a_confirmed_order_has_nothing_pending_after_the_trip() -> None:
    track = replace(long_order(), confirmed_update_id=0, pending=None)
    assert from_record(stored(track), now=1.0).pending is None


def test_the_request_and_the_traffic_note_are_kept() -> None:
    track = replace(long_order(), request_json='{"destination": "n11"}', note="traffic: make way")
    record = stored(track)
    assert record.request == {"destination": "n11"}
    back = from_record(record, now=0.0)
    assert (back.note, back.created_utc) == ("traffic: make way", track.created_utc)


def test_creation_is_one_created_event() -> None:
    track = long_order()
    (event,) = track_events(None, track, T0)
    assert event.event == OrderEventKind.CREATED
    assert event.details["destination"] == "n11"
    assert event.details["nodes"] == 12


def test_status_confirmation_and_cancel_become_events() -> None:
    track = long_order()
    running = replace(track, status=OrderStatus.RUNNING, confirmed_update_id=0)
    cancelling = replace(running, cancel_action_id="c1")
    failed = replace(cancelling, status=OrderStatus.FAILED, reason="it broke")

    accepted = track_events(track, running, T0)
    assert [e.event for e in accepted] == ["accepted", "status_changed"]
    assert accepted[1].details == {"status": "RUNNING", "previous": "SENT"}
    assert [e.event for e in track_events(running, cancelling, T0)] == ["cancel_requested"]
    (changed,) = track_events(cancelling, failed, T0)
    assert changed.details["reason"] == "it broke"
    assert track_events(failed, failed, T0) == []


def test_last_passed_node_from_the_history() -> None:
    def passed(sequence_id: int) -> OrderEvent:
        return OrderEvent("o", T0, OrderEventKind.NODE_PASSED, {"sequenceId": sequence_id})

    assert last_passed([]) == -1
    other = OrderEvent("o", T0, OrderEventKind.PUBLISHED, {"sequenceId": 40})
    assert last_passed([passed(0), passed(2), passed(6), other]) == 3
