"""Settling a recovered order with its vehicle's first state after a master restart (issue 10):
still running, ahead of the store, finished, lost, never received, silent."""

from __future__ import annotations

from dataclasses import replace

from tests.unit.master.orders import long_order, stored
from vda5050.models import ActionStatus
from vda_master.dispatcher import OrderStatus, OrderTrack, extend_track
from vda_master.order_records import from_record
from vda_master.recovery import RecoveryOutcome, overdue, reconcile, released_end_in
from vda_master.testing import plan_state


def _recovered(track: OrderTrack) -> OrderTrack:
    """``track`` as it comes back from the store after a restart at monotonic 100."""
    return from_record(stored(track), now=100.0)


def _running() -> OrderTrack:
    """Confirmed and RUNNING, base released to node 3 of 11."""
    track = long_order()
    return replace(track, confirmed_update_id=0, pending=None, status=OrderStatus.RUNNING)


def test_still_running_as_recorded_keeps_tracking() -> None:
    track = _recovered(_running())
    state = plan_state(track.plan, passed=2, released_end=3)

    settled = reconcile(track, state)

    assert settled.outcome is RecoveryOutcome.RUNNING
    assert settled.track.status is OrderStatus.RUNNING
    assert settled.track.recovering_since is None
    assert (settled.track.released_end, settled.track.update_id) == (3, 0)


def test_an_update_published_but_never_recorded_is_adopted() -> None:
    """The store knew update 0 (base to node 3); the vehicle holds update 1 (base to node 5),
    published just before the crash: the counters follow the vehicle, so the next update is 2
    and stitches at node 5."""
    track = _recovered(_running())
    state = plan_state(track.plan, update_id=1, passed=3, released_end=5)

    settled = reconcile(track, state)

    assert settled.outcome is RecoveryOutcome.AHEAD
    assert (settled.track.update_id, settled.track.released_end) == (1, 5)
    assert settled.track.confirmed_update_id == 1
    assert settled.track.pending is None
    following = extend_track(settled.track, 8)
    assert following.update_id == 2
    assert following.message.nodes[0].node_id == "n5"


def test_finished_while_the_master_was_down_becomes_finished() -> None:
    """Whole route released and confirmed, nothing left to traverse, every action FINISHED."""
    done = extend_track(_running(), 11)
    done = replace(done, pending=None, confirmed_update_id=done.update_id)
    track = _recovered(done)
    finished_actions = dict.fromkeys(track.plan.action_ids(), ActionStatus.FINISHED)
    state = plan_state(track.plan, update_id=done.update_id, passed=11, actions=finished_actions)

    settled = reconcile(track, state)

    assert settled.outcome is RecoveryOutcome.ENDED
    assert settled.track.status is OrderStatus.FINISHED


def test_a_vehicle_that_lost_the_order_fails_it_with_the_reason() -> None:
    track = _recovered(_running())
    state = plan_state(track.plan, passed=2, order_id="", node_states=[], edge_states=[])

    settled = reconcile(track, state)

    assert settled.outcome is RecoveryOutcome.LOST
    assert settled.track.status is OrderStatus.FAILED
    assert "no longer holds the order" in settled.track.reason


def test_an_order_the_vehicle_never_confirmed_is_sent_again() -> None:
    track = _recovered(long_order())  # published, never confirmed
    state = plan_state(track.plan, passed=0, order_id="", node_states=[], edge_states=[])

    settled = reconcile(track, state)

    assert settled.outcome is RecoveryOutcome.NOT_RECEIVED
    assert settled.track.status is OrderStatus.SENT
    assert settled.track.pending is not None  # resent once the confirm timeout has passed


def test_a_silent_vehicle_makes_the_order_unknown_until_it_reports() -> None:
    track = _recovered(_running())
    assert overdue(track, now=159.0, timeout_s=60) is None

    unknown = overdue(track, now=160.0, timeout_s=60)

    assert unknown is not None
    assert unknown.status is OrderStatus.UNKNOWN
    assert "has not reported for 60 s since master control restarted" in unknown.reason
    assert overdue(unknown, now=500.0, timeout_s=60) is None  # said once
    settled = reconcile(unknown, plan_state(track.plan, passed=4, released_end=3))
    assert settled.track.status is OrderStatus.RUNNING
    assert settled.track.reason == ""


def test_released_end_shown_by_a_state() -> None:
    track = _running()
    assert released_end_in(track, plan_state(track.plan, passed=1, released_end=6)) == 6
    assert released_end_in(track, plan_state(track.plan, passed=7, released_end=6)) == 7
