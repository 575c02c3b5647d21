"""Vehicle alarms (docs/master.md, *Webhooks*): master control logs every error a vehicle
raises or clears (§6.10.5) and every change of its safety chain (§6.10.6), and tells a plant's
systems by ``vehicle.errors`` and ``vehicle.safety`` events."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any

import pytest
from structlog.testing import capture_logs

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import Error, ErrorLevel, ErrorReference, EStop, SafetyState, v3
from vda5050.testing import (
    make_connection_v3,
    make_factsheet_v3,
    make_state,
    make_state_v3,
)
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.alarms import (
    AlarmBoard,
    alarm_document,
    error_change,
    error_document,
    reported_level,
    safety_changed,
)
from vda_master.config import MasterConfig
from vda_master.service import MasterService
from vda_master.testing import RecordingPublisher, demo_graph, report_online
from vda_master.webhook_events import Event
from vda_master.wire3 import error_from_v3

AGV = AgvId("acme", "robot_0")


def _error(
    error_type: str = "noRouteToTarget",
    level: ErrorLevel = ErrorLevel.WARNING,
    description: str | None = None,
    **references: str,
) -> Error:
    return Error(
        error_type=error_type,
        error_level=level,
        error_description=description,
        error_references=[
            ErrorReference(reference_key=k, reference_value=v) for k, v in references.items()
        ]
        or None,
    )


def test_an_error_is_the_same_while_type_level_and_references_stay() -> None:
    first = _error(description="1 try", nodeId="7", orderId="o1")
    again = _error(description="2 tries", orderId="o1", nodeId="7")  # references reordered
    assert error_change([first], [again]) is None
    assert error_change([], []) is None
    other_node = _error(nodeId="8", orderId="o1")
    change = error_change([first], [again, other_node])
    assert change is not None
    assert (change.raised, change.cleared) == ((other_node,), ())
    worse = _error(level=ErrorLevel.FATAL, nodeId="7", orderId="o1")
    change = error_change([first], [worse])
    assert change is not None
    assert (change.raised, change.cleared) == ((worse,), (first,))
    change = error_change([first, first], [])  # one error listed twice is one error
    assert change is not None
    assert change.cleared == (first,)


def test_the_safety_chain_changes_with_either_field_and_a_first_state_only_when_not_clear() -> None:
    clear = SafetyState(e_stop=EStop.NONE, field_violation=False)
    assert not safety_changed(None, clear)
    assert not safety_changed(clear, clear)
    assert safety_changed(None, SafetyState(e_stop=EStop.NONE, field_violation=True))
    assert safety_changed(clear, SafetyState(e_stop=EStop.MANUAL, field_violation=False))
    manual = SafetyState(e_stop=EStop.MANUAL, field_violation=False)
    assert safety_changed(manual, SafetyState(e_stop=EStop.REMOTE, field_violation=False))
    assert safety_changed(manual, clear)


@pytest.mark.parametrize("level", [v3.ErrorLevel.URGENT, v3.ErrorLevel.CRITICAL])
@pytest.mark.parametrize("description", ["lidar dirty", None])
def test_a_3_0_robot_s_level_is_reported_as_it_sent_it(
    level: v3.ErrorLevel, description: str | None
) -> None:
    """T77 maps URGENT and CRITICAL to WARNING for the core; an alarm says the robot's level."""
    sent = v3.Error(error_type="sensorDirty", error_level=level, error_description=description)
    core = error_from_v3(sent)
    assert core.error_level is ErrorLevel.WARNING
    assert reported_level(core, v3=True) == level.value
    document = error_document(core, v3=True)
    assert (document["errorLevel"], document["errorDescription"]) == (level.value, description)
    # A 2.x vehicle's own words are never read as a level.
    said = _error(description=f"{level.value}: lidar dirty")
    assert error_document(said, v3=False)["errorLevel"] == "WARNING"
    assert error_document(said, v3=False)["errorDescription"] == f"{level.value}: lidar dirty"


def _recorded(service: MasterService) -> list[dict[str, Any]]:
    """The events ``service`` emits, recorded instead of sent."""
    events: list[dict[str, Any]] = []

    def record(event: Event) -> None:
        events.append(event)

    service.webhooks.emit = record  # type: ignore[method-assign]
    return events


def _service() -> tuple[MasterService, list[dict[str, Any]]]:
    settings = MasterConfig.model_validate(
        {"traffic_control": False, "webhook_urls": ["http://wms.example:8080/events"]}
    )
    service = MasterService(settings, demo_graph(), RecordingPublisher(), FakeClock())
    events = _recorded(service)
    report_online(service, AGV, "7")
    return service, events


def _send_state(service: MasterService, **fields: object) -> None:
    state = make_state(last_node_id="7", **fields)
    service.ingest(build_topic("uagv", 2, AGV, Topic.STATE), encode(state))


def _alarms(events: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [e for e in events if e["type"] in {"vehicle.errors", "vehicle.safety"}]


def test_an_error_raised_then_cleared_is_logged_and_sent_once_each() -> None:
    """R103: a state lists the active errors and drops one once it is cleared; master control
    tells each change once."""
    service, events = _service()
    blocked = _error("noRouteToTarget", description="aisle 4 blocked", nodeId="12")
    fatal = _error("driveFault", ErrorLevel.FATAL, description="motor 2 overheated")
    with capture_logs() as logs:
        _send_state(service, errors=[blocked], order_id="o1")
        _send_state(service, errors=[blocked], order_id="o1")  # nothing new
        _send_state(service, errors=[blocked, fatal], order_id="o1")
        _send_state(service, errors=[])

    alarms = _alarms(events)
    assert [(len(e["raised"]), len(e["cleared"]), len(e["errors"])) for e in alarms] == [
        (1, 0, 1),
        (1, 0, 2),
        (0, 2, 0),
    ]
    first = alarms[0]
    assert first["manufacturer"] == "acme"
    assert first["serialNumber"] == "robot_0"
    assert first["orderId"] == "o1"
    assert first["raised"] == [
        {
            "errorType": "noRouteToTarget",
            "errorLevel": "WARNING",
            "errorDescription": "aisle 4 blocked",
            "errorHint": None,
            "errorReferences": [{"referenceKey": "nodeId", "referenceValue": "12"}],
        }
    ]
    assert alarms[1]["raised"][0]["errorType"] == "driveFault"
    assert alarms[2]["orderId"] is None
    assert {e["errorType"] for e in alarms[2]["cleared"]} == {"noRouteToTarget", "driveFault"}
    raised = [
        (e["error_type"], e["log_level"]) for e in logs if e["event"] == "vehicle.error_raised"
    ]
    assert raised == [("noRouteToTarget", "info"), ("driveFault", "warning")]
    cleared = [e["error_type"] for e in logs if e["event"] == "vehicle.error_cleared"]
    assert sorted(cleared) == ["driveFault", "noRouteToTarget"]


def test_an_emergency_stop_and_its_release_are_logged_and_sent() -> None:
    """R104: eStop and fieldViolation follow the vehicle's safety chain."""
    service, events = _service()
    with capture_logs() as logs:
        _send_state(service, safety_state=SafetyState(e_stop=EStop.MANUAL, field_violation=False))
        _send_state(service, safety_state=SafetyState(e_stop=EStop.MANUAL, field_violation=False))
        _send_state(service)
    alarms = _alarms(events)
    assert [
        (e["eStop"], e["fieldViolation"], e["previousEStop"], e["previousFieldViolation"])
        for e in alarms
    ] == [("MANUAL", False, "NONE", False), ("NONE", False, "MANUAL", False)]
    changes = [
        (e["e_stop"], e["log_level"]) for e in logs if e["event"] == "vehicle.safety_changed"
    ]
    assert changes == [("MANUAL", "warning"), ("NONE", "info")]


def test_a_vehicle_s_first_state_reports_what_is_already_wrong() -> None:
    """After a restart of master control (or a new vehicle) the first state is compared with
    nothing: its errors are raised, a safety chain that is not clear is reported."""
    settings = MasterConfig.model_validate({"webhook_urls": ["http://wms.example/events"]})
    service = MasterService(settings, demo_graph(), RecordingPublisher(), FakeClock())
    events = _recorded(service)
    state = make_state(
        last_node_id="7",
        errors=[_error("driveFault", ErrorLevel.FATAL)],
        safety_state=SafetyState(e_stop=EStop.NONE, field_violation=True),
    )
    service.ingest(build_topic("uagv", 2, AGV, Topic.STATE), encode(state))
    alarms = _alarms(events)
    assert [e["type"] for e in alarms] == ["vehicle.errors", "vehicle.safety"]
    assert alarms[0]["raised"][0]["errorLevel"] == "FATAL"
    assert (alarms[1]["fieldViolation"], alarms[1]["previousFieldViolation"]) == (True, None)


def test_a_3_0_robot_s_critical_error_is_sent_as_critical() -> None:
    service = MasterService(
        MasterConfig.model_validate({"webhook_urls": ["http://wms.example/events"]}),
        demo_graph(),
        RecordingPublisher(),
        FakeClock(),
    )
    events = _recorded(service)

    def topic(kind: Topic) -> str:
        return build_topic("vda5050", 3, AGV, kind)

    service.ingest(topic(Topic.CONNECTION), encode(make_connection_v3()))
    service.ingest(topic(Topic.FACTSHEET), encode(make_factsheet_v3()))
    critical = v3.Error(
        error_type="sensorDirty", error_level=v3.ErrorLevel.CRITICAL, error_description="lidar"
    )
    service.ingest(topic(Topic.STATE), encode(make_state_v3(last_node_id="7", errors=[critical])))
    [alarm] = _alarms(events)
    assert alarm["raised"][0]["errorLevel"] == "CRITICAL"
    assert alarm["raised"][0]["errorDescription"] == "lidar"


def test_a_vehicle_without_errors_and_with_a_clear_safety_chain_logs_nothing() -> None:
    service = MasterService(MasterConfig(), demo_graph(), RecordingPublisher(), FakeClock())
    with capture_logs() as logs:
        report_online(service, AGV, "7")
        _send_state(service)
    assert not [e for e in logs if str(e["event"]).startswith(("vehicle.error", "vehicle.safety"))]


def test_the_board_keeps_when_each_alarm_began_and_lists_the_worst_first() -> None:
    board = AlarmBoard()
    start = datetime(2026, 12, 3, 8, 0, tzinfo=UTC)
    other = AgvId("acme", "robot_1")
    warning = _error("batteryLow", description="19 %")
    fatal = _error("driveFault", ErrorLevel.FATAL)
    board.note_errors(AGV, [warning], start, v3=False)
    later = start + timedelta(seconds=30)
    board.note_errors(AGV, [_error("batteryLow", description="18 %"), fatal], later, v3=False)
    board.note_safety(other, SafetyState(e_stop=EStop.AUTOACK, field_violation=False), later)
    assert [(a.agv, a.level, a.since) for a in board.alarms()] == [
        (AGV, "FATAL", later),
        (other, "SAFETY", later),
        (AGV, "WARNING", start),  # the same warning since the start, its description newer
    ]
    assert board.alarms()[2].error == _error("batteryLow", description="18 %")
    documents = [alarm_document(a) for a in board.alarms()]
    assert documents[1] == {
        "manufacturer": "acme",
        "serialNumber": "robot_1",
        "since": "2026-12-03T08:00:30.000Z",
        "kind": "safety",
        "safety": {"eStop": "AUTOACK", "fieldViolation": False},
    }
    assert documents[0]["kind"] == "error"
    assert documents[0]["error"]["errorType"] == "driveFault"  # type: ignore[index,call-overload]
    assert board.alarms(manufacturer="other") == []

    board.note_errors(AGV, [], later, v3=False)
    board.note_safety(other, SafetyState(e_stop=EStop.NONE, field_violation=False), later)
    assert board.alarms() == []


def test_a_3_0_robot_s_critical_alarm_ranks_below_a_stop_and_above_a_warning() -> None:
    board = AlarmBoard()
    now = datetime(2026, 12, 3, 8, 0, tzinfo=UTC)
    critical = error_from_v3(v3.Error(error_type="sensorDirty", error_level=v3.ErrorLevel.CRITICAL))
    board.note_errors(AGV, [_error("batteryLow"), critical], now, v3=True)
    board.note_safety(AGV, SafetyState(e_stop=EStop.NONE, field_violation=True), now)
    assert [a.level for a in board.alarms()] == ["SAFETY", "CRITICAL", "WARNING"]
    assert alarm_document(board.alarms()[1])["error"] == error_document(critical, v3=True)


def test_a_broken_connection_is_an_alarm_until_the_vehicle_is_back() -> None:
    """R11: CONNECTIONBROKEN (the broker's last will) is an alarm, ranked after FATAL errors;
    a vehicle that went OFFLINE on purpose, or is ONLINE again, is none."""
    board = AlarmBoard()
    now = datetime(2026, 12, 3, 8, 0, tzinfo=UTC)
    other = AgvId("acme", "robot_1")
    board.note_errors(AGV, [_error("driveFault", ErrorLevel.FATAL)], now, v3=False)
    board.note_safety(AGV, SafetyState(e_stop=EStop.MANUAL, field_violation=False), now)
    board.note_connection(other, "CONNECTIONBROKEN", now + timedelta(seconds=1))
    board.note_connection(AgvId("acme", "robot_2"), "OFFLINE", now)
    assert [(a.agv, a.level) for a in board.alarms()] == [
        (AGV, "FATAL"),
        (other, "CONNECTIONBROKEN"),
        (AGV, "SAFETY"),
    ]
    assert alarm_document(board.alarms()[1]) == {
        "manufacturer": "acme",
        "serialNumber": "robot_1",
        "since": "2026-12-03T08:00:01.000Z",
        "kind": "connection",
        "connection": {"connectionState": "CONNECTIONBROKEN"},
    }
    board.note_connection(other, "ONLINE", now)
    assert [a.level for a in board.alarms()] == ["FATAL", "SAFETY"]


def test_a_3_0_error_that_turns_from_urgent_to_critical_is_a_change() -> None:
    """T77: both reach the core as WARNINGs; the robot's own level tells them apart."""
    urgent, critical = (
        error_from_v3(v3.Error(error_type="batteryLow", error_level=level))
        for level in (v3.ErrorLevel.URGENT, v3.ErrorLevel.CRITICAL)
    )
    assert error_change([urgent], [critical], v3=False) is None  # 2.x reading: the same
    change = error_change([urgent], [critical], v3=True)
    assert change is not None
    assert (change.raised, change.cleared) == ((critical,), (urgent,))
