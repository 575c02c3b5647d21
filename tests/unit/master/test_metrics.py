"""``GET /metrics`` (docs/master.md, *Metrics*): the Prometheus text format, and what the service
counts as it happens."""

from __future__ import annotations

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import ActionStatus, Connection, ConnectionState
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.config import MasterConfig
from vda_master.metrics import (
    Histogram,
    Metric,
    order_origin,
    render,
)
from vda_master.monitoring import metrics_text
from vda_master.planner import Target
from vda_master.requests import OrderRequest
from vda_master.service import MasterService
from vda_master.testing import (
    RecordingPublisher,
    demo_graph,
    make_factsheet,
    parse_exposition,
    plan_state,
)

AGV = AgvId("acme", "robot_0")


def test_the_text_format_escapes_label_values_and_writes_histograms_cumulatively() -> None:
    histogram = Histogram((0.1, 1.0))
    for value in (0.05, 0.5, 0.7, 3.0):
        histogram.observe(value)
    text = render(
        [Metric("x_total", "counter", "a\\b\nc", [((("k", 'a"b\\c\nd'),), 2.5)])],
        {"lat_seconds": ("latency", histogram)},
    )
    assert text == (
        "# HELP x_total a\\\\b\\nc\n"
        "# TYPE x_total counter\n"
        'x_total{k="a\\"b\\\\c\\nd"} 2.5\n'
        "# HELP lat_seconds latency\n"
        "# TYPE lat_seconds histogram\n"
        'lat_seconds_bucket{le="0.1"} 1\n'
        'lat_seconds_bucket{le="1"} 3\n'
        'lat_seconds_bucket{le="+Inf"} 4\n'
        "lat_seconds_sum 4.25\n"
        "lat_seconds_count 4\n"
    )
    assert parse_exposition(text)['x_total{k="a\\"b\\\\c\\nd"}'] == 2.5


def test_an_order_is_counted_by_who_made_it() -> None:
    assert order_origin("") == "api"
    assert order_origin("traffic: in the way of acme/r2") == "traffic"
    assert order_origin("charging: battery 20 % is below charge_below_pct 30 %") == "charging"
    assert order_origin("something: else") == "api"


def _topic(kind: Topic) -> str:
    return build_topic("uagv", 2, AGV, kind)


def test_the_service_counts_messages_orders_and_resends() -> None:
    publisher, clock = RecordingPublisher(), FakeClock()
    config = MasterConfig.model_validate({"confirm_timeout_s": 1.0})
    service = MasterService(config, demo_graph(), publisher, clock)
    online = Connection.model_validate({**HEADER, "connection_state": ConnectionState.ONLINE})
    service.ingest(_topic(Topic.CONNECTION), encode(online))
    service.ingest(_topic(Topic.FACTSHEET), encode(make_factsheet()))
    service.ingest(_topic(Topic.STATE), encode(make_state(last_node_id="7")))
    service.ingest(_topic(Topic.STATE), b'{"headerId": "not a state"}')

    before = parse_exposition(metrics_text(service))
    assert before['vda_master_vehicles{connection="ONLINE"}'] == 1
    assert before["vda_master_vehicles_available"] == 1
    labels = '{manufacturer="acme",serial_number="robot_0"}'
    assert before[f"vda_master_vehicle_battery_percent{labels}"] == 80
    assert before[f"vda_master_vehicle_available{labels}"] == 1
    assert before['vda_master_messages_received_total{topic="state",major="2"}'] == 2
    assert before['vda_master_messages_dropped_total{topic="state"}'] == 1

    track = service.create_order(OrderRequest(Target(destination="10"), AGV))
    clock.advance(1.1)
    service.tick()  # unconfirmed: sent again
    plan = track.plan
    service.ingest(_topic(Topic.STATE), encode(plan_state(plan)))  # confirms it
    finished = dict.fromkeys(plan.action_ids(), ActionStatus.FINISHED)
    service.ingest(
        _topic(Topic.STATE), encode(plan_state(plan, passed=plan.last_index, actions=finished))
    )
    after = parse_exposition(metrics_text(service))
    assert after['vda_master_orders_created_total{origin="api"}'] == 1
    assert after['vda_master_orders_ended_total{status="FINISHED"}'] == 1
    assert after['vda_master_messages_published_total{topic="order"}'] == 2
    assert after['vda_master_messages_resent_total{topic="order"}'] == 1
    assert after["vda_master_order_confirm_seconds_count"] == 1
    assert after["vda_master_orders_active"] == 0
    assert after[f"vda_master_vehicle_available{labels}"] == 1
