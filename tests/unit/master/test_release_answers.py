"""A RELEASE zone through master control: the zone goes to 3.0 robots in their zone set, their
ACCESS requests are answered on ``responses`` as traffic control gives them the zone, and a
vehicle that cannot ask is kept out by its base alone (3.0 §6.4.1.1, §6.4.3, §6.9, §7.5;
T86, T91-T93; docs/master.md, Release zones)."""

from __future__ import annotations

import functools

import pytest
from jsonschema import Draft202012Validator, FormatChecker

from tests.spec_files import needs_official_schemas, official_schema
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.graph_file import GraphZone
from vda5050.models import v3
from vda5050.models.v3.state import RequestStatus, ZoneRequest, ZoneRequestType
from vda5050.testing import make_connection_v3, make_factsheet_v3, make_state, make_state_v3
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.api_documents import zones_document
from vda_master.config import MasterConfig
from vda_master.graph import Graph, build_graph
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.testing import RecordingPublisher, report_online, zone

ROBOT = AgvId("acme", "robot_3")  # 3.0
OTHER = AgvId("acme", "robot_0")  # 2.x (the test messages' own serial number)
ME: dict[str, object] = {"serial_number": ROBOT.serial_number}
#: A strip (x 3 … 13) over two lanes' ends 8 m apart: W0 → W1 → WN enters it at W1 and
#: leaves northwards, E2 → E1 → EN at E1. Without the zone the two routes never conflict.
STRIP = zone("door", "RELEASE", [[3.0, -1.0], [13.0, -1.0], [13.0, 1.0], [3.0, 1.0]])
POSITIONS = {"W0": (0, 0), "W1": (4, 0), "WN": (4, 4), "E2": (16, 0), "E1": (12, 0), "EN": (12, 4)}
SQUARE = [[20.0, 20.0], [22.0, 20.0], [22.0, 22.0]]
LANES = [("W0", "W1"), ("W1", "WN"), ("E2", "E1"), ("E1", "EN")]
SUPPORTED = [v3.ZoneType.BLOCKED, v3.ZoneType.SPEED_LIMIT, v3.ZoneType.RELEASE]


@functools.cache
def _official(kind: str) -> Draft202012Validator:
    return Draft202012Validator(official_schema("3.0.0", kind), format_checker=FormatChecker())


def _topic(agv: AgvId, kind: Topic) -> str:
    return build_topic("vda5050", 3, agv, kind)


def _service() -> tuple[MasterService, RecordingPublisher]:
    publisher, clock = RecordingPublisher(), FakeClock()
    config = MasterConfig.model_validate({"release_lease_s": 30})
    service = MasterService(config, _floor(), publisher, clock)
    service.ingest(
        _topic(ROBOT, Topic.CONNECTION),
        encode(make_connection_v3(serial_number=ROBOT.serial_number)),
    )
    factsheet = make_factsheet_v3(supported_zones=SUPPORTED, serial_number=ROBOT.serial_number)
    service.ingest(_topic(ROBOT, Topic.FACTSHEET), encode(factsheet))
    service.ingest(_topic(ROBOT, Topic.STATE), encode(make_state_v3(last_node_id="W0", **ME)))
    return service, publisher


def _floor() -> Graph:
    document = {
        "mapId": "demo",
        "nodes": [{"nodeId": n, "x": x, "y": y} for n, (x, y) in POSITIONS.items()],
        "edges": [{"edgeId": f"{a}-{b}", "startNodeId": a, "endNodeId": b} for a, b in LANES],
        "zones": [STRIP],
    }
    return build_graph(document, source="strip")


def _asking(service: MasterService, status: RequestStatus, **state: object) -> None:
    request = ZoneRequest(
        request_id="zr-1",
        request_type=ZoneRequestType.ACCESS,
        zone_id="door",
        zone_set_id=service.zone_sets["demo"].zone_set_id,
        request_status=status,
    )
    fields = {"last_node_id": "W0", **state, "zone_requests": [request]}
    service.ingest(_topic(ROBOT, Topic.STATE), encode(make_state_v3(**fields, **ME)))


@needs_official_schemas
def test_a_robot_is_queued_then_granted_once_its_base_is_released_into_the_zone() -> None:
    """The zone set carries the RELEASE zone (releaseLossBehavior STOP: Table 6's default,
    sent because §7.6 requires it). Asked with no order through the zone, master control
    answers QUEUED; once the robot's base is released through the zone, GRANTED with a
    leaseExpiry; GET /zones names the zone's vehicle and the robot's request."""
    service, publisher = _service()
    (sent,) = publisher.messages(Topic.ZONE_SET)
    assert not list(_official("zoneSet").iter_errors(sent))
    (door,) = sent["zoneSet"]["zones"]
    assert (door["zoneType"], door["releaseLossBehavior"]) == ("RELEASE", "STOP")

    _asking(service, RequestStatus.REQUESTED)
    (queued,) = publisher.messages(Topic.RESPONSES)
    assert not list(_official("responses").iter_errors(queued))
    assert queued["responses"] == [{"requestId": "zr-1", "grantType": "QUEUED"}]

    track = service.create_order(OrderRequest(Target(destination="WN"), ROBOT))
    assert [n.node_id for n in track.plan.nodes] == ["W0", "W1", "WN"]
    _asking(service, RequestStatus.REQUESTED, order_id=track.order_id)
    granted = publisher.messages(Topic.RESPONSES)[-1]
    assert not list(_official("responses").iter_errors(granted))
    (answer,) = granted["responses"]
    assert (answer["requestId"], answer["grantType"]) == ("zr-1", "GRANTED")
    assert answer["leaseExpiry"].endswith("Z")
    (document,) = zones_document(service.graph, service, service)
    assert document["heldBy"] == "acme/robot_3"
    assert document["requests"] == {"acme/robot_3": "REQUESTED"}
    assert document["robots"] == {"acme/robot_3": "SENT"}


def test_a_vehicle_that_cannot_ask_waits_outside_while_the_robot_has_the_zone() -> None:
    """A 2.x vehicle gets no zone set; its base stops short of the zone while another
    vehicle's base runs into it 8 m away, and goes through once that one is out."""
    service, _ = _service()
    service.create_order(OrderRequest(Target(destination="WN"), ROBOT))
    report_online(service, OTHER, "E2")
    track = service.create_order(OrderRequest(Target(destination="EN"), OTHER))
    assert [n.node_id for n in track.plan.nodes] == ["E2", "E1", "EN"]
    assert service.tracks[track.order_id].released_end == 0  # waits on node E2, outside
    waiting = make_state(order_id=track.order_id, last_node_id="E2", node_states=[])
    service.ingest(build_topic("uagv", 2, OTHER, Topic.STATE), encode(waiting))
    assert service.tracks[track.order_id].released_end == 0

    done = service.tracks[service.active[ROBOT]]
    finished = make_state_v3(
        order_id=done.order_id,
        last_node_id="WN",
        last_node_sequence_id=4,
        order_update_id=0,
        **ME,
    )
    service.ingest(_topic(ROBOT, Topic.STATE), encode(finished))
    assert service.tracks[track.order_id].released_end == 2  # through the zone and out
    (document,) = zones_document(service.graph, service, service)
    assert document["heldBy"] == "acme/robot_0"


def test_a_request_for_a_zone_that_is_not_a_release_zone_of_ours_is_rejected() -> None:
    """T92: a request master control cannot grant is REJECTED, not left unanswered."""
    service, publisher = _service()
    request = ZoneRequest(
        request_id="zr-9",
        request_type=ZoneRequestType.ACCESS,
        zone_id="door",
        zone_set_id="someone.elses.set",
        request_status=RequestStatus.REQUESTED,
    )
    state = make_state_v3(last_node_id="W0", zone_requests=[request], **ME)
    service.ingest(_topic(ROBOT, Topic.STATE), encode(state))
    (answer,) = publisher.messages(Topic.RESPONSES)[-1]["responses"]
    assert answer == {"requestId": "zr-9", "grantType": "REJECTED"}


async def test_a_release_zone_cannot_be_added_at_run_time() -> None:
    """RELEASE zones are traffic control's geometry, computed once per graph file: POST /zones
    answers 422 saying so, and nothing changes."""
    service, _ = _service()
    with pytest.raises(RequestError) as refused:
        await service.add_zone(GraphZone.model_validate(zone("gate", "RELEASE", SQUARE)))
    assert refused.value.status == 422
    assert "comes from the graph file only" in refused.value.message
    assert [z.zone_id for z in service.graph.zones] == ["door"]
