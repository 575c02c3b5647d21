"""Master control's answers to a 3.0 robot's zone and edge requests (3.0 §6.4.3, §6.6.10,
§6.9; rules T91-T94): what traffic control gives the vehicle is what is granted."""

from __future__ import annotations

from vda5050.models import v3
from vda5050.models.v3.state import (
    EdgeRequest,
    EdgeRequestType,
    RequestStatus,
    ZoneRequest,
    ZoneRequestType,
)
from vda5050.topics import AgvId
from vda_master.zone_requests import (
    RESEND_AFTER_S,
    Answered,
    Decision,
    Facts,
    decide,
    owners_after,
    remember,
)

G, Q, X = v3.GrantType.GRANTED, v3.GrantType.QUEUED, v3.GrantType.REJECTED


def _access(
    request_id: str = "r1",
    zone_id: str = "door",
    status: RequestStatus = RequestStatus.REQUESTED,
    request_type: ZoneRequestType = ZoneRequestType.ACCESS,
) -> ZoneRequest:
    return ZoneRequest(
        request_id=request_id,
        request_type=request_type,
        zone_id=zone_id,
        zone_set_id="demo.zones.abc",
        request_status=status,
    )


def _facts(*, held: set[str] | None = None, lease_s: float | None = 60.0) -> Facts:
    def release_zone(zone_set_id: str, zone_id: str) -> str | None:
        if zone_set_id != "demo.zones.abc":
            return "not a zone set of this master control"
        return None if zone_id == "door" else "the zone set has no such zone"

    return Facts(
        release_zone=release_zone,
        holds=lambda zone_id: zone_id in (held or set()),
        in_base=lambda edge_id, sequence_id: (edge_id, sequence_id) == ("e1", 3),
        lease_s=lease_s,
    )


def _kinds(decisions: list[Decision]) -> list[tuple[str, v3.GrantType, bool]]:
    return [(d.request_id, d.grant_type, d.lease) for d in decisions]


def test_access_is_granted_with_a_lease_while_the_vehicle_holds_the_zone() -> None:
    """T92: GRANTED once traffic control has released the vehicle's base into the zone,
    QUEUED before (the grant follows), each with the reason it is logged with."""
    queued = decide([_access()], _facts(), {}, 0.0)
    assert _kinds(queued) == [("r1", Q, False)]
    granted = decide([_access()], _facts(held={"door"}), {}, 0.0)
    assert _kinds(granted) == [("r1", G, True)]
    assert "released into it" in granted[0].reason


def test_requests_master_control_cannot_grant_are_rejected_saying_why() -> None:
    """A zone of another zone set, an unknown zone, and every REPLANNING request (master
    control has no COORDINATED_REPLANNING zones) are REJECTED; the reason names the zone."""
    requests = [
        _access("a", zone_id="elsewhere"),
        _access("b", request_type=ZoneRequestType.REPLANNING),
        ZoneRequest(
            request_id="c",
            request_type=ZoneRequestType.ACCESS,
            zone_id="door",
            zone_set_id="someone.elses",
            request_status=RequestStatus.REQUESTED,
        ),
    ]
    decisions = decide(requests, _facts(held={"door"}), {}, 0.0)
    assert _kinds(decisions) == [("a", X, False), ("b", X, False), ("c", X, False)]
    assert "'elsewhere'" in decisions[0].reason
    assert "COORDINATED_REPLANNING" in decisions[1].reason
    assert "not a zone set of this master control" in decisions[2].reason


def test_a_corridor_is_granted_for_an_edge_of_the_released_base_only() -> None:
    """T94 (§6.6.10): fleet control releases the corridor only for edges of the base."""
    in_base = EdgeRequest(
        request_id="e",
        request_type=EdgeRequestType.CORRIDOR,
        edge_id="e1",
        sequence_id=3,
        request_status=RequestStatus.REQUESTED,
    )
    beyond = in_base.model_copy(update={"request_id": "f", "sequence_id": 5})
    decisions = decide([in_base, beyond], _facts(), {}, 0.0)
    assert _kinds(decisions) == [("e", G, True), ("f", X, False)]
    assert "not in the robot's released base" in decisions[1].reason


def test_an_answer_is_sent_once_and_again_only_while_the_robot_does_not_show_it() -> None:
    """``responses`` is QoS 0: an answer the robot's state does not reflect yet is resent
    after RESEND_AFTER_S; an unchanged QUEUED is not repeated with every state; a change
    (QUEUED -> GRANTED) goes at once."""
    facts = _facts()
    first = decide([_access()], facts, {}, 0.0)
    answered = remember({}, first, ["r1"], 60.0, 0.0)
    assert decide([_access()], facts, answered, 1.0) == []
    assert _kinds(decide([_access()], facts, answered, RESEND_AFTER_S)) == [("r1", Q, False)]
    assert _kinds(decide([_access()], _facts(held={"door"}), answered, 1.0)) == [("r1", G, True)]


def test_a_lease_is_renewed_at_half_time_while_the_robot_reports_granted() -> None:
    """§6.9: a later leaseExpiry extends the grant. Not renewed before half of it has passed;
    no renewal at all without a lease."""
    facts = _facts(held={"door"})
    granted = remember({}, decide([_access()], facts, {}, 0.0), ["r1"], 60.0, 0.0)
    assert granted["r1"] == Answered(G, 0.0, 60.0)
    holding = [_access(status=RequestStatus.GRANTED)]
    assert decide(holding, facts, granted, 29.0) == []
    assert _kinds(decide(holding, facts, granted, 30.0)) == [("r1", G, True)]
    assert decide(holding, _facts(held={"door"}, lease_s=None), granted, 30.0) == []


def test_a_grant_traffic_control_does_not_back_is_neither_renewed_nor_revoked() -> None:
    """A robot reporting GRANTED for a zone traffic control does not give it (a master restart
    in between): revoking it inside the zone would stop it, renewing it could put two vehicles
    inside. It is left alone and its lease runs out. One that traffic control does give it
    gets this master's lease at once."""
    holding = [_access(status=RequestStatus.GRANTED)]
    assert decide(holding, _facts(), {}, 0.0) == []
    assert _kinds(decide(holding, _facts(held={"door"}), {}, 0.0)) == [("r1", G, True)]


def test_revoked_expired_and_dropped_requests_need_no_answer_and_are_forgotten() -> None:
    """The robot lets a REVOKED or EXPIRED request go (§6.9); once it leaves the state, its
    answer is forgotten."""
    gone = [_access("a", status=RequestStatus.REVOKED), _access("b", status=RequestStatus.EXPIRED)]
    assert decide(gone, _facts(held={"door"}), {}, 0.0) == []
    answered = {"a": Answered(G, 0.0, 60.0), "z": Answered(Q, 0.0)}
    assert remember(answered, [], ["a"], 60.0, 1.0) == {"a": Answered(G, 0.0, 60.0)}


def test_with_traffic_control_off_a_zone_goes_to_one_asking_robot_at_a_time() -> None:
    """T92 without traffic control: first come, first served; the zone is free again once its
    robot's state no longer asks for it (it has left), and REPLANNING claims nothing."""
    first, second = AgvId("acme", "r1"), AgvId("acme", "r2")
    owners = owners_after({}, first, [_access()])
    assert owners == {"door": first}
    assert owners_after(owners, second, [_access("r9")]) == {"door": first}
    replanning = _access("r5", zone_id="hall", request_type=ZoneRequestType.REPLANNING)
    assert owners_after(owners, second, [replanning]) == {"door": first}
    assert owners_after(owners_after(owners, first, []), second, [_access()]) == {"door": second}
