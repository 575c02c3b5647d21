"""Answering 3.0 robots' zone and edge requests on ``responses`` (the shell of
:mod:`vda_master.zone_requests`; 3.0 §6.4.3, §6.6.10, §6.9, §7.5).

Mixed into :class:`vda_master.service.MasterService`. Each 3.0 state's ``zoneRequests`` and
``edgeRequests`` are answered at once; the tick answers again the robots whose requests are
still open (QUEUED until traffic control releases the base into the zone, a lease due for
renewal), so a grant does not wait for the robot's next state. Logged as
``zones.request_answered`` (with the reason); a rejection at WARNING.

With traffic control off (config ``traffic_control: false``) nothing holds a RELEASE zone for
the vehicles: the zone then goes to one requesting robot at a time, first come, until its
requests for the zone leave its state (it has left the zone); vehicles that do not ask are not
kept out.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import timedelta
from typing import TYPE_CHECKING

import structlog

from vda5050.clock import Clock, format_timestamp
from vda5050.models import v3
from vda5050.models.v3.state import ZoneRequest
from vda5050.topics import AgvId, Topic
from vda_master.config import MasterConfig
from vda_master.coordination import Coordinator
from vda_master.dispatcher import OrderTrack
from vda_master.zone_requests import (
    Answered,
    Decision,
    Facts,
    Request,
    decide,
    owners_after,
    remember,
)

log = structlog.get_logger()


class ZoneAnswers:
    """The requests of each 3.0 robot and what was answered to them."""

    config: MasterConfig
    clock: Clock
    coordinator: Coordinator
    tracks: dict[str, OrderTrack]
    active: dict[AgvId, str]
    _zone_sets_made: dict[str, v3.ZoneSet]

    if TYPE_CHECKING:

        def _publish_v3_only(
            self, agv: AgvId, kind: Topic, model: type[v3.Responses], **content: object
        ) -> v3.Responses | None: ...

    def _init_zone_answers(self) -> None:
        #: Each robot's requests in its latest state (only robots that have some).
        self._requests: dict[AgvId, tuple[Request, ...]] = {}
        #: Request id -> the last answer, per robot.
        self._answered: dict[AgvId, dict[str, Answered]] = {}
        #: Traffic control off: RELEASE zone id -> the robot it is granted to.
        self._zone_owner: dict[str, AgvId] = {}
        lease = self.config.release_lease_s
        self._lease_s = lease if lease > 0 else None

    def note_requests(self, agv: AgvId, state: v3.State, now: float) -> None:
        """A 3.0 state: its zone and edge requests, answered where an answer is due."""
        requests: tuple[Request, ...] = (*(state.zone_requests or ()), *(state.edge_requests or ()))
        if not requests and agv not in self._requests:
            return
        if requests:
            self._requests[agv] = requests
        else:
            self._requests.pop(agv, None)
        self._own_zones(agv, requests)
        self._answer(agv, now)

    def answer_open_requests(self, now: float) -> None:
        """The tick: robots with requests in their latest state are answered where an answer
        is due (a zone granted since, a lease to renew, an answer that may have been lost)."""
        for agv in list(self._requests):
            self._answer(agv, now)

    def forget_requests(self, agv: AgvId) -> None:
        self._requests.pop(agv, None)
        self._answered.pop(agv, None)
        self._own_zones(agv, ())

    def release_zone_requests(self, zone_id: str) -> dict[str, str]:
        """``GET /zones``: the robots asking for ``zone_id`` -> their request's status."""
        return {
            f"{agv.manufacturer}/{agv.serial_number}": request.request_status.value
            for agv, requests in self._requests.items()
            for request in requests
            if isinstance(request, ZoneRequest) and request.zone_id == zone_id
        }

    def release_zone_holder(self, zone_id: str) -> AgvId | None:
        """The vehicle the zone is given to now (traffic control's holder), if any."""
        if not self.coordinator.enabled:
            return self._zone_owner.get(zone_id)
        holders = self.coordinator.controller.release_zone_holders(zone_id)
        return next(iter(holders), None)  # at most one: the zone's resources all conflict

    def _answer(self, agv: AgvId, now: float) -> None:
        requests = self._requests.get(agv, ())
        answered = self._answered.get(agv, {})
        decisions = decide(requests, self._facts(agv), answered, now)
        if decisions:
            self._send_responses(agv, decisions)
        live = [request.request_id for request in requests]
        kept = remember(answered, decisions, live, self._lease_s, now)
        if kept:
            self._answered[agv] = kept
        else:
            self._answered.pop(agv, None)

    def _facts(self, agv: AgvId) -> Facts:
        def holds(zone_id: str) -> bool:
            return self.release_zone_holder(zone_id) == agv

        return Facts(self._release_zone_problem, holds, self._base_check(agv), self._lease_s)

    def _release_zone_problem(self, zone_set_id: str, zone_id: str) -> str | None:
        zone_set = self._zone_sets_made.get(zone_set_id)
        if zone_set is None:
            return "not a zone set of this master control"
        zone = next((z for z in zone_set.zones if z.zone_id == zone_id), None)
        if zone is None:
            return "the zone set has no such zone"
        if zone.zone_type is not v3.ZoneType.RELEASE:
            return f"a {zone.zone_type.value} zone takes no ACCESS request"
        if zone_id not in self.coordinator.controller.state.conflicts.release_zones:
            return "the zone is no longer in force"
        return None

    def _base_check(self, agv: AgvId) -> Callable[[str, int], bool]:
        order_id = self.active.get(agv)
        track = self.tracks.get(order_id) if order_id is not None else None

        def in_base(edge_id: str, sequence_id: int) -> bool:
            if track is None or sequence_id % 2 == 0:
                return False
            index = sequence_id // 2
            edges = track.plan.edges
            return index < min(len(edges), track.released_end) and edges[index].edge_id == edge_id

        return in_base

    def _own_zones(self, agv: AgvId, requests: tuple[Request, ...]) -> None:
        """Traffic control off: first come, first served; a zone is free again once its
        robot's state no longer asks for it."""
        if self.coordinator.enabled:
            return
        self._zone_owner = owners_after(self._zone_owner, agv, requests)

    def _send_responses(self, agv: AgvId, decisions: list[Decision]) -> None:
        """§7.5: one ``responses`` message (QoS 0) with every answer due, stamped like every
        message to ``agv``."""
        expiry = self._lease_expiry()
        responses = [
            v3.Response(
                request_id=d.request_id,
                grant_type=d.grant_type,
                lease_expiry=expiry if d.lease else None,
            )
            for d in decisions
        ]
        sent = self._publish_v3_only(agv, Topic.RESPONSES, v3.Responses, responses=responses)
        if sent is None:
            return  # responses exist from 3.0 on (T02)
        for decision in decisions:
            rejected = decision.grant_type is v3.GrantType.REJECTED
            (log.warning if rejected else log.info)(
                "zones.request_answered",
                agv=str(agv),
                request_id=decision.request_id,
                grant_type=decision.grant_type.value,
                reason=decision.reason,
                lease_expiry=expiry if decision.lease else None,
            )

    def _lease_expiry(self) -> str | None:
        if self._lease_s is None:
            return None
        return format_timestamp(self.clock.now() + timedelta(seconds=self._lease_s))
