"""The graph file's zones as 3.0 zone sets for the robots that support them (T86; 3.0 §6.4.2,
§7.6; docs/master.md, Zones): one set per map under an id that changes with its content, sent,
enabled, and an older set of this master deleted, each step after the robot's state."""

from __future__ import annotations

import functools

from jsonschema import Draft202012Validator, FormatChecker

from tests.spec_files import needs_official_schemas, official_schema
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.graph_file import GraphZone
from vda5050.models import v3
from vda5050.testing import make_connection_v3, make_factsheet_v3, make_state_v3
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.api_documents import zones_document
from vda_master.config import MasterConfig
from vda_master.service import MasterService
from vda_master.testing import RecordingPublisher, demo_graph, demo_graph_with_zones, zone
from vda_master.zone_sets import (
    RESEND_AFTER_S,
    DeleteZoneSet,
    EnableZoneSet,
    SendZoneSet,
    next_step,
    zone_sets_of,
)

AGV = AgvId("acme", "robot_0")
CLOSED = zone("works", "BLOCKED", [[13.0, -1.5], [17.0, -1.5], [17.0, 1.5]])
SLOW = zone("slow", "SPEED_LIMIT", [[-1.0, 7.0], [6.0, 7.0], [6.0, 9.0]], maximumSpeed=0.4)
GRAPH = demo_graph_with_zones(CLOSED, SLOW)
Z = v3.ZoneSetStatus
Z_BLOCKED = v3.ZoneType.BLOCKED


def _held(zone_set_id: str, status: v3.ZoneSetStatus, map_id: str = "demo") -> v3.StoredZoneSet:
    return v3.StoredZoneSet(zone_set_id=zone_set_id, map_id=map_id, zone_set_status=status)


def test_one_zone_set_per_map_under_an_id_that_changes_with_its_content() -> None:
    (zone_set,) = zone_sets_of(GRAPH).values()
    assert zone_set.map_id == "demo"
    assert [z.zone_id for z in zone_set.zones] == ["works", "slow"]
    assert zone_set.zones[1].maximum_speed == 0.4
    assert zone_set.zone_set_id.startswith("demo.zones.")
    again = zone_sets_of(demo_graph_with_zones(CLOSED, SLOW))["demo"]
    assert again.zone_set_id == zone_set.zone_set_id  # the same zones: the same id
    faster = zone("slow", "SPEED_LIMIT", [[-1.0, 7.0], [6.0, 7.0], [6.0, 9.0]], maximumSpeed=0.6)
    changed = zone_sets_of(demo_graph_with_zones(CLOSED, faster))["demo"]
    assert changed.zone_set_id != zone_set.zone_set_id  # §6.4.2: never changed under one id
    assert zone_sets_of(demo_graph_with_zones()) == {}


def test_a_zone_drawn_clockwise_is_sent_counterclockwise() -> None:
    """3.0 §7.6 (T85): a zone's vertices are given counterclockwise; the graph file's need not."""
    clockwise = [[13.0, -1.5], [13.0, 1.5], [17.0, 1.5], [17.0, -1.5]]
    (sent,) = zone_sets_of(demo_graph_with_zones(zone("z", "BLOCKED", clockwise)))["demo"].zones
    assert [(v.x, v.y) for v in sent.vertices] == [tuple(c) for c in reversed(clockwise)]


def test_send_then_enable_then_delete_the_older_set_of_this_master() -> None:
    zone_set = zone_sets_of(GRAPH)["demo"]
    ours = zone_set.zone_set_id
    assert next_step(zone_set, [], {}, 0.0) == SendZoneSet(zone_set)
    assert next_step(zone_set, [_held(ours, Z.DISABLED)], {}, 0.0) == EnableZoneSet(ours)
    older, foreign = "demo.zones.0123456789ab", "plant-zones-7"
    held = [_held(ours, Z.ENABLED), _held(older, Z.DISABLED), _held(foreign, Z.DISABLED)]
    assert next_step(zone_set, held, {}, 0.0) == DeleteZoneSet(older)
    assert (
        next_step(zone_set, [_held(ours, Z.ENABLED), _held(foreign, Z.DISABLED)], {}, 0.0) is None
    )
    other_map = [_held(ours, Z.DISABLED, map_id="upstairs")]
    assert next_step(zone_set, other_map, {}, 0.0) == SendZoneSet(zone_set)


def test_a_step_asked_for_is_asked_again_only_after_a_while() -> None:
    """zoneSet and instantActions go QoS 0: a set that does not show up in the robot's states
    is sent again, but not with every state."""
    zone_set = zone_sets_of(GRAPH)["demo"]
    asked = {f"send {zone_set.zone_set_id}": 10.0}
    assert next_step(zone_set, [], asked, 10.0 + RESEND_AFTER_S - 0.1) is None
    assert next_step(zone_set, [], asked, 10.0 + RESEND_AFTER_S) == SendZoneSet(zone_set)


def _topic(kind: Topic) -> str:
    return build_topic("vda5050", 3, AGV, kind)


def _robot(supported: list[v3.ZoneType] | None) -> tuple[MasterService, RecordingPublisher]:
    publisher, clock = RecordingPublisher(), FakeClock()
    service = MasterService(MasterConfig.model_validate({}), GRAPH, publisher, clock)
    service.ingest(_topic(Topic.CONNECTION), encode(make_connection_v3()))
    service.ingest(_topic(Topic.FACTSHEET), encode(make_factsheet_v3(supported_zones=supported)))
    service.ingest(_topic(Topic.STATE), encode(make_state_v3(last_node_id="7")))
    return service, publisher


@functools.cache
def _official(kind: str) -> Draft202012Validator:
    return Draft202012Validator(official_schema("3.0.0", kind), format_checker=FormatChecker())


@needs_official_schemas
def test_a_robot_that_supports_the_zones_is_given_them_step_by_step() -> None:
    """The zone set goes out on zoneSet (official 3.0 schema); once the robot's state lists it
    DISABLED, enableZoneSet follows; GET /zones tells how far the robot has got."""
    service, publisher = _robot([v3.ZoneType.BLOCKED, v3.ZoneType.SPEED_LIMIT])
    zone_set_id = service.zone_sets["demo"].zone_set_id
    (sent,) = publisher.messages(Topic.ZONE_SET)
    assert not list(_official("zoneSet").iter_errors(sent))
    assert sent["zoneSet"]["zoneSetId"] == zone_set_id
    assert [z["zoneType"] for z in sent["zoneSet"]["zones"]] == ["BLOCKED", "SPEED_LIMIT"]
    (document, _) = zones_document(service.graph, service)
    assert document["robots"] == {"acme/robot_0": "SENT"}

    held = make_state_v3(last_node_id="7", zone_sets=[_held(zone_set_id, Z.DISABLED)])
    service.ingest(_topic(Topic.STATE), encode(held))
    (enable,) = publisher.messages(Topic.INSTANT_ACTIONS)
    assert not list(_official("instantActions").iter_errors(enable))
    (action,) = enable["actions"]
    assert action["actionType"] == "enableZoneSet"
    assert action["actionParameters"] == [{"key": "zoneSetId", "value": zone_set_id}]
    service.ingest(_topic(Topic.STATE), encode(held))
    assert len(publisher.messages(Topic.INSTANT_ACTIONS)) == 1  # not again with every state

    enabled = make_state_v3(last_node_id="7", zone_sets=[_held(zone_set_id, Z.ENABLED)])
    service.ingest(_topic(Topic.STATE), encode(enabled))
    assert zones_document(service.graph, service)[0]["robots"] == {"acme/robot_0": "ENABLED"}
    assert len(publisher.messages(Topic.ZONE_SET)) == 1


def test_a_robot_that_lists_no_zone_types_gets_no_zone_set() -> None:
    """A robot without ``supportedZones`` gets no zone set (its orders keep to the zones)."""
    service, publisher = _robot(None)
    assert publisher.messages(Topic.ZONE_SET) == []
    assert zones_document(service.graph, service)[0]["robots"] == {}


def test_a_robot_without_every_zone_type_gets_the_part_it_supports() -> None:
    """A robot that supports BLOCKED but not SPEED_LIMIT would refuse the whole set: it gets a
    set of its own with the BLOCKED zones only, and GET /zones shows the other zone as
    UNSUPPORTED for it (its orders are slowed there anyway)."""
    service, publisher = _robot([v3.ZoneType.BLOCKED])
    (sent,) = publisher.messages(Topic.ZONE_SET)
    assert [z["zoneType"] for z in sent["zoneSet"]["zones"]] == ["BLOCKED"]
    own = sent["zoneSet"]["zoneSetId"]
    assert own != service.zone_sets["demo"].zone_set_id
    works, slow = zones_document(service.graph, service)
    assert works["robots"] == {"acme/robot_0": "SENT"}
    assert slow["robots"] == {"acme/robot_0": "UNSUPPORTED"}

    enabled = make_state_v3(last_node_id="7", zone_sets=[_held(own, Z.DISABLED)])
    service.ingest(_topic(Topic.STATE), encode(enabled))
    (enable,) = publisher.messages(Topic.INSTANT_ACTIONS)
    assert enable["actions"][0]["actionParameters"] == [{"key": "zoneSetId", "value": own}]


@needs_official_schemas
async def test_zones_changed_at_run_time_reach_the_robot_as_a_new_set_or_an_empty_one() -> None:
    """A zone added through the API gives a new zone set, sent at once; with every zone of
    the map removed, the robot gets an empty set (valid by the official schema), which replaces
    ours once enabled."""
    service, publisher = _robot([v3.ZoneType.BLOCKED, v3.ZoneType.SPEED_LIMIT])
    before = service.zone_sets["demo"].zone_set_id
    await service.add_zone(
        GraphZone.model_validate(zone("spill", "BLOCKED", [[0.0, 3.0], [1.0, 3.0], [1.0, 5.0]]))
    )
    sent = publisher.messages(Topic.ZONE_SET)[-1]["zoneSet"]
    assert sent["zoneSetId"] != before
    assert [z["zoneId"] for z in sent["zones"]] == ["works", "slow", "spill"]

    bare = MasterService(MasterConfig.model_validate({}), demo_graph(), publisher, FakeClock())
    bare.ingest(_topic(Topic.CONNECTION), encode(make_connection_v3()))
    bare.ingest(_topic(Topic.FACTSHEET), encode(make_factsheet_v3(supported_zones=[Z_BLOCKED])))
    bare.ingest(_topic(Topic.STATE), encode(make_state_v3(last_node_id="7")))
    await bare.add_zone(GraphZone.model_validate(CLOSED))
    added = bare.zone_sets["demo"].zone_set_id
    await bare.remove_zone("works")
    empty = publisher.messages(Topic.ZONE_SET)[-1]
    assert not list(_official("zoneSet").iter_errors(empty))
    assert empty["zoneSet"]["zones"] == []
    assert empty["zoneSet"]["zoneSetId"] not in (added, before)


async def test_a_robot_keeping_to_an_older_set_that_blocks_more_takes_no_order_meanwhile() -> None:
    """A BLOCKED zone lifted at run time is open to master control at once but still closed to
    a 3.0 robot until it enables the new set: meanwhile the robot is not available (it would
    refuse an order through the area, NO_ROUTE_TO_TARGET), saying why, and then it is again. A
    zone added instead makes master control the stricter one: the robot stays available."""
    service, _ = _robot([v3.ZoneType.BLOCKED, v3.ZoneType.SPEED_LIMIT])
    spill = GraphZone.model_validate(zone("spill", "BLOCKED", [[0.0, 3.0], [1.0, 3.0], [1.0, 5.0]]))
    await service.add_zone(spill)
    with_spill = service.zone_sets["demo"].zone_set_id
    enabled = make_state_v3(last_node_id="7", zone_sets=[_held(with_spill, Z.ENABLED)])
    service.ingest(_topic(Topic.STATE), encode(enabled))
    assert service.availability_of(AGV) is None

    await service.remove_zone("spill")
    lagging = service.availability_of(AGV)
    assert lagging is not None
    assert f"still keeps to zone set {with_spill!r}" in lagging
    current = service.zone_sets["demo"].zone_set_id
    caught_up = make_state_v3(
        last_node_id="7", zone_sets=[_held(with_spill, Z.DISABLED), _held(current, Z.ENABLED)]
    )
    service.ingest(_topic(Topic.STATE), encode(caught_up))
    assert service.availability_of(AGV) is None

    await service.add_zone(spill)  # the robot's set blocks less than master control's now
    assert service.availability_of(AGV) is None


@needs_official_schemas
def test_a_set_of_ours_for_a_map_without_zones_now_is_replaced_by_an_empty_one() -> None:
    """The graph file lost its zones before a restart; a robot still holding ours ENABLED would
    keep to them. It is sent an empty set for the map (the official schema takes it) and takes
    no order until it has enabled it; a set for a map this graph does not have is left alone."""
    publisher, clock = RecordingPublisher(), FakeClock()
    service = MasterService(MasterConfig.model_validate({}), demo_graph(), publisher, clock)
    service.ingest(_topic(Topic.CONNECTION), encode(make_connection_v3()))
    supported = [v3.ZoneType.BLOCKED, v3.ZoneType.SPEED_LIMIT]
    service.ingest(_topic(Topic.FACTSHEET), encode(make_factsheet_v3(supported_zones=supported)))
    older = "demo.zones.0123456789ab"
    elsewhere = _held("upstairs.zones.0123456789ab", Z.ENABLED, map_id="upstairs")
    holding = make_state_v3(last_node_id="7", zone_sets=[_held(older, Z.ENABLED), elsewhere])
    service.ingest(_topic(Topic.STATE), encode(holding))
    (sent,) = publisher.messages(Topic.ZONE_SET)
    assert not list(_official("zoneSet").iter_errors(sent))
    assert sent["zoneSet"]["mapId"] == "demo"
    assert sent["zoneSet"]["zones"] == []
    assert "still keeps to zone set" in (service.availability_of(AGV) or "")
    empty = sent["zoneSet"]["zoneSetId"]
    caught_up = make_state_v3(
        last_node_id="7", zone_sets=[_held(older, Z.DISABLED), _held(empty, Z.ENABLED), elsewhere]
    )
    service.ingest(_topic(Topic.STATE), encode(caught_up))
    assert service.availability_of(AGV) is None
