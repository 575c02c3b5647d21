"""Resuming orders after a master restart (issue 10), pure.

The store gives back every open order (:mod:`vda_master.order_records`); each waits for its
vehicle's first state after the restart, which settles it (:func:`reconcile`):

=================================================  ===========================================
what the vehicle's first state shows               what master control does
=================================================  ===========================================
another order, and ours was never confirmed        ``NOT_RECEIVED``: the message is sent (again)
another order (``""`` after a vehicle restart),    ``LOST``: FAILED with that reason
ours was confirmed                                 (:func:`vda_master.dispatcher.lost_reason`)
ours, with an update the store never recorded      ``AHEAD``: the release counters follow the
(published just before the crash)                  vehicle; tracking and releasing go on
ours, as recorded, still to do                     ``RUNNING``: tracking and releasing go on
ours, done (nothing left to traverse, every        ``ENDED``: FINISHED, or FAILED if an action
action FINISHED) or failed                         failed (the usual status rules)
=================================================  ===========================================

An order whose vehicle stays silent ``recovery_timeout_s`` after the restart becomes UNKNOWN
with the reason (:func:`overdue`); the next state settles it like the first one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum

from vda5050.models import State
from vda_master.dispatcher import OrderStatus, OrderTrack, observe_track
from vda_master.order_builder import build_message
from vda_master.release import progress_index


class RecoveryOutcome(StrEnum):
    """How the vehicle's first state after a restart settled a recovered order."""

    NOT_RECEIVED = "not_received"
    LOST = "lost"
    AHEAD = "ahead"
    RUNNING = "running"
    ENDED = "ended"


@dataclass(frozen=True, slots=True)
class Reconciled:
    """The settled track (the state already folded in) and how it was settled."""

    track: OrderTrack
    outcome: RecoveryOutcome


def reconcile(track: OrderTrack, state: State) -> Reconciled:
    """``track``, loaded from the store, after its vehicle's first state since the restart."""
    settled = replace(track, recovering_since=None)
    if track.status is OrderStatus.UNKNOWN:
        before = OrderStatus.SENT if track.confirmed_update_id is None else OrderStatus.ACCEPTED
        settled = replace(settled, status=before, reason="")
    if state.order_id != track.order_id:
        outcome = (
            RecoveryOutcome.NOT_RECEIVED
            if track.confirmed_update_id is None
            else RecoveryOutcome.LOST
        )
        return Reconciled(observe_track(settled, state), outcome)
    outcome = RecoveryOutcome.RUNNING
    if state.order_update_id > track.update_id:
        settled = _follow(settled, state)
        outcome = RecoveryOutcome.AHEAD
    observed = observe_track(settled, state)
    return Reconciled(observed, RecoveryOutcome.ENDED if observed.terminal else outcome)


def _follow(track: OrderTrack, state: State) -> OrderTrack:
    """The track adopting the newer update the vehicle holds (its base reaches as far as the
    state's released nodes show)."""
    end = max(track.released_end, released_end_in(track, state))
    message = build_message(
        track.plan,
        first=track.released_end,
        release_end=end,
        update_id=state.order_update_id,
        max_nodes=track.max_nodes,
    )
    return replace(
        track,
        update_id=state.order_update_id,
        sent_update_id=state.order_update_id,
        released_end=end,
        message=message,
        pending=None,
    )


def released_end_in(track: OrderTrack, state: State) -> int:
    """The furthest released node index the vehicle's state shows (the last traversed node
    counts: everything up to it was released)."""
    furthest = progress_index(track.plan, state) or 0
    for node in state.node_states:
        if node.released and node.sequence_id % 2 == 0:
            furthest = max(furthest, node.sequence_id // 2)
    return min(furthest, track.plan.last_index)


def overdue(track: OrderTrack, now: float, timeout_s: float) -> OrderTrack | None:
    """The track as UNKNOWN once its vehicle stayed silent ``timeout_s`` after the restart;
    None while there is time left, or when it is already settled or UNKNOWN."""
    since = track.recovering_since
    if since is None or track.status is OrderStatus.UNKNOWN or track.terminal:
        return None
    if now - since < timeout_s:
        return None
    reason = (
        f"the vehicle has not reported for {timeout_s:g} s since master control restarted: "
        "its progress is unknown"
    )
    return replace(track, status=OrderStatus.UNKNOWN, reason=reason)
