"""The next stop of an order with several (docs/master.md, *Orders with several stops*).

An order asked for with ``stops`` is planned and sent to its first stop like any order; the
others wait in its track (:attr:`OrderTrack.onward`). Once the vehicle stands at the end of the
route (its whole base released and confirmed), the route to the next stop is planned from there
(time-aware with traffic control; a station type goes to its nearest free node) and appended
by an order update whose stitching node is the stop the vehicle stands at (§6.6.2; its actions
stay as first sent, R58), with the next stop's actions at its new end. Traffic control sees each
leg as a re-plan of the order's route, so waits, detours and back-offs work leg by leg.

A next stop that can no longer be reached (a BLOCKED zone since, no route, an action the
vehicle's factsheet stopped offering) ends the order: master control cancels it on the vehicle
and it ends FAILED, saying which stop and why.

A vehicle must not run the stitching node's actions again (R51; 3.0 says so in as many words).
One that does (vda-5050-lib 1.4's AGV runs them again: a pick then fails, "load already
picked") is noticed by the state that follows the update, logged (``vehicle.reran_actions``),
and from then on not sent orders with several stops (:meth:`OnwardStops.reruns_stop_actions`).
"""

from __future__ import annotations

import itertools
from dataclasses import replace
from typing import TYPE_CHECKING

import structlog

from vda5050.models import State
from vda5050.topics import AgvId
from vda_master.dispatcher import OrderTrack, at_stop
from vda_master.order_builder import BuildProblem, stop_actions
from vda_master.release import progress_index
from vda_master.resolution import Resolution
from vda_master.routing import Route, RouteProblem
from vda_master.stops import Stop, reran_actions, stop_number

log = structlog.get_logger()


class OnwardStops(Resolution):
    """Mixed into the master service (with :class:`Resolution`, whose re-plan of a route's
    tail it uses): appending an order's next stop."""

    if TYPE_CHECKING:

        def _new_id(self) -> str: ...
        def _leg(self, start: str, stop: Stop) -> Route | RouteProblem: ...
        def _with_cancel(self, track: OrderTrack) -> OrderTrack | str: ...

    def _init_onward(self) -> None:
        #: Orders whose last update stitched at a stop, with the stop's (FINISHED) action ids,
        #: until the vehicle has left the stop: a state that lists one of them as not FINISHED
        #: (or twice) shows the vehicle ran them again (R51).
        self._stitched_at_stop: dict[str, tuple[int, frozenset[str]]] = {}
        #: Vehicles seen running a stitching node's actions again, with the order it was seen on.
        self._reruns: dict[AgvId, str] = {}

    def reruns_stop_actions(self, agv: AgvId) -> str | None:
        """Why ``agv`` takes no order with several stops (None: it may)."""
        order_id = self._reruns.get(agv)
        if order_id is None:
            return None
        return (
            f"it ran the actions of the node an order update starts at again (R51, seen on "
            f"order {order_id!r}): every further stop would repeat the last one's actions"
        )

    def check_stitched_stop(self, agv: AgvId, order_id: str, state: State) -> None:
        """After an update that stitched at a stop: did the vehicle run its actions again?"""
        stitched = self._stitched_at_stop.get(order_id)
        track = self.tracks.get(order_id)
        if stitched is None or track is None or state.order_id != order_id:
            return
        index, done = stitched
        again = reran_actions(done, state)
        if again:
            del self._stitched_at_stop[order_id]
            self._reruns[agv] = order_id
            log.warning(
                "vehicle.reran_actions",
                agv=str(agv),
                order_id=order_id,
                action_ids=list(again),
                reason="the vehicle runs the actions of an order update's stitching node again "
                "(R51); it is sent no more orders with several stops",
            )
        elif (progress_index(track.plan, state) or 0) > index:
            del self._stitched_at_stop[order_id]  # it has left the stop: all is well

    def go_on_to_next_stop(self, agv: AgvId, state: State, now: float) -> None:
        """``agv`` stands at the end of its order's route with stops still to come: append the
        next one (or end the order, saying why it cannot go on)."""
        order_id = self.active.get(agv)
        track = None if order_id is None else self.tracks.get(order_id)
        if track is None or not at_stop(track, state):
            return
        route = track.plan.route
        assert route is not None  # noqa: S101 - a track with stops has its graph route
        here = route.node_ids[track.plan.last_index]
        stop, number = track.onward[0], stop_number(track.request_json, len(track.onward))
        leg = self._next_leg(agv, here, stop, now)
        if isinstance(leg, str):
            self._end_at_stop(track, f"stop {number} ({stop.describe()}): {leg}", now)
            return
        vehicle = self.fleet.get(agv)
        actions = stop_actions(
            self.graph,
            leg.destination,
            stop.actions,
            factsheet=None if vehicle is None else vehicle.factsheet,
            action_ids=(self._new_id() for _ in itertools.count()),
        )
        if isinstance(actions, BuildProblem):
            self._end_at_stop(track, f"stop {number} ({stop.describe()}): {actions.reason}", now)
            return
        appended = self._replace_tail(
            track,
            leg,
            last_actions=actions,
            resume=None,
            state=state,
            now=now,
            onward=track.onward[1:],
        )
        if not appended:
            self._end_at_stop(track, f"stop {number}: its order update could not be built", now)
        else:
            self.coordinator.add_leg(agv, here, leg.destination, now)
            index = track.plan.last_index
            done = frozenset(a.action_id for a in track.plan.nodes[index].actions)
            if done:
                self._stitched_at_stop[track.order_id] = (index, done)
            log.info(
                "order.next_stop",
                order_id=track.order_id,
                agv=str(agv),
                stop=number,
                node_id=leg.destination,
                length_m=round(leg.length_m, 3),
            )

    def _next_leg(self, agv: AgvId, here: str, stop: Stop, now: float) -> Route | str:
        """The route from ``here`` to ``stop`` (time-aware with traffic control, else the
        shortest), or why there is none."""
        if stop.destination is not None:
            closed = self.graph.node_closed(stop.destination)
            if closed is not None:
                return closed
            planned = self.coordinator.plan(agv, here, stop.destination, now)
            if planned is not None:
                return planned.route
        elif self.coordinator.enabled:
            nodes = self.graph.station_nodes(stop.station_type or "")
            chosen = self.coordinator.choose(
                [(agv, here)], tuple(n for n in nodes if n != here), now
            )
            if chosen is not None:
                return chosen[1].route
        static = self._leg(here, stop)
        return static.reason if isinstance(static, RouteProblem) else static

    def _end_at_stop(self, track: OrderTrack, reason: str, now: float) -> None:
        """The order cannot go on: cancel it on the vehicle; it ends FAILED with ``reason``."""
        cancelled = self._with_cancel(track)
        if isinstance(cancelled, str):
            return  # being cancelled already
        why = f"master control stopped it: {reason}"
        log.warning("order.stopped", order_id=track.order_id, agv=str(track.plan.agv), reason=why)
        self._store(track.plan.agv, replace(cancelled, cancel_reason=why, onward=()))
        self._pump(track.plan.agv, now)
