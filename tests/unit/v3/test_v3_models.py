"""The 3.0 wire models: field names, enums, defaults and the rule tables they carry."""

from __future__ import annotations

import json
import math

import pytest
from pydantic import ValidationError

from vda5050.codec import encode
from vda5050.models import v3
from vda5050.testing import (
    make_action_v3,
    make_factsheet_v3,
    make_order_v3,
    make_state_v3,
    make_zone_v3,
)

S = v3.ActionStatus


def order_json(**edge: object) -> bytes:
    raw = json.loads(encode(make_order_v3(["a", "b"])))
    raw["edges"][0].update(edge)
    return json.dumps(raw).encode()


# -- order ------------------------------------------------------------------------------------


def test_edges_have_no_endpoint_ids_and_use_3_0_names() -> None:
    """T18, T100: a 3.0 edge carries no startNodeId/endNodeId and spells its limits out."""
    order = v3.Order.model_validate_json(
        order_json(
            maximumSpeed=1.0,
            maximumMobileRobotHeight=2.0,
            minimumLoadHandlingDeviceHeight=0.1,
            reachOrientationBeforeEntering=True,
        ),
        strict=True,
    )
    edge = order.edges[0]
    assert (edge.maximum_speed, edge.maximum_mobile_robot_height) == (1.0, 2.0)
    assert edge.minimum_load_handling_device_height == 0.1
    assert edge.reach_orientation_before_entering is True
    encoded = json.loads(encode(order))["edges"][0]
    assert "startNodeId" not in encoded
    assert "endNodeId" not in encoded
    assert encoded["maximumSpeed"] == 1.0


@pytest.mark.parametrize("name", ["maximumRotationSpeed", "maxRotationSpeed"])
def test_rotation_speed_is_read_under_both_names_and_sent_under_the_text_name(name: str) -> None:
    """T100: the text's maximumRotationSpeed is sent; the official schema's maxRotationSpeed is
    also understood, so such a field is never silently ignored (T21)."""
    order = v3.Order.model_validate_json(order_json(**{name: 0.7}), strict=True)
    assert order.edges[0].maximum_rotation_speed == 0.7
    edge = json.loads(encode(order))["edges"][0]
    assert edge["maximumRotationSpeed"] == 0.7
    assert "maxRotationSpeed" not in edge


def test_2x_edge_fields_are_ignored_not_mapped() -> None:
    """T16: 2.x names such as maxSpeed are unknown extra fields in 3.0 and are dropped."""
    order = v3.Order.model_validate_json(
        order_json(maxSpeed=9.0, rotationAllowed=True), strict=True
    )
    assert order.edges[0].maximum_speed is None
    assert b"maxSpeed" not in encode(order)


@pytest.mark.parametrize(
    ("a", "b", "theta", "inside", "outside"),
    [
        (1.0, 0.5, 0.0, [(0.99, 0.0), (0.0, 0.49), (0.6, 0.3)], [(1.01, 0.0), (0.0, 0.51)]),
        (1.0, 0.5, math.pi / 2, [(0.0, 0.99), (0.49, 0.0)], [(0.99, 0.0), (0.0, 1.01)]),
        (1.0, 0.5, math.pi / 4, [(0.7, 0.7)], [(0.7, -0.7)]),
        (1.0, 0.0, 0.0, [(0.5, 0.0), (-1.0, 0.0)], [(0.5, 0.01)]),
        (0.0, 0.0, 0.0, [(0.0, 0.0)], [(0.001, 0.0)]),
    ],
)
def test_allowed_deviation_is_a_rotated_ellipse(
    a: float,
    b: float,
    theta: float,
    inside: list[tuple[float, float]],
    outside: list[tuple[float, float]],
) -> None:
    """T99, T71: the deviation ellipse has semi-axes a (along theta) and b; a = b = 0 allows
    only the node itself."""
    ellipse = v3.AllowedDeviationXY(a=a, b=b, theta=min(theta, 1.570796327))
    assert all(ellipse.contains(dx, dy) for dx, dy in inside)
    assert not any(ellipse.contains(dx, dy) for dx, dy in outside)


@pytest.mark.parametrize(
    "ellipse",
    [{"a": -1, "b": 0, "theta": 0}, {"a": 1, "b": 1, "theta": 2.0}, {"a": 1, "b": 1}],
)
def test_malformed_ellipses_are_rejected(ellipse: dict[str, float]) -> None:
    """T99: negative axes, a rotation beyond ±π/2 and a missing field fail validation."""
    with pytest.raises(ValidationError):
        v3.AllowedDeviationXY.model_validate(ellipse, strict=True)


def test_trajectory_needs_only_control_points_and_positive_weights() -> None:
    """T101: degree and knotVector are optional, degree is an integer, weights are > 0."""
    trajectory = v3.Trajectory.model_validate_json(b'{"controlPoints": [{"x": 0, "y": 0}]}')
    assert trajectory.degree is None
    for bad in (
        b'{"degree": 1.0, "controlPoints": []}',
        b'{"controlPoints": [{"x": 0, "y": 0, "weight": 0}]}',
        b'{"degree": 2}',
    ):
        with pytest.raises(ValidationError):
            v3.Trajectory.model_validate_json(bad, strict=True)


def test_order_knows_its_base_and_decision_point() -> None:
    """The decision point is the last released node (§6.1.2); the base holds the released
    elements."""
    order = make_order_v3(["a", "b", "c", "d"], released=2)
    nodes, edges = order.base()
    assert [n.node_id for n in nodes] == ["a", "b"]
    assert [e.edge_id for e in edges] == ["a-b"]
    decision = order.decision_point()
    assert decision is not None
    assert (decision.node_id, decision.sequence_id) == ("b", 2)


# -- actions ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("blocking", "drives", "parallel"),
    [
        (v3.BlockingType.NONE, True, True),
        (v3.BlockingType.SINGLE, True, False),
        (v3.BlockingType.SOFT, False, True),
        (v3.BlockingType.HARD, False, False),
    ],
)
def test_blocking_types_follow_table_3(
    blocking: v3.BlockingType, drives: bool, parallel: bool
) -> None:
    """T48: NONE drives + parallel, SINGLE drives alone, SOFT stops + parallel, HARD stops
    alone."""
    assert (blocking.allows_driving, blocking.allows_parallel) == (drives, parallel)


def test_retriable_defaults_to_false() -> None:
    """T52: an action without the retriable flag is not retriable."""
    assert not make_action_v3("pick", "a").is_retriable
    assert make_action_v3("pick", "a", retriable=True).is_retriable
    assert make_action_v3("pick", "a", stationType="floor").parameter("stationType") == "floor"


def test_instant_actions_accept_only_blocking_type_none() -> None:
    """T49: an instant action's blockingType is NONE; SINGLE, SOFT and HARD are invalid."""
    for value in ("SINGLE", "SOFT", "HARD"):
        with pytest.raises(ValidationError, match="always NONE"):
            v3.InstantAction.model_validate_json(
                json.dumps({"actionType": "beep", "actionId": "a", "blockingType": value}),
                strict=True,
            )


def test_figure_21_transitions() -> None:
    """T51: RETRIABLE is reached only from RUNNING and left by retry (INITIALIZING/RUNNING),
    skipRetry/cancel (FAILED) or an operator (FINISHED); FINISHED and FAILED are final."""
    assert v3.may_transition(S.RUNNING, S.RETRIABLE)
    assert not v3.may_transition(S.WAITING, S.RETRIABLE)
    assert not v3.may_transition(S.INITIALIZING, S.RETRIABLE)
    assert v3.ACTION_TRANSITIONS[S.RETRIABLE] == {S.INITIALIZING, S.RUNNING, S.FINISHED, S.FAILED}
    assert not v3.may_transition(None, S.PAUSED)
    assert not v3.may_transition(None, S.RETRIABLE)
    for final in v3.FINAL_ACTION_STATUSES:
        assert not v3.ACTION_TRANSITIONS[final]
    assert set(v3.ACTION_TRANSITIONS) == {None, *S}


# -- state ------------------------------------------------------------------------------------


def state_with(**fields: object) -> v3.State:
    return make_state_v3(**fields)


def action_state(action_id: str, status: v3.ActionStatus) -> v3.ActionState:
    return v3.ActionState(action_id=action_id, action_status=status)


def test_idle_means_no_node_edge_states_and_only_final_order_actions() -> None:
    """T28: idle needs empty nodeStates and edgeStates and every order action FINISHED or
    FAILED; instant actions do not count."""
    assert state_with().is_idle()
    assert state_with(
        action_states=[action_state("a", S.FINISHED), action_state("b", S.FAILED)],
        instant_action_states=[action_state("i", S.RUNNING)],
    ).is_idle()
    horizon = v3.NodeState(node_id="h", sequence_id=2, released=False)
    assert not state_with(node_states=[horizon]).is_idle()
    for status in (S.WAITING, S.RUNNING, S.PAUSED, S.RETRIABLE, S.INITIALIZING):
        assert not state_with(action_states=[action_state("a", status)]).is_idle()


def test_action_state_is_found_in_every_array() -> None:
    """T50: order, instant and zone action states are reported in three arrays."""
    state = state_with(
        action_states=[action_state("o", S.WAITING)],
        instant_action_states=[action_state("i", S.FINISHED)],
        zone_action_states=[action_state("z", S.RUNNING)],
    )
    found = [state.action_state(i) for i in ("o", "i", "z", "x")]
    assert [s.action_status if s else None for s in found] == [
        S.WAITING,
        S.FINISHED,
        S.RUNNING,
        None,
    ]


def test_state_requires_the_3_0_fields() -> None:
    """T70: instantActionStates and powerSupply are required; batteryState is not a 3.0 field."""
    raw = json.loads(encode(make_state_v3()))
    assert raw["instantActionStates"] == []
    assert raw["powerSupply"] == {"stateOfCharge": 80.0, "charging": False}
    for missing in ("instantActionStates", "powerSupply", "safetyState", "lastNodeId"):
        reduced = {k: v for k, v in raw.items() if k != missing}
        with pytest.raises(ValidationError, match=missing):
            v3.State.model_validate_json(json.dumps(reduced), strict=True)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("operatingMode", "TEACHIN"),
        ("operatingMode", "SEMI_AUTOMATIC"),
        ("operatingMode", "automatic"),
    ],
)
def test_enums_use_the_exact_3_0_spelling(field: str, value: str) -> None:
    """T15: 3.0 enums are case-sensitive UPPER_SNAKE; 2.x spellings are rejected."""
    raw = json.loads(encode(make_state_v3()))
    raw[field] = value
    with pytest.raises(ValidationError):
        v3.State.model_validate_json(json.dumps(raw), strict=True)
    assert {m.value for m in v3.OperatingMode} >= {"TEACH_IN", "STARTUP", "INTERVENED"}
    assert v3.ConnectionState.CONNECTION_BROKEN.value == "CONNECTION_BROKEN"
    assert v3.CorridorReferencePoint.KINEMATIC_CENTER.value == "KINEMATIC_CENTER"


def test_request_status_accepts_queued_on_input() -> None:
    """§A: QUEUED (§6.9) is understood although the §7.8 table and schema lack it."""
    request = v3.ZoneRequest.model_validate_json(
        b'{"requestId": "r", "requestType": "ACCESS", "zoneId": "z", "zoneSetId": "s",'
        b' "requestStatus": "QUEUED"}',
        strict=True,
    )
    assert request.request_status is v3.RequestStatus.QUEUED


# -- errors -----------------------------------------------------------------------------------


def test_predefined_error_types_carry_their_table_9_level() -> None:
    """T76: every predefined error type has its Table 9 level; the rejection errors of §6.1.4
    are WARNING except UNSUPPORTED_PARAMETER (CRITICAL) and INSUFFICIENT_MEMORY (URGENT)."""
    levels = v3.PREDEFINED_ERROR_LEVELS
    assert set(levels) == set(v3.ErrorType)
    assert levels[v3.ErrorType.UNSUPPORTED_PARAMETER] is v3.ErrorLevel.CRITICAL
    assert levels[v3.ErrorType.INSUFFICIENT_MEMORY] is v3.ErrorLevel.URGENT
    assert levels[v3.ErrorType.LOCALIZATION_ERROR] is v3.ErrorLevel.FATAL
    for warning in (
        "VALIDATION_FAILURE",
        "INVALID_ORDER_ACTION",
        "OUTDATED_ORDER_UPDATE",
        "SAME_ORDER_UPDATE_ID",
        "ORDER_UPDATE_FOLLOWING_CANCEL",
        "OTHER_ORDER_ACTIVE",
        "START_NODE_OUT_OF_RANGE",
        "NO_ROUTE_TO_TARGET",
        "MOBILE_ROBOT_NOT_AVAILABLE",
        "UNKNOWN_MAP_ID",
        "NO_ORDER_TO_CANCEL",
    ):
        assert levels[v3.ErrorType(warning)] is v3.ErrorLevel.WARNING, warning


def test_predefined_error_builds_the_error_object() -> None:
    """T46, T76: NO_ORDER_TO_CANCEL is a WARNING referencing the cancelOrder's actionId."""
    error = v3.predefined_error(
        v3.ErrorType.NO_ORDER_TO_CANCEL, ("actionId", "ia-1"), description="no order"
    )
    assert error.error_level is v3.ErrorLevel.WARNING
    assert error.reference("actionId") == "ia-1"
    assert error.known_type is v3.ErrorType.NO_ORDER_TO_CANCEL
    assert json.loads(error.model_dump_json(by_alias=True, exclude_none=True)) == {
        "errorType": "NO_ORDER_TO_CANCEL",
        "errorReferences": [{"referenceKey": "actionId", "referenceValue": "ia-1"}],
        "errorDescription": "no order",
        "errorLevel": "WARNING",
    }


def test_vendor_error_types_are_accepted() -> None:
    """T76: errorType is an extensible enum; unknown types decode and are not 'known'."""
    error = v3.Error.model_validate_json(
        b'{"errorType": "acmeOverheat", "errorLevel": "URGENT"}', strict=True
    )
    assert error.known_type is None
    with pytest.raises(ValidationError):
        v3.Error.model_validate_json(b'{"errorType": "x", "errorLevel": "ERROR"}', strict=True)


@pytest.mark.parametrize(
    ("level", "stops", "blocks"),
    [
        (v3.ErrorLevel.WARNING, False, False),
        (v3.ErrorLevel.URGENT, False, False),
        (v3.ErrorLevel.CRITICAL, True, False),
        (v3.ErrorLevel.FATAL, True, True),
    ],
)
def test_error_levels_say_whether_the_robot_drives_and_takes_orders(
    level: v3.ErrorLevel, stops: bool, blocks: bool
) -> None:
    """T77: CRITICAL and FATAL stop the robot; only FATAL refuses new orders."""
    assert (level.stops_driving, level.blocks_new_orders) == (stops, blocks)


# -- operating modes --------------------------------------------------------------------------


def test_orders_are_allowed_in_automatic_semiautomatic_and_intervened_only() -> None:
    """T26, T60: Table 11's 'sending orders allowed' column."""
    allowed = {mode for mode in v3.OperatingMode if mode.rules.orders_allowed}
    assert allowed == {
        v3.OperatingMode.AUTOMATIC,
        v3.OperatingMode.SEMIAUTOMATIC,
        v3.OperatingMode.INTERVENED,
    }


def test_instant_actions_per_mode() -> None:
    """T58, T60: all instant actions in (SEMI)AUTOMATIC, only cancelOrder in INTERVENED, none
    in MANUAL, STARTUP, SERVICE, TEACH_IN."""
    intervened = v3.OperatingMode.INTERVENED.rules
    assert intervened.allows_instant_action("cancelOrder")
    assert not intervened.allows_instant_action("startPause")
    assert v3.OperatingMode.SEMIAUTOMATIC.rules.allows_instant_action("startPause")
    for mode in ("MANUAL", "STARTUP", "SERVICE", "TEACH_IN"):
        assert not v3.OperatingMode(mode).rules.allows_instant_action("cancelOrder")


def test_which_modes_clear_the_order_and_the_last_node() -> None:
    """T61, T62, T63, T65: MANUAL, STARTUP, SERVICE, TEACH_IN clear the order; SERVICE,
    TEACH_IN, STARTUP always empty lastNodeId, MANUAL only when needed; INTERVENED keeps the
    order but drops zone requests; STARTUP states are not valid."""
    clearing = {m for m in v3.OperatingMode if m.rules.clears_order_on_entry}
    assert clearing == {
        v3.OperatingMode.MANUAL,
        v3.OperatingMode.STARTUP,
        v3.OperatingMode.SERVICE,
        v3.OperatingMode.TEACH_IN,
    }
    assert v3.OperatingMode.MANUAL.rules.empties_last_node_id == "if_not_continuable"
    assert v3.OperatingMode.SERVICE.rules.empties_last_node_id == "always"
    intervened = v3.OperatingMode.INTERVENED.rules
    assert intervened.clears_zone_requests_on_entry
    assert not intervened.clears_order_on_entry
    assert [m for m in v3.OperatingMode if not m.rules.state_valid] == [v3.OperatingMode.STARTUP]


# -- zones, responses, factsheet --------------------------------------------------------------


@pytest.mark.parametrize(("zone_type", "fields"), list(v3.ZONE_PARAMETERS.items()))
def test_each_zone_type_requires_its_parameters(
    zone_type: v3.ZoneType, fields: tuple[str, ...]
) -> None:
    """T84: a zone without its type's parameters is invalid and the error names them."""
    if not fields:
        assert make_zone_v3("z", zone_type).zone_type is zone_type
        return
    with pytest.raises(ValidationError, match=fields[0]):
        make_zone_v3("z", zone_type)


def test_zone_needs_three_vertices() -> None:
    """T85: fewer than three vertices make a zone invalid."""
    with pytest.raises(ValidationError, match="at least 3"):
        make_zone_v3("z", v3.ZoneType.BLOCKED, corners=((0, 0), (1, 0)))


def test_zone_categories() -> None:
    """T84: six contour-based and four kinematic-center-based zone types."""
    assert len(v3.CONTOUR_BASED_ZONES) == 6
    assert v3.ZoneType.PRIORITY not in v3.CONTOUR_BASED_ZONES
    assert v3.ZoneType.BLOCKED in v3.CONTOUR_BASED_ZONES


def test_zone_actions_have_no_action_id() -> None:
    """§7.6: the robot makes up zone action ids, so none is sent."""
    zone = make_zone_v3(
        "z",
        v3.ZoneType.ACTION,
        entry_actions=[v3.ZoneAction(action_type="beep", blocking_type=v3.BlockingType.NONE)],
        during_actions=[],
        exit_actions=[],
    )
    assert "actionId" not in json.loads(zone.model_dump_json(by_alias=True))["entryActions"][0]


def test_response_uses_grant_type() -> None:
    """T92: a response names its request and the decision as grantType."""
    response = v3.Response.model_validate_json(
        b'{"requestId": "r1", "grantType": "GRANTED", "leaseExpiry": "2026-01-01T00:00:00.000Z"}',
        strict=True,
    )
    assert response.grant_type is v3.GrantType.GRANTED
    with pytest.raises(ValidationError):
        v3.Response.model_validate_json(
            b'{"requestId": "r1", "grantType": "GRANTED", "leaseExpiry": "tomorrow"}', strict=True
        )


def test_factsheet_declares_mandatory_actions_and_zones() -> None:
    """T55, T81, T82: the factsheet lists cancelOrder/startPause/stopPause with pause and cancel
    flags, and the zone types the robot understands."""
    sheet = make_factsheet_v3(supported_zones=[v3.ZoneType.BLOCKED])
    for action_type in ("cancelOrder", "startPause", "stopPause"):
        action = sheet.action(action_type)
        assert action is not None
        assert action.pause_allowed is False
    assert sheet.supports_zone(v3.ZoneType.BLOCKED)
    assert not sheet.supports_zone(v3.ZoneType.RELEASE)
    assert not make_factsheet_v3().supports_zone(v3.ZoneType.BLOCKED)
    encoded = json.loads(encode(sheet))
    assert "mobileRobotGeometry" in encoded
    assert "agvGeometry" not in encoded


def test_factsheet_envelope_names_keep_their_lowercase_d() -> None:
    """T80: envelopes2d/envelope2dId are read and written with a lowercase d."""
    raw = json.loads(encode(make_factsheet_v3()))
    raw["mobileRobotGeometry"] = {
        "envelopes2d": [{"envelope2dId": "e", "vertices": [{"x": 0, "y": 0}]}]
    }
    sheet = v3.Factsheet.model_validate_json(json.dumps(raw), strict=True)
    assert [e.envelope2d_id for e in sheet.mobile_robot_geometry.envelopes2d or []] == ["e"]
    encoded = json.loads(encode(sheet))["mobileRobotGeometry"]
    assert encoded["envelopes2d"][0]["envelope2dId"] == "e"


def test_error_translations_pair_a_language_with_a_text() -> None:
    """T78: description and hint translations are (ISO 639-1 key, text) pairs."""
    error = v3.Error.model_validate_json(
        b'{"errorType": "x", "errorLevel": "WARNING", "errorDescription": "blocked",'
        b' "errorDescriptionTranslations":'
        b' [{"translationKey": "de", "translationValue": "blockiert"}],'
        b' "errorHintTranslations": [{"translationKey": "fr", "translationValue": "attendre"}]}',
        strict=True,
    )
    assert [
        (t.translation_key, t.translation_value) for t in error.error_description_translations or []
    ] == [("de", "blockiert")]
    assert error.error_hint is None
    with pytest.raises(ValidationError):
        v3.Translation.model_validate_json(b'{"translationKey": "de"}', strict=True)


def test_cancel_order_may_name_the_order() -> None:
    """T44: cancelOrder is an instant action that may carry an orderId parameter."""
    action = v3.InstantAction.model_validate_json(
        b'{"actionType": "cancelOrder", "actionId": "c1", "blockingType": "NONE",'
        b' "actionParameters": [{"key": "orderId", "value": "order-7"}]}',
        strict=True,
    )
    assert action.parameter("orderId") == "order-7"
