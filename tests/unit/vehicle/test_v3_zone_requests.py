"""Zone requests of the 3.0 vehicle for RELEASE zones (3.0 §6.4.3, §6.9; T91, T93 of
docs/vda5050-3.md): the pure lifecycle (:mod:`vda_vehicle.v3_requests`) and the simulated
vehicle that waits before a zone until fleet control grants it. Every state the vehicle sends
validates against the official 3.0.0 state schema."""

from __future__ import annotations

import functools
import json
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest
from jsonschema import Draft202012Validator, FormatChecker

from tests.spec_files import needs_official_schemas, official_schema
from vda5050.clock import FakeClock, format_timestamp
from vda5050.codec import encode
from vda5050.models import v3
from vda5050.testing import (
    make_action_v3,
    make_instant_action_v3,
    make_instant_actions_v3,
    make_order_v3,
    make_responses_v3,
    make_zone_set_v3,
    make_zone_v3,
)
from vda5050.topics import Topic
from vda_vehicle.model import RobotMode
from vda_vehicle.testing import Recorder, make_runtime_v3
from vda_vehicle.v3_requests import (
    RELEASE_LOST_DRIVING_ON,
    EdgeZones,
    Outcome,
    ZoneRequests,
    answer,
    cleared,
    first_closed,
    forget_refusals,
    loss_errors,
    reported,
    track,
)
from vda_vehicle.v3_zones import ReleaseZone, release_loss_defaulted
from vda_vehicle.vehicle_status import StackStatus

Json = dict[str, Any]
PREFIX = "vda5050/v3/acme/robot_0"
NOW = datetime(2026, 1, 1, tzinfo=UTC)
#: A RELEASE zone across the x axis at x 6..8 (counterclockwise).
DOOR = ((6.0, -1.0), (8.0, -1.0), (8.0, 1.0), (6.0, 1.0))
G, Q, RV, RJ = (
    v3.GrantType.GRANTED,
    v3.GrantType.QUEUED,
    v3.GrantType.REVOKED,
    v3.GrantType.REJECTED,
)


def release_zone(
    zone_id: str = "door",
    loss: v3.ZoneReleaseLossBehavior | None = v3.ZoneReleaseLossBehavior.STOP,
    corners: tuple[tuple[float, float], ...] = DOOR,
) -> ReleaseZone:
    zone = make_zone_v3(zone_id, v3.ZoneType.RELEASE, corners, release_loss_behavior="STOP")
    return ReleaseZone("zones-1", "map", zone.model_copy(update={"release_loss_behavior": loss}))


def edge(*zones: ReleaseZone, sequence_id: int = 3) -> EdgeZones:
    return EdgeZones("b-c", sequence_id, "c", zones)


def response(request_id: str, grant: v3.GrantType, lease: datetime | None = None) -> v3.Response:
    expiry = None if lease is None else format_timestamp(lease)
    return v3.Response(request_id=request_id, grant_type=grant, lease_expiry=expiry)


def statuses(book: ZoneRequests) -> list[tuple[str, str, str]]:
    return [(r.request_id, r.zone_id, r.request_status.value) for r in reported(book)]


NONE: frozenset[tuple[str, str]] = frozenset()
DOOR_KEY = ("zones-1", "door")


# -- the pure lifecycle -------------------------------------------------------------------------


def test_a_zone_ahead_is_asked_for_once_and_closes_its_edge_until_granted() -> None:
    """T91: an edge ahead reaching an enabled RELEASE zone brings one ACCESS request,
    REQUESTED, with a fresh requestId; the edge stays closed until GRANTED; the lease of a
    later GRANTED replaces the first (§6.9: extended)."""
    door = release_zone()
    ahead = (edge(door),)
    book = track(ZoneRequests(), ahead, NONE, NOW, reported=True)
    assert statuses(book) == [("zr-1", "door", "REQUESTED")]
    assert reported(book)[0].request_type is v3.ZoneRequestType.ACCESS
    assert track(book, ahead, NONE, NOW, reported=True) is book  # asked once
    assert first_closed(book, ahead) == ahead[0]
    book, result = answer(book, response("zr-1", G, NOW + timedelta(seconds=5)), NONE)
    assert result.outcome is Outcome.GRANTED
    assert statuses(book) == [("zr-1", "door", "GRANTED")]
    assert first_closed(book, ahead) is None
    book, _ = answer(book, response("zr-1", G, NOW + timedelta(seconds=60)), NONE)
    later = track(book, ahead, NONE, NOW + timedelta(seconds=30), reported=True)
    assert statuses(later) == [("zr-1", "door", "GRANTED")]


def test_queued_keeps_waiting_and_reports_requested() -> None:
    """T93, Figure 16: QUEUED changes nothing the state shows (the official schema has no
    QUEUED); the edge stays closed. An unknown requestId is ignored."""
    ahead = (edge(release_zone()),)
    book = track(ZoneRequests(), ahead, NONE, NOW, reported=True)
    queued, result = answer(book, response("zr-1", Q), NONE)
    assert (queued, result.outcome) == (book, Outcome.QUEUED)
    assert statuses(queued) == [("zr-1", "door", "REQUESTED")]
    assert first_closed(queued, ahead) is not None
    same, result = answer(book, response("zr-99", G), NONE)
    assert (same, result.outcome, result.request) == (book, Outcome.UNKNOWN, None)


def test_every_zone_an_edge_reaches_must_be_granted() -> None:
    """§6.4.3: an area covered by two RELEASE zones is entered only with both granted."""
    door, hall = release_zone("door"), release_zone("hall")
    ahead = (edge(door, hall),)
    book = track(ZoneRequests(), ahead, NONE, NOW, reported=True)
    assert statuses(book) == [("zr-1", "door", "REQUESTED"), ("zr-2", "hall", "REQUESTED")]
    book, _ = answer(book, response("zr-1", G), NONE)
    assert first_closed(book, ahead) == ahead[0]
    book, _ = answer(book, response("zr-2", G), NONE)
    assert first_closed(book, ahead) is None


def test_a_lease_passed_before_entry_is_expired_once_then_asked_anew() -> None:
    """§6.4.3: the lease passed before entry: EXPIRED in one state, not entered; then the
    request goes and a new one (new requestId) is asked."""
    ahead = (edge(release_zone()),)
    book = track(ZoneRequests(), ahead, NONE, NOW, reported=True)
    book, _ = answer(book, response("zr-1", G, NOW + timedelta(seconds=2)), NONE)
    expired = track(book, ahead, NONE, NOW + timedelta(seconds=2), reported=True)
    assert statuses(expired) == [("zr-1", "door", "EXPIRED")]
    assert first_closed(expired, ahead) == ahead[0]
    unsent = track(expired, ahead, NONE, NOW + timedelta(seconds=3), reported=False)
    assert statuses(unsent) == [("zr-1", "door", "EXPIRED")]  # not yet in a state
    again = track(expired, ahead, NONE, NOW + timedelta(seconds=3), reported=True)
    assert statuses(again) == [("zr-2", "door", "REQUESTED")]


def test_revoked_before_entry_is_removed_and_asked_anew() -> None:
    """§6.4.3: REVOKED before entry: the request leaves the state; the zone still needed, a
    new request follows."""
    ahead = (edge(release_zone()),)
    book = track(ZoneRequests(), ahead, NONE, NOW, reported=True)
    book, _ = answer(book, response("zr-1", G), NONE)
    book, result = answer(book, response("zr-1", RV), NONE)
    assert (result.outcome, statuses(book)) == (Outcome.REVOKED, [])
    book = track(book, ahead, NONE, NOW, reported=True)
    assert statuses(book) == [("zr-2", "door", "REQUESTED")]


def test_rejected_is_dropped_and_not_asked_again_until_a_new_order() -> None:
    """T93: REJECTED: not entered, the request dropped, the zone not asked for again (the
    vehicle waits for fleet control, §6.4.5) until a new order or update."""
    ahead = (edge(release_zone()),)
    book = track(ZoneRequests(), ahead, NONE, NOW, reported=True)
    book, result = answer(book, response("zr-1", RJ), NONE)
    assert result.outcome is Outcome.REJECTED
    assert result.request is not None
    assert result.request.request_id == "zr-1"
    book = track(book, ahead, NONE, NOW, reported=True)
    assert statuses(book) == []
    assert first_closed(book, ahead) == ahead[0]
    book = track(forget_refusals(book), ahead, NONE, NOW, reported=True)
    assert statuses(book) == [("zr-2", "door", "REQUESTED")]


def test_a_request_leaves_after_the_zone_or_when_no_longer_needed() -> None:
    """§6.4.3: GRANTED is reported while the body is inside, also once no edge ahead needs
    the zone (the order ended inside); it goes once the body has left. A request not yet
    granted goes as soon as no edge ahead needs it (order cancelled or replaced)."""
    ahead = (edge(release_zone()),)
    book = track(ZoneRequests(), ahead, NONE, NOW, reported=True)
    book, _ = answer(book, response("zr-1", G), NONE)
    inside = frozenset({DOOR_KEY})
    assert statuses(track(book, (), inside, NOW, reported=True)) == [("zr-1", "door", "GRANTED")]
    assert statuses(track(book, (), NONE, NOW, reported=True)) == []
    waiting = track(ZoneRequests(), ahead, NONE, NOW, reported=True)
    assert statuses(track(waiting, (), NONE, NOW, reported=True)) == []
    assert track(waiting, (), NONE, NOW, reported=True).issued == 1  # ids are not reused


@pytest.mark.parametrize(
    ("loss", "status", "passable", "error"),
    [
        (v3.ZoneReleaseLossBehavior.STOP, "REVOKED", False, ("RELEASE_LOST", "CRITICAL")),
        (None, "REVOKED", False, ("RELEASE_LOST", "CRITICAL")),  # Table 6: absent means STOP
        (
            v3.ZoneReleaseLossBehavior.CONTINUE,
            "GRANTED",
            True,
            (RELEASE_LOST_DRIVING_ON, "WARNING"),
        ),
        (
            v3.ZoneReleaseLossBehavior.EVACUATE,
            "REVOKED",
            True,
            (RELEASE_LOST_DRIVING_ON, "WARNING"),
        ),
    ],
)
def test_revoked_inside_follows_the_release_loss_behavior(
    loss: v3.ZoneReleaseLossBehavior | None, status: str, passable: bool, error: tuple[str, str]
) -> None:
    """T93, Table 6: REVOKED with the body inside: STOP stops (RELEASE_LOST, CRITICAL) and
    asks anew while it still needs the zone, CONTINUE drives on reporting GRANTED, EVACUATE
    drives on until out; the request stays while the body is inside and goes once it has
    left, with the error."""
    door = release_zone(loss=loss)
    ahead = (edge(door),)
    inside = frozenset({DOOR_KEY})
    book = track(ZoneRequests(), ahead, NONE, NOW, reported=True)
    book, _ = answer(book, response("zr-1", G), NONE)
    book, result = answer(book, response("zr-1", RV), inside)
    assert result.outcome is Outcome.LOST
    book = track(book, ahead, inside, NOW, reported=True)
    anew = [] if passable else [("zr-2", "door", "REQUESTED")]
    assert statuses(book) == [("zr-1", "door", status), *anew]
    assert (first_closed(book, ahead) is None) is passable
    [lost] = loss_errors(book)
    assert (lost.error_type, lost.error_level.value) == error
    assert lost.reference("zoneId") == "door"
    left = track(book, (), NONE, NOW, reported=True)
    assert (statuses(left), loss_errors(left)) == ([], ())


def test_a_lease_expiring_inside_a_stop_zone_stops_until_granted_again() -> None:
    """§6.4.3: the lease passes inside a STOP zone: EXPIRED, RELEASE_LOST, and the vehicle
    asks anew beside the lost request; a GRANTED for either resumes it and the other request
    and the error go (Table 9: until the release is granted again)."""
    ahead = (edge(release_zone()),)
    inside = frozenset({DOOR_KEY})
    book = track(ZoneRequests(), ahead, NONE, NOW, reported=True)
    book, _ = answer(book, response("zr-1", G, NOW + timedelta(seconds=1)), NONE)
    later = NOW + timedelta(seconds=1)
    book = track(book, ahead, inside, later, reported=True)
    assert statuses(book) == [("zr-1", "door", "EXPIRED"), ("zr-2", "door", "REQUESTED")]
    assert first_closed(book, ahead) == ahead[0]
    assert [e.error_type for e in loss_errors(book)] == ["RELEASE_LOST"]
    regranted, result = answer(book, response("zr-1", G), inside)
    assert result.outcome is Outcome.REGRANTED
    assert first_closed(regranted, ahead) is None
    regranted = track(regranted, ahead, inside, later, reported=True)
    assert (statuses(regranted), loss_errors(regranted)) == ([("zr-1", "door", "GRANTED")], ())
    granted, result = answer(book, response("zr-2", G), inside)
    assert result.outcome is Outcome.GRANTED
    assert first_closed(granted, ahead) is None
    granted = track(granted, ahead, inside, later, reported=True)
    assert (statuses(granted), loss_errors(granted)) == ([("zr-2", "door", "GRANTED")], ())


def test_leaving_the_driving_modes_clears_every_request() -> None:
    """Table 11, T63: entering INTERVENED (or MANUAL, ...) removes all requests, also inside a
    zone; the counter goes on."""
    book = track(ZoneRequests(), (edge(release_zone()),), NONE, NOW, reported=True)
    assert cleared(book) == ZoneRequests(issued=1)


def test_the_contour_counts_for_a_release_zone() -> None:
    """§6.4.1.1: a way passing 0.5 m beside a RELEASE zone reaches it with the body's 0.72 m,
    not with a reach of 0.3 m; standing 0.6 m off it, the body is inside."""
    door = release_zone()
    beside = ((0.0, 1.5), (10.0, 1.5))
    assert door.reached(beside, 0.72)
    assert not door.reached(beside, 0.3)
    assert door.holds("map", (7.0, 1.6), 0.72)
    assert not door.holds("other", (7.0, 0.0), 0.72)


def test_a_release_zone_without_loss_behavior_becomes_stop() -> None:
    """Table 6: releaseLossBehavior left out means STOP; the zone set is taken as such."""
    zone = make_zone_v3("door", v3.ZoneType.RELEASE, DOOR, release_loss_behavior="EVACUATE")
    body = json.loads(encode(make_zone_set_v3(zone, make_zone_v3("b", v3.ZoneType.BLOCKED))))
    del body["zoneSet"]["zones"][0]["releaseLossBehavior"]
    payload, defaulted = release_loss_defaulted(json.dumps(body).encode())
    assert defaulted == ("door",)
    assert json.loads(payload)["zoneSet"]["zones"][0]["releaseLossBehavior"] == "STOP"
    assert release_loss_defaulted(b"not json RELEASE") == (b"not json RELEASE", ())


# -- the simulated vehicle ----------------------------------------------------------------------


@functools.cache
def _state_schema() -> Draft202012Validator:
    return Draft202012Validator(official_schema("3.0.0", "state"), format_checker=FormatChecker())


def schema_problems(sent: Recorder) -> list[str]:
    return [
        f"{error.message} at {error.json_path}"
        for _, kind, body in sent.sent
        if kind is Topic.STATE
        for error in _state_schema().iter_errors(json.loads(body))
    ]


class Robot:
    """A 3.0 vehicle at (0, 0) on a fake clock (1.2 m x 0.8 m: its body reaches 0.72 m)."""

    def __init__(self) -> None:
        self.clock = FakeClock()
        self.vehicle, self.sent = make_runtime_v3(self.clock)
        self.vehicle.on_connected()

    def order(self, order: v3.Order) -> None:
        self.vehicle.handle_order(f"{PREFIX}/order", encode(order))

    def instant(self, *actions: v3.InstantAction) -> None:
        message = make_instant_actions_v3(*actions)
        self.vehicle.handle_instant_actions(f"{PREFIX}/instantActions", encode(message))

    def zone_set(self, *zones: v3.Zone) -> None:
        self.vehicle.handle_zone_set(f"{PREFIX}/zoneSet", encode(make_zone_set_v3(*zones)))
        self.instant(make_instant_action_v3("enableZoneSet", "e-1", zoneSetId="zones-1"))

    def respond(self, *grants: v3.Response) -> None:
        self.vehicle.handle_responses(f"{PREFIX}/responses", encode(make_responses_v3(*grants)))

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / 0.2)):
            self.clock.advance(0.2)
            self.vehicle.tick(0.2, self.clock.monotonic())

    def run_until_x(self, x: float, limit_s: float = 30.0) -> None:
        for _ in range(round(limit_s / 0.2)):
            if self.x >= x:
                return
            self.run(0.2)
        msg = f"x {x} not reached"
        raise AssertionError(msg)

    @property
    def x(self) -> float:
        return self.vehicle.state.pose.x

    def last(self) -> Json:
        """The newest state sent (no tick in between)."""
        return self.sent.of(Topic.STATE)[-1]

    def state(self) -> Json:
        self.run(0.2)
        return self.last()

    def requests(self, state: Json | None = None) -> list[tuple[str, str]]:
        state = state or self.state()
        return [(r["requestId"], r["requestStatus"]) for r in state["zoneRequests"]]

    def errors(self) -> list[tuple[str, str]]:
        return [(e["errorType"], e["errorLevel"]) for e in self.state()["errors"]]


def door(loss: str | None = "STOP") -> v3.Zone:
    extra = {} if loss is None else {"release_loss_behavior": loss}
    return make_zone_v3("door", v3.ZoneType.RELEASE, DOOR, **extra)


def through_the_door() -> v3.Order:
    """a (0, 0) → b (3, 0) → c (12, 0): b → c runs through the door (x 6..8)."""
    return make_order_v3(["a", "b", "c"], positions=[(0.0, 0.0), (3.0, 0.0), (12.0, 0.0)])


def grant(request_id: str = "zr-1", lease: datetime | None = None) -> v3.Response:
    return response(request_id, G, lease)


@needs_official_schemas
def test_the_vehicle_waits_before_the_zone_until_granted_and_drops_the_request_after() -> None:
    """T91, T93, T68: the state answering the order already asks for the door (REQUESTED);
    the vehicle drives to b and waits there, its body outside the zone (driving false),
    reporting the request; GRANTED arrives and is reported at once, and it drives through;
    GRANTED is reported while inside, and the request leaves the state once the body is out
    of the zone. Every state fits the official schema."""
    robot = Robot()
    robot.zone_set(door())
    robot.run(1.0)  # minimumStateInterval: the order's state goes out at once
    robot.order(through_the_door())
    assert robot.requests(robot.last()) == [("zr-1", "REQUESTED")]
    robot.run(10.0)
    assert robot.x == pytest.approx(3.0)
    state = robot.state()
    assert (state["lastNodeId"], state["driving"]) == ("b", False)
    assert robot.requests(state) == [("zr-1", "REQUESTED")]

    robot.respond(grant())
    assert robot.requests(robot.last()) == [("zr-1", "GRANTED")]  # T68: at once
    robot.run_until_x(7.0)
    assert robot.requests() == [("zr-1", "GRANTED")]
    robot.run_until_x(6.0 + 2.0 + 0.72 + 0.3)
    assert robot.requests() == []
    robot.run(6.0)
    assert robot.state()["lastNodeId"] == "c"
    assert schema_problems(robot.sent) == []


def test_a_prompt_grant_lets_the_vehicle_drive_on_without_stopping() -> None:
    """T91: it asks as soon as the edge is in its released base, so a grant given before it
    reaches b keeps it driving through b."""
    robot = Robot()
    robot.zone_set(door())
    robot.order(through_the_door())
    robot.run(0.4)
    robot.respond(grant())
    while robot.x < 9.0:
        robot.run(0.2)
        assert robot.vehicle.state.driving
    assert robot.requests() == []


def test_an_edge_action_starts_only_when_the_vehicle_enters_the_edge() -> None:
    """§6.10.2 step 5, T91: the actions of an edge are triggered when the vehicle enters it.
    Held at b for the door, the vehicle has not entered b -> c: its action stays WAITING until
    the grant sets it off, and then runs as it drives."""
    robot = Robot()
    robot.zone_set(door())
    order = make_order_v3(
        ["a", "b", "c"],
        positions=[(0.0, 0.0), (3.0, 0.0), (12.0, 0.0)],
        edge_actions={1: [make_action_v3("detectObject", "look-1", objectType="door")]},
    )
    robot.order(order)
    robot.run(10.0)
    state = robot.state()
    assert (state["lastNodeId"], state["driving"]) == ("b", False)
    assert action_status(state, "look-1") == "WAITING"
    robot.respond(grant())
    robot.run(0.4)
    assert robot.vehicle.state.driving
    assert action_status(robot.last(), "look-1") in ("RUNNING", "FINISHED")


def action_status(state: Json, action_id: str) -> str:
    return str(next(a for a in state["actionStates"] if a["actionId"] == action_id)["actionStatus"])


def test_a_rejected_zone_is_not_entered_and_its_node_is_unreachable() -> None:
    """T93, §6.4.5: REJECTED: the request goes, the vehicle stays at b, reports c
    NODE_UNREACHABLE (CRITICAL, naming node and zone) and asks no more; a new order is fleet
    control's word: it clears the error and the vehicle drives elsewhere."""
    robot = Robot()
    robot.zone_set(door())
    robot.order(through_the_door())
    robot.run(6.0)
    robot.respond(response("zr-1", RJ))
    state = robot.last()
    assert robot.requests(state) == []
    [error] = state["errors"]
    assert (error["errorType"], error["errorLevel"]) == ("NODE_UNREACHABLE", "CRITICAL")
    references = {r["referenceKey"]: r["referenceValue"] for r in error["errorReferences"]}
    assert (references["nodeId"], references["zoneId"]) == ("c", "door")
    robot.run(6.0)
    assert robot.x == pytest.approx(3.0)
    assert robot.requests() == []
    robot.instant(make_instant_action_v3("cancelOrder", "c-1"))
    robot.run(1.0)
    robot.order(make_order_v3(["b", "d"], order_id="order-2", positions=[(3.0, 0.0), (3.0, 5.0)]))
    robot.run(6.0)
    state = robot.state()
    assert (state["lastNodeId"], state["errors"], state["zoneRequests"]) == ("d", [], [])


@needs_official_schemas
def test_a_lease_expiring_inside_a_stop_zone_stops_the_vehicle() -> None:
    """T93, Table 6: the lease passes while the body is in a STOP zone: the vehicle stops
    inside, reports the request EXPIRED (kept: it is still inside), RELEASE_LOST (CRITICAL),
    and asks anew. The new request granted, it drives on; the lost request and the error go,
    and the new request once it is out."""
    robot = Robot()
    robot.zone_set(door())
    robot.order(through_the_door())
    robot.run(0.4)
    lease = robot.clock.now() + timedelta(seconds=4.5)  # the body enters the door at ~4.3 s
    robot.respond(grant(lease=lease))
    robot.run(5.0)
    stopped_at = robot.x
    assert 6.0 - 0.72 < stopped_at < 8.0 + 0.72
    state = robot.state()
    assert robot.requests(state) == [("zr-1", "EXPIRED"), ("zr-2", "REQUESTED")]
    assert state["driving"] is False
    assert robot.errors() == [("RELEASE_LOST", "CRITICAL")]
    robot.run(3.0)
    assert robot.x == pytest.approx(stopped_at)

    robot.respond(grant("zr-2"))
    assert robot.requests(robot.last()) == [("zr-2", "GRANTED")]
    assert robot.last()["errors"] == []
    robot.run(6.0)
    state = robot.state()
    assert (state["lastNodeId"], state["errors"], state["zoneRequests"]) == ("c", [], [])
    assert schema_problems(robot.sent) == []


@needs_official_schemas
def test_a_lease_passed_before_entry_stops_the_vehicle_short_of_the_zone() -> None:
    """§6.4.3: the lease passes while the vehicle is still on its way to the door: one state
    says EXPIRED, the vehicle stops where it is, short of the zone, and asks anew (zr-2);
    granted, it drives through."""
    robot = Robot()
    robot.zone_set(door())
    robot.order(through_the_door())
    robot.run(6.0)  # waiting at b
    robot.respond(grant(lease=robot.clock.now() + timedelta(seconds=1)))
    seen: list[list[tuple[str, str]]] = []
    for _ in range(20):
        robot.run(0.2)
        seen.append(robot.requests(robot.last()))
    assert [("zr-1", "EXPIRED")] in seen
    assert seen[-1] == [("zr-2", "REQUESTED")]
    stopped_at = robot.x
    assert 3.0 < stopped_at < 6.0 - 0.72
    assert robot.state()["driving"] is False
    robot.respond(grant("zr-2"))
    robot.run(8.0)
    state = robot.state()
    assert (state["lastNodeId"], state["zoneRequests"]) == ("c", [])
    assert schema_problems(robot.sent) == []


def test_a_cancel_while_held_short_of_the_zone_ends_where_the_vehicle_stands() -> None:
    """§6.6.3, T91: held mid-edge short of the door (its lease passed before entry), the
    vehicle cannot finish the edge as a cancel otherwise makes it (R63), since that would take
    it into the zone: the cancel ends where it stands, FINISHED with no node left, the request
    is dropped and the vehicle never entered the zone."""
    robot = Robot()
    robot.zone_set(door())
    robot.order(through_the_door())
    robot.run(6.0)  # waiting at b
    robot.respond(grant(lease=robot.clock.now() + timedelta(seconds=1)))
    robot.run(4.0)
    stopped_at = robot.x
    assert 3.0 < stopped_at < 6.0 - 0.72
    robot.instant(make_instant_action_v3("cancelOrder", "cancel-1"))
    robot.run(2.0)
    state = robot.state()
    cancel = next(a for a in state["instantActionStates"] if a["actionId"] == "cancel-1")
    assert cancel["actionStatus"] == "FINISHED"
    assert (state["nodeStates"], state["edgeStates"], state["zoneRequests"]) == ([], [], [])
    assert robot.x == pytest.approx(stopped_at)
    assert schema_problems(robot.sent) == []


def test_a_revoke_inside_a_continue_zone_drives_on_with_a_warning() -> None:
    """Table 6 CONTINUE: revoked inside, the vehicle drives on, reports the request GRANTED
    and a WARNING until its body has left the zone; then both go."""
    robot = Robot()
    robot.zone_set(door("CONTINUE"))
    robot.order(through_the_door())
    robot.run(0.4)
    robot.respond(grant())
    robot.run_until_x(6.5)
    robot.respond(response("zr-1", RV))
    assert robot.requests(robot.last()) == [("zr-1", "GRANTED")]
    assert robot.errors() == [(RELEASE_LOST_DRIVING_ON, "WARNING")]
    assert robot.vehicle.state.driving
    robot.run_until_x(9.0)
    state = robot.state()
    assert (state["zoneRequests"], state["errors"]) == ([], [])


def test_the_vehicle_asks_anew_after_a_revoke_before_entry() -> None:
    """§6.4.3: REVOKED before entry: the request leaves; the zone still ahead, a new
    requestId is asked at once and the vehicle waits for it."""
    robot = Robot()
    robot.zone_set(door())
    robot.order(through_the_door())
    robot.respond(grant())
    robot.run(1.0)
    robot.respond(response("zr-1", RV))
    assert robot.requests(robot.last()) == [("zr-2", "REQUESTED")]
    robot.run(8.0)
    assert robot.x == pytest.approx(3.0)


def test_requests_are_cleared_in_intervened_and_asked_anew_after() -> None:
    """Table 11, T63: INTERVENED removes the requests and makes none; back in AUTOMATIC, the
    vehicle asks anew."""
    robot = Robot()
    robot.zone_set(door())
    robot.order(through_the_door())
    robot.vehicle.on_stack_status(StackStatus(RobotMode.INTERVENED))
    assert robot.requests(robot.last()) == []
    robot.vehicle.on_stack_status(StackStatus(RobotMode.AUTOMATIC))
    assert robot.requests() == [("zr-2", "REQUESTED")]


def test_bad_responses_are_validation_failures_and_unknown_ids_are_ignored() -> None:
    """Malformed responses become VALIDATION_FAILURE (T20) and never crash the vehicle; a
    response to no request held changes nothing."""
    robot = Robot()
    robot.vehicle.handle_responses(f"{PREFIX}/responses", b'{"responses": 3}')
    assert robot.errors() == [("VALIDATION_FAILURE", "WARNING")]
    before = len(robot.sent.of(Topic.STATE))
    robot.respond(grant("zr-7"))
    assert len(robot.sent.of(Topic.STATE)) == before


def test_a_zone_set_with_a_release_zone_without_loss_behavior_is_taken() -> None:
    """Table 6: a RELEASE zone without releaseLossBehavior is taken as STOP."""
    robot = Robot()
    body = json.loads(encode(make_zone_set_v3(door())))
    del body["zoneSet"]["zones"][0]["releaseLossBehavior"]
    robot.vehicle.handle_zone_set(f"{PREFIX}/zoneSet", json.dumps(body).encode())
    state = robot.state()
    assert state["errors"] == []
    assert state["zoneSets"] == [
        {"zoneSetId": "zones-1", "mapId": "map", "zoneSetStatus": "DISABLED"}
    ]
    assert robot.vehicle.zones[0].zone_set.zones[0].release_loss_behavior is (
        v3.ZoneReleaseLossBehavior.STOP
    )


def test_the_zone_is_judged_along_the_trajectory() -> None:
    """T91 with trajectories: a zone 2 m beside the straight line is out of the body's reach,
    so the straight edge asks nothing; a curve bending into it asks for it."""
    alcove = make_zone_v3(
        "alcove",
        v3.ZoneType.RELEASE,
        ((6.0, 2.0), (8.0, 2.0), (8.0, 4.0), (6.0, 4.0)),
        release_loss_behavior="STOP",
    )
    straight = make_order_v3(["a", "b"], positions=[(0.0, 0.0), (14.0, 0.0)])
    robot = Robot()
    robot.zone_set(alcove)
    robot.order(straight)
    assert robot.requests() == []
    trajectory = v3.Trajectory(
        degree=2,
        control_points=[
            v3.ControlPoint(x=0.0, y=0.0),
            v3.ControlPoint(x=7.0, y=6.0),
            v3.ControlPoint(x=14.0, y=0.0),
        ],
    )
    (leg,) = straight.edges
    curved = straight.model_copy(
        update={"edges": [leg.model_copy(update={"trajectory": trajectory})]}
    )
    robot = Robot()
    robot.zone_set(alcove)
    robot.order(curved)
    assert robot.requests() == [("zr-1", "REQUESTED")]


def test_a_disabled_zone_set_asks_nothing() -> None:
    """T91: requests only for zones of enabled zone sets."""
    robot = Robot()
    robot.vehicle.handle_zone_set(f"{PREFIX}/zoneSet", encode(make_zone_set_v3(door())))
    robot.order(through_the_door())
    robot.run(8.0)
    assert robot.requests() == []
    assert robot.x > 8.0
