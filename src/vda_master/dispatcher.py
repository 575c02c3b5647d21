"""The life of one order as master control sees it: status machine, confirmation, resends,
base extension and cancellation (§6.6.2–§6.6.4, §6.10; R56–R58, R66, R84).

Status, driven only by the vehicle's states (never by the wire alone)::

    SENT ──state shows orderId+orderUpdateId──▶ ACCEPTED ──nodeStates──▶ RUNNING ──▶ FINISHED
      │                                                                      │
      ├──error references the order──▶ REJECTED       an action FAILED ──▶ FAILED
      ├──no confirmation after max_sends──▶ FAILED    the vehicle cleared it ──▶ FAILED
      └──DELETE ▶ cancelOrder ──FINISHED──▶ CANCELLED

Order messages travel at QoS 0 and may be lost (§6.2): one not confirmed by a state within
``confirm_timeout_s`` is sent again unchanged (same orderId and orderUpdateId, a new header),
at most ``max_sends`` times in all. Load is not loss: the shell stretches the timeout with the
measured confirmation latency (:mod:`vda_master.confirmation`) and holds resends while its own
inbound lags (:attr:`SendGate.resend_allowed`). A vehicle discards a copy it already holds
(R45). Only one message per order is in flight: the next update stitches onto the confirmed
decision point.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Final

from vda5050.evolve import evolve
from vda5050.models import Action, ActionStatus, InstantActions, Order, State
from vda_master.fleet import CONTROLLABLE_MODES
from vda_master.order_builder import OrderPlan, all_actions, build_message
from vda_master.release import ReleasePolicy, decide_release, progress_index, release_end
from vda_master.stops import Stop


class OrderStatus(StrEnum):
    """Status of an order in master control (architecture §3.4)."""

    SENT = "SENT"
    ACCEPTED = "ACCEPTED"
    RUNNING = "RUNNING"
    FINISHED = "FINISHED"
    FAILED = "FAILED"
    REJECTED = "REJECTED"
    CANCELLED = "CANCELLED"
    #: After a master restart, the vehicle has not reported within the recovery timeout: its
    #: progress is unknown (not terminal; its next state settles it).
    UNKNOWN = "UNKNOWN"
    #: Asked for with ``queue: true`` while no vehicle could take it: it waits for one
    #: (:mod:`vda_master.queue_rules`); no vehicle has been sent anything yet.
    QUEUED = "QUEUED"


TERMINAL = frozenset(
    {OrderStatus.FINISHED, OrderStatus.FAILED, OrderStatus.REJECTED, OrderStatus.CANCELLED}
)
_ENDED = frozenset({ActionStatus.FINISHED, ActionStatus.FAILED})
_BUSY = frozenset({ActionStatus.INITIALIZING, ActionStatus.RUNNING, ActionStatus.PAUSED})


#: How the note of an order master control created itself for traffic control begins.
TRAFFIC_NOTE: Final = "traffic: "
#: While master control's inbound lags, a message is resent only after this many timeouts.
BEHIND_CEILING: Final = 5.0


@dataclass(frozen=True, slots=True)
class DispatchSettings:
    """Resend timing and the release policy; seconds."""

    confirm_timeout_s: float = 2.0
    max_sends: int = 4
    release: ReleasePolicy = field(default_factory=ReleasePolicy)


@dataclass(frozen=True, slots=True)
class Outgoing:
    """A message waiting for a state to confirm it; ``last_sent`` is None until first sent."""

    message: Order | InstantActions
    sends: int = 0
    last_sent: float | None = None


@dataclass(frozen=True, slots=True)
class SendGate:
    """What the shell knows about sending to the vehicle right now (R84, R114)."""

    #: ONLINE and in AUTOMATIC or SEMIAUTOMATIC (Table 1, R84).
    vehicle_ready: bool
    #: minOrderInterval has passed since the last order message to this vehicle.
    order_allowed: bool
    #: False while master control has not read all the broker delivered (its inbound lags):
    #: the confirmation may be among the unread messages, so an overdue message is not taken
    #: for lost yet - unless overdue :data:`BEHIND_CEILING` times over (load is not loss).
    resend_allowed: bool = True
    #: cancelOrder may go (None: as ``vehicle_ready``); True also in 3.0 INTERVENED (T58).
    cancel_ready: bool | None = None


@dataclass(frozen=True, slots=True)
class Resume:
    """After backing off (traffic control), drive on to ``node_id`` and do ``actions`` there:
    the destination and the destination actions of the interrupted route."""

    node_id: str
    actions: tuple[Action, ...]


@dataclass(frozen=True, slots=True)
class OrderTrack:
    """Everything master control tracks about one order."""

    plan: OrderPlan
    status: OrderStatus
    released_end: int
    update_id: int
    max_nodes: int | None
    #: The latest order message built; the one in flight while ``pending`` is set.
    message: Order
    pending: Outgoing | None
    created_at: float
    confirmed_update_id: int | None = None
    #: Wall-clock creation time, UTC ISO 8601 (for people; ``created_at`` is monotonic).
    created_utc: str = ""
    #: Why master control created the order itself (traffic control), empty when asked for.
    note: str = ""
    #: Set while the vehicle backs off: where the order goes on afterwards.
    resume: Resume | None = None
    #: The latest orderUpdateId published (None before the first send).
    sent_update_id: int | None = None
    #: What the API was asked, as JSON text (kept with the order in the store).
    request_json: str = "{}"
    #: Set (monotonic) on an order loaded after a master restart, until the vehicle's first
    #: state reconciles it (:mod:`vda_master.recovery`).
    recovering_since: float | None = None
    cancel: Outgoing | None = None
    cancel_action_id: str | None = None
    reason: str = ""
    #: Set when master control cancels the order itself (not asked to): the order then ends
    #: FAILED with this reason instead of CANCELLED (:mod:`vda_master.graph_change`).
    cancel_reason: str = ""
    #: The stops after the plan's destination, still to come (:mod:`vda_master.stops`): the
    #: next is appended by an update once the vehicle stands at the destination.
    onward: tuple[Stop, ...] = ()

    @property
    def order_id(self) -> str:
        return self.plan.order_id

    @property
    def terminal(self) -> bool:
        return self.status in TERMINAL


def start_track(
    plan: OrderPlan,
    settings: DispatchSettings,
    *,
    max_nodes: int | None,
    now: float,
    created_utc: str = "",
    granted_end: int | None = None,
    note: str = "",
    whole: Order | None = None,
) -> OrderTrack:
    """Track a new order; its first message (orderUpdateId 0, R57) is ready to send. The base
    goes to the release window's end, or to ``granted_end`` when traffic control decided it.
    ``whole``, the first message with everything released (built to check its size), is that
    message when the base reaches the last node the message holds."""
    end = release_end(settings.release, plan.last_index, 0) if granted_end is None else granted_end
    last = plan.last_index
    if max_nodes is not None:
        end = min(end, max_nodes - 1)
        last = min(last, max_nodes - 1)
    if whole is not None and end >= last:
        message = whole
    else:
        message = build_message(plan, first=0, release_end=end, update_id=0, max_nodes=max_nodes)
    return OrderTrack(
        plan=plan,
        status=OrderStatus.SENT,
        released_end=end,
        update_id=0,
        max_nodes=max_nodes,
        message=message,
        pending=Outgoing(message),
        created_at=now,
        created_utc=created_utc,
        note=note,
    )


def reduce_track(track: OrderTrack, state: State, settings: DispatchSettings) -> OrderTrack:
    """Fold one state of the order's vehicle into the track: confirmation, status, and the
    base extension the release window wants (without traffic control)."""
    track = observe_track(track, state)
    wanted = release_wanted(track, state, settings)
    return track if wanted is None else extend_track(track, wanted.desired_end)


def observe_track(track: OrderTrack, state: State) -> OrderTrack:
    """Fold one state of the order's vehicle into the track: confirmation and status."""
    if track.terminal:
        return track
    track = _confirm(track, state)
    status, reason = _status_from_state(track, state)
    if status != track.status or (reason and reason != track.reason):
        # Replaced only on change: this runs for every state on the ingest hot path.
        track = evolve(track, status=status, reason=reason or track.reason)
    if track.terminal:
        return evolve(track, pending=None, cancel=None)
    return track


def _confirm(track: OrderTrack, state: State) -> OrderTrack:
    """Drop pending messages the state confirms (§6.10: every accepted order triggers a state)."""
    if track.cancel is not None and any(
        a.action_id == track.cancel_action_id for a in state.action_states
    ):
        track = evolve(track, cancel=None)
    if state.order_id != track.order_id:
        return track
    confirmed = state.order_update_id
    if track.pending is not None and confirmed >= track.update_id:
        track = evolve(track, pending=None)
    if track.confirmed_update_id == confirmed:
        return track
    return evolve(track, confirmed_update_id=confirmed)


def _status_from_state(track: OrderTrack, state: State) -> tuple[OrderStatus, str]:
    rejection = rejection_reason(track, state)
    if rejection is not None:
        return OrderStatus.REJECTED, rejection
    lost = lost_reason(track, state)
    if lost is not None:
        return OrderStatus.FAILED, lost
    statuses = {a.action_id: a.action_status for a in state.action_states}
    ours = state.order_id == track.order_id
    if track.cancel_action_id is not None:
        cancelled = _status_after_cancel(track, state, statuses)
        if cancelled is not None:
            return cancelled
    elif ours and _finished(track, state, statuses):
        return OrderStatus.FINISHED, ""
    if ours and track.cancel_action_id is None:
        cleared = cleared_reason(track, state)
        if cleared is not None:
            return OrderStatus.FAILED, cleared
    return _status_from_progress(track, state, statuses) if ours else (track.status, "")


def _status_after_cancel(
    track: OrderTrack, state: State, statuses: dict[str, ActionStatus]
) -> tuple[OrderStatus, str] | None:
    """Once cancelOrder ended: CANCELLED, or FINISHED when it came too late (the vehicle had no
    order left to cancel, §6.6.3.2, and had done it all). None while it runs: an order being
    cancelled is never FINISHED by the empty node states the cancel itself produces."""
    cancel = statuses.get(track.cancel_action_id or "")
    if cancel == ActionStatus.FINISHED:
        if track.cancel_reason:
            return OrderStatus.FAILED, track.cancel_reason
        return OrderStatus.CANCELLED, "cancelled on request"
    if cancel != ActionStatus.FAILED:
        return None
    if state.order_id == track.order_id and _finished(track, state, statuses):
        return OrderStatus.FINISHED, "cancelOrder came after the order had finished"
    return OrderStatus.CANCELLED, "cancelOrder ended FAILED: the vehicle held no order to cancel"


def _status_from_progress(
    track: OrderTrack, state: State, statuses: dict[str, ActionStatus]
) -> tuple[OrderStatus, str]:
    """Status of a confirmed order that is neither finished nor cancelled."""
    failed = [i for i in track.plan.action_ids() if statuses.get(i) == ActionStatus.FAILED]
    if failed and track.cancel_action_id is None:
        return OrderStatus.FAILED, action_failure(track, state, failed[0])
    busy = any(statuses.get(i) in _BUSY for i in track.plan.action_ids())
    if state.node_states or busy:
        return OrderStatus.RUNNING, ""
    if track.status == OrderStatus.SENT:
        return OrderStatus.ACCEPTED, ""
    return track.status, ""


def _finished(track: OrderTrack, state: State, statuses: dict[str, ActionStatus]) -> bool:
    """Done: no stop left to append (:mod:`vda_master.stops`) and the route driven to its
    end (:func:`_route_done`)."""
    return not track.onward and _route_done(track, state, statuses)


def at_stop(track: OrderTrack, state: State) -> bool:
    """The vehicle has driven the route to a stop with another still to come, and is done
    there: the next stop may be appended (the order is not being cancelled or ended).

    Waiting for the stop's actions to end keeps the update clear of them: vda-5050-lib 1.4's
    AGV takes the stitching node's actions of an update that arrives while they wait or run
    for new ones (R51), lists them twice and never ends the order; and the next leg's way is
    not held while the vehicle stands at the stop."""
    if not track.onward or track.terminal or track.cancel_action_id is not None:
        return False
    statuses = {a.action_id: a.action_status for a in state.action_states}
    return state.order_id == track.order_id and _route_done(track, state, statuses)


def _route_done(track: OrderTrack, state: State, statuses: dict[str, ActionStatus]) -> bool:
    """Whole route released and confirmed, nothing left to traverse, the route's end
    reached, every action FINISHED. Empty node states alone do not say the vehicle arrived: a
    vehicle that clears its order (:func:`cleared_reason`) empties them where it stands. The
    end is compared by nodeId, so a vehicle that numbers sequenceIds wrongly still finishes
    (tolerated, as for every order it can run)."""
    return (
        track.released_end == track.plan.last_index
        and track.resume is None
        and track.pending is None
        and not state.node_states
        and not state.edge_states
        and state.last_node_id == track.plan.destination
        and all(statuses.get(i) == ActionStatus.FINISHED for i in track.plan.action_ids())
    )


def cleared_reason(track: OrderTrack, state: State) -> str | None:
    """Why the vehicle no longer executes a confirmed order it still names, if it cleared it.

    A vehicle that enters MANUAL (2.x §6.10.6 Table 1), or MANUAL, SERVICE, TEACH_IN or STARTUP
    (3.0 §6.6.7), clears its order: it keeps orderId, orderUpdateId and lastNodeId but empties
    nodeStates and edgeStates where it stands. Such an order can never end by itself, and empty
    node states must not read as FINISHED: it ends FAILED, and the vehicle is free once it is
    back in a mode that takes orders. Recognised by the mode together with the empty states
    short of the released base's end, so that a vehicle that has driven its whole base and
    waits for the next update (empty states on the base's end node) is not mistaken for one.
    """
    if (
        state.operating_mode in CONTROLLABLE_MODES
        or state.node_states
        or state.edge_states
        or track.pending is not None
        or state.order_update_id != track.update_id
    ):
        return None
    base_end = track.plan.nodes[track.released_end]
    if state.last_node_id == base_end.node_id:
        return None
    return (
        f"the vehicle cleared the order in operatingMode {state.operating_mode.value} at node "
        f"{state.last_node_id or '(none)'}, before reaching {track.plan.destination}"
    )


def action_failure(track: OrderTrack, state: State, action_id: str) -> str:
    """Why an order action FAILED, in the vehicle's own words where it gives them: the
    actionState's resultDescription and the errors that reference the action (§6.11, §7.1)."""
    action_type = next(
        (a.action_type for a in all_actions(track.plan) if a.action_id == action_id), "action"
    )
    details = [
        a.result_description
        for a in state.action_states
        if a.action_id == action_id and a.result_description
    ]
    for error in state.errors:
        refs = {r.reference_key: r.reference_value for r in error.error_references or ()}
        if refs.get("actionId") == action_id:
            details.append(
                f"{error.error_type}: {error.error_description}"
                if error.error_description
                else error.error_type
            )
    detail = "; ".join(dict.fromkeys(details))
    reason = f"{action_type} action {action_id!r} failed"
    return f"{reason}: {detail}" if detail else reason


def lost_reason(track: OrderTrack, state: State) -> str | None:
    """Why the vehicle no longer holds an order it once confirmed, if so: it reports another
    orderId (``""`` after a restart, or another master's order). Such an order can never end
    by itself; it ends FAILED and the vehicle is free at once (issue 14)."""
    if track.confirmed_update_id is None or state.order_id == track.order_id:
        return None
    shown = repr(state.order_id) if state.order_id else "none"
    return (
        f"the vehicle no longer holds the order: it reports orderId {shown} (it restarted, or "
        "another controller replaced the order)"
    )


def rejection_reason(track: OrderTrack, state: State) -> str | None:
    """The error that rejects this order's latest message, described, if the state has one."""
    for error in state.errors:
        refs = {r.reference_key: r.reference_value for r in error.error_references or ()}
        if refs.get("orderId") != track.order_id:
            continue
        if refs.get("orderUpdateId", str(track.update_id)) != str(track.update_id):
            continue
        detail = f": {error.error_description}" if error.error_description else ""
        return f"{error.error_type} ({error.error_level}){detail}"
    return None


@dataclass(frozen=True, slots=True)
class ReleaseWanted:
    """The vehicle stands at node ``progress`` of the plan and the release window wants the
    base to reach node ``desired_end`` (beyond the current ``released_end``)."""

    progress: int
    desired_end: int


def release_wanted(
    track: OrderTrack, state: State, settings: DispatchSettings
) -> ReleaseWanted | None:
    """Whether to extend the base now, and how far the window would (§6.6.2; R56–R58).

    Never while an update is in flight or a cancel is under way: one message per order at a time.
    """
    if track.terminal or track.pending is not None or track.cancel_action_id is not None:
        return None
    progress = progress_index(track.plan, state)
    if progress is None:
        return None
    end = decide_release(
        settings.release,
        last_index=track.plan.last_index,
        released_end=track.released_end,
        progress=progress,
        new_base_request=bool(state.new_base_request),
    )
    return None if end is None else ReleaseWanted(progress, end)


def extend_track(track: OrderTrack, end: int) -> OrderTrack:
    """The track with an update that releases the base up to node ``end``, stitched at the
    decision point (R56–R58); unchanged when ``end`` does not go beyond the released end."""
    if end <= track.released_end or track.pending is not None or track.terminal:
        return track
    first = track.released_end  # the decision point: same nodeId and sequenceId (R56)
    end = min(end, track.plan.last_index)
    if track.max_nodes is not None:
        end = min(end, first + track.max_nodes - 1)
    update_id = track.update_id + 1  # R57
    message = build_message(
        track.plan, first=first, release_end=end, update_id=update_id, max_nodes=track.max_nodes
    )
    return replace(
        track, released_end=end, update_id=update_id, pending=Outgoing(message), message=message
    )


def due_messages(
    track: OrderTrack, now: float, settings: DispatchSettings, gate: SendGate
) -> tuple[OrderTrack, list[Order | InstantActions]]:
    """Messages to publish now (first sends and resends), and the track with them marked sent.

    Nothing goes to a vehicle that is not ready (R84); order messages wait for
    minOrderInterval (R114); ``cancelOrder`` does not.
    """
    cancel_ready = gate.vehicle_ready if gate.cancel_ready is None else gate.cancel_ready
    if track.terminal or not (gate.vehicle_ready or cancel_ready):
        return track, []
    out: list[Order | InstantActions] = []
    cancel, pending = track.cancel, track.pending
    resend = gate.resend_allowed
    if cancel is not None and cancel_ready and _due(cancel, now, settings, resend=resend):
        if cancel.sends >= settings.max_sends:
            return _give_up(track, f"no state confirmed cancelOrder after {cancel.sends} sends"), []
        track = evolve(track, cancel=_sent(cancel, now))
        out.append(cancel.message)
    ready = gate.vehicle_ready and gate.order_allowed
    if pending is not None and ready and _due(pending, now, settings, resend=resend):
        if pending.sends >= settings.max_sends:
            reason = (
                f"no state confirmed orderUpdateId {track.update_id} after {pending.sends} sends"
            )
            return _give_up(track, reason), out
        track = evolve(track, pending=_sent(pending, now), sent_update_id=track.update_id)
        out.append(pending.message)
    return track, out


def anything_due(
    track: OrderTrack, now: float, settings: DispatchSettings, *, resend: bool = True
) -> bool:
    """Whether :func:`due_messages` may have something to send now: a message not yet sent, or
    one whose confirmation is overdue (see :attr:`SendGate.resend_allowed` for ``resend``).
    Cheap, so a periodic sweep can skip every other order."""
    if track.terminal:
        return False
    cancel, pending = track.cancel, track.pending
    return (cancel is not None and _due(cancel, now, settings, resend=resend)) or (
        pending is not None and _due(pending, now, settings, resend=resend)
    )


def unsettled(track: OrderTrack) -> bool:
    """Whether ``track`` has a message not yet sent or not yet confirmed: only such an order
    can become due (:func:`anything_due`) as time passes, without a new message or request."""
    return not track.terminal and (track.pending is not None or track.cancel is not None)


def _give_up(track: OrderTrack, reason: str) -> OrderTrack:
    return replace(track, status=OrderStatus.FAILED, reason=reason, pending=None, cancel=None)


def _sent(outgoing: Outgoing, now: float) -> Outgoing:
    return evolve(outgoing, sends=outgoing.sends + 1, last_sent=now)


def _due(outgoing: Outgoing, now: float, settings: DispatchSettings, *, resend: bool) -> bool:
    if outgoing.last_sent is None:
        return True
    timeout = settings.confirm_timeout_s * (1.0 if resend else BEHIND_CEILING)
    return now - outgoing.last_sent >= timeout


def request_cancel(track: OrderTrack, message: InstantActions) -> OrderTrack | str:
    """Stop extending and resending; send ``cancelOrder`` (§6.6.3, R66). A problem if ended."""
    if track.terminal:
        return f"order {track.order_id!r} is already {track.status.value}"
    if track.cancel_action_id is not None:
        return f"order {track.order_id!r} is already being cancelled"
    return replace(
        track,
        pending=None,
        cancel=Outgoing(message),
        cancel_action_id=message.actions[0].action_id,
    )
