"""Asking vehicles for a missing state or factsheet (§6.8.1 stateRequest/factsheetRequest; a
factsheet narrows, its absence never makes a vehicle unusable)."""

from __future__ import annotations

import itertools

from structlog.testing import capture_logs

from vda5050.models import (
    ActionState,
    ActionStatus,
    Connection,
    ConnectionState,
    Error,
    OperatingMode,
)
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId
from vda_master.fleet import FleetView, Observation, VehicleView, reduce_fleet
from vda_master.inquirer import BEHIND_TICK_S, Inquirer
from vda_master.inquiries import (
    BEHIND_FACTOR,
    FIRST_DELAY_S,
    MAX_ATTEMPTS,
    RETRY_DELAYS_S,
    Inquiry,
    InquiryKind,
    due,
    refusal,
    sent,
    wanted,
)
from vda_master.testing import make_factsheet

AGV = AgvId("acme", "agv1")


def _vehicle(*messages: object, at: float = 0.0) -> VehicleView:
    view = FleetView()
    for message in messages:
        view = reduce_fleet(view, Observation(AGV, message), at)  # type: ignore[arg-type]
    vehicle = view.get(AGV)
    assert vehicle is not None
    return vehicle


def _online(version: str = "2.0.0") -> Connection:
    return Connection.model_validate(
        {**HEADER, "version": version, "connection_state": ConnectionState.ONLINE}
    )


def test_online_vehicle_without_state_or_factsheet_is_asked_for_both() -> None:
    """ONLINE, nothing known: a stateRequest and a factsheetRequest are wanted."""
    vehicle = _vehicle(_online())
    assert wanted(InquiryKind.STATE, vehicle, stale_before=None)
    assert wanted(InquiryKind.FACTSHEET, vehicle, stale_before=None)


def test_nothing_is_wanted_from_a_vehicle_that_is_not_online() -> None:
    """A vehicle that is not ONLINE cannot answer, so it is not asked."""
    broken = Connection.model_validate({**HEADER, "connection_state": "CONNECTIONBROKEN"})
    vehicle = _vehicle(broken)
    assert not wanted(InquiryKind.STATE, vehicle, stale_before=None)
    assert not wanted(InquiryKind.FACTSHEET, vehicle, stale_before=None)


def test_known_state_is_wanted_again_only_when_stale() -> None:
    """A state older than the master's reconnect is stale and asked for again."""
    vehicle = _vehicle(_online(), make_state(), at=10.0)
    assert not wanted(InquiryKind.STATE, vehicle, stale_before=None)
    assert not wanted(InquiryKind.STATE, vehicle, stale_before=5.0)
    assert wanted(InquiryKind.STATE, vehicle, stale_before=11.0)


def test_valid_factsheet_is_not_asked_for() -> None:
    """A vehicle whose valid factsheet is known gets no factsheetRequest."""
    vehicle = _vehicle(_online(), make_factsheet())
    assert not wanted(InquiryKind.FACTSHEET, vehicle, stale_before=None)


def test_requests_back_off_and_stop() -> None:
    """The first request waits FIRST_DELAY_S (what the vehicle publishes by itself comes
    first); resends wait 5, 10, 20, 40 s; after MAX_ATTEMPTS sends nothing more is due."""
    inquiry, now = Inquiry(InquiryKind.STATE, opened_at=0.0), 0.0
    times = []
    while now < 500:
        if due(inquiry, now):
            times.append(now)
            inquiry = sent(inquiry, f"a{len(times)}", now)
        now += 0.5
    assert len(times) == MAX_ATTEMPTS
    assert times[0] == FIRST_DELAY_S
    assert [b - a for a, b in itertools.pairwise(times)] == list(RETRY_DELAYS_S)


def test_requests_wait_longer_while_master_control_lags() -> None:
    """Behind its inbound messages, master control waits BEHIND_FACTOR times each delay: the
    state or factsheet it lacks may only be unread (load is not loss)."""
    fresh = Inquiry(InquiryKind.STATE, opened_at=0.0)
    assert due(fresh, FIRST_DELAY_S)
    assert not due(fresh, FIRST_DELAY_S, behind=True)
    assert due(fresh, FIRST_DELAY_S * BEHIND_FACTOR, behind=True)
    once = sent(fresh, "q1", 1.0)
    assert not due(once, 1.0 + RETRY_DELAYS_S[0] * BEHIND_FACTOR - 0.1, behind=True)
    assert due(once, 1.0 + RETRY_DELAYS_S[0] * BEHIND_FACTOR, behind=True)


def test_vehicle_in_manual_is_not_asked() -> None:
    """R84: no instant action, not even a request, goes to a vehicle in MANUAL."""
    vehicle = _vehicle(_online(), make_state(operating_mode=OperatingMode.MANUAL))
    assert not wanted(InquiryKind.FACTSHEET, vehicle, stale_before=None)
    assert not wanted(InquiryKind.STATE, vehicle, stale_before=100.0)


def test_failed_action_state_is_a_refusal() -> None:
    """The request's actionState FAILED means the vehicle refused it."""
    inquiry = sent(Inquiry(InquiryKind.FACTSHEET), "q1", 0.0)
    state = make_state(
        action_states=[
            ActionState(
                action_id="q1",
                action_status=ActionStatus.FAILED,
                result_description="not supported",
            )
        ]
    )
    assert refusal(inquiry, state) == "not supported"


def test_error_naming_the_action_is_a_refusal() -> None:
    """A vehicle that does not know the action rejects it with an error naming its actionId."""
    inquiry = sent(Inquiry(InquiryKind.FACTSHEET), "q1", 0.0)
    error = Error.model_validate(
        {
            "errorType": "instantActionError",
            "errorLevel": "WARNING",
            "errorDescription": "instant action is not executable",
            "errorReferences": [{"referenceKey": "actionId", "referenceValue": "q1"}],
        }
    )
    state = make_state(errors=[error])
    assert refusal(inquiry, state) == "instantActionError: instant action is not executable"
    assert refusal(sent(Inquiry(InquiryKind.STATE), "q2", 0.0), state) is None


class _Sent:
    def __init__(self) -> None:
        self.actions: list[tuple[AgvId, str, str]] = []
        self._ids = iter(f"id{n}" for n in range(1000))

    def send(self, agv: AgvId, action: object) -> None:
        self.actions.append((agv, action.action_type, action.action_id))  # type: ignore[attr-defined]

    def new_id(self) -> str:
        return next(self._ids)


def test_inquirer_asks_once_then_retries_only_when_due() -> None:
    """A new ONLINE vehicle gets both requests at once, nothing more until the retry delay."""
    out = _Sent()
    inquirer = Inquirer(out.send, out.new_id)
    vehicle = _vehicle(_online())
    inquirer.vehicle_reconnected(vehicle, 0.0)
    fleet = reduce_fleet(FleetView(), Observation(AGV, _online()), 0.0)
    inquirer.tick(fleet, 0.5)
    assert out.actions == []
    inquirer.tick(fleet, 1.0)
    assert [a[1] for a in out.actions] == ["stateRequest", "factsheetRequest"]
    inquirer.tick(fleet, 5.0)
    assert len(out.actions) == 2
    inquirer.tick(fleet, 6.0)
    assert len(out.actions) == 4


def test_lagging_inquirer_visits_open_inquiries_once_a_second() -> None:
    """While master control lags, the tick waits BEHIND_FACTOR times the first delay and
    visits the open inquiries at most every BEHIND_TICK_S, not every tick."""
    out = _Sent()
    inquirer = Inquirer(out.send, out.new_id)
    inquirer.behind = True
    inquirer.vehicle_reconnected(_vehicle(_online()), 0.0)
    fleet = reduce_fleet(FleetView(), Observation(AGV, _online()), 0.0)
    inquirer.tick(fleet, FIRST_DELAY_S * BEHIND_FACTOR - 0.1)
    inquirer.tick(fleet, FIRST_DELAY_S * BEHIND_FACTOR)  # due, but within the second
    assert out.actions == []
    inquirer.tick(fleet, FIRST_DELAY_S * BEHIND_FACTOR - 0.1 + BEHIND_TICK_S)
    assert [a[1] for a in out.actions] == ["stateRequest", "factsheetRequest"]


def test_refused_factsheet_request_is_logged_and_not_repeated() -> None:
    """A refusal is one WARNING line; the vehicle stays usable and is not asked again."""
    out = _Sent()
    inquirer = Inquirer(out.send, out.new_id)
    vehicle = _vehicle(_online())
    inquirer.vehicle_reconnected(vehicle, 0.0)
    inquirer.tick(reduce_fleet(FleetView(), Observation(AGV, _online()), 0.0), 1.0)
    factsheet_id = out.actions[1][2]
    refused = make_state(
        action_states=[ActionState(action_id=factsheet_id, action_status=ActionStatus.FAILED)]
    )
    with capture_logs() as logs:
        inquirer.observe_state(_vehicle(_online(), refused), refused, 1.5)
    assert [entry["event"] for entry in logs] == [
        "vehicle.request_refused",
        "vehicle.request_closed",
    ]
    assert logs[0]["action"] == "factsheetRequest"
    fleet = reduce_fleet(FleetView(), Observation(AGV, _online()), 0.0)
    inquirer.tick(fleet, 100.0)
    assert [a[1] for a in out.actions].count("factsheetRequest") == 1
    assert inquirer.pending() == 0


def test_broker_reconnect_asks_every_online_vehicle_for_a_state() -> None:
    """After the master reconnects to the broker, known states are stale: every ONLINE vehicle
    gets a stateRequest at once instead of waiting for its heartbeat."""
    out = _Sent()
    inquirer = Inquirer(out.send, out.new_id)
    fleet = FleetView()
    for message in (_online(), make_factsheet(), make_state()):
        fleet = reduce_fleet(fleet, Observation(AGV, message), 1.0)
    inquirer.broker_connected(fleet, 50.0)
    inquirer.tick(fleet, 51.0)
    assert [a[1] for a in out.actions] == ["stateRequest"]
