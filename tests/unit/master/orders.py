"""Orders for the store and recovery tests: a long order on a line graph, and its record as a
database gives it back."""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime

import orjson

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import Connection, ConnectionState
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderTrack
from vda_master.order_records import plan_document, to_record
from vda_master.planner import Target
from vda_master.requests import OrderRequest
from vda_master.service import MasterService
from vda_master.store import OrderRecord
from vda_master.testing import RecordingPublisher, line_graph

AGV = AgvId("acme", "robot_0")
T0 = datetime(2026, 11, 1, 8, 0, tzinfo=UTC)


def long_order(**config: object) -> OrderTrack:
    """A 12-node order on a line, released 3 nodes ahead (traffic control off: on a line of
    one-lane edges it would release the whole corridor), its first message published."""
    settings = MasterConfig.model_validate(
        {"release_window_nodes": 3, "traffic_control": False, **config}
    )
    service = MasterService(settings, line_graph(12), RecordingPublisher(), FakeClock())
    topic = build_topic("uagv", 2, AGV, Topic.CONNECTION)
    online = Connection.model_validate({**HEADER, "connection_state": ConnectionState.ONLINE})
    service.ingest(topic, encode(online))
    state = make_state(last_node_id="n0")
    service.ingest(build_topic("uagv", 2, AGV, Topic.STATE), encode(state))
    return service.create_order(OrderRequest(Target(destination="n11"), AGV))


def through_json(record: OrderRecord) -> OrderRecord:
    """The record as a database gives it back: every payload through JSON text."""
    return replace(
        record,
        request=orjson.loads(orjson.dumps(record.request)),
        plan=orjson.loads(orjson.dumps(record.plan)),
    )


def stored(track: OrderTrack) -> OrderRecord:
    """``track``'s record after a trip through the database."""
    return through_json(to_record(track, plan_document(track.plan), created=T0, updated=T0))
