"""Property-based fuzzing of every inbound topic of both services, in-process (issue 14).

Whatever arrives (random bytes, valid messages with any part replaced by any JSON value, huge
arrays), the handler never raises, the service's memory stays bounded, and it still does its
job afterwards: the master still dispatches, the vehicle still reports and drives.
"""

from __future__ import annotations

import json

import orjson
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import Connection
from vda5050.testing import HEADER, make_action, make_instant_actions, make_order, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.config import MasterConfig
from vda_master.planner import Target
from vda_master.requests import OrderRequest
from vda_master.service import MasterService
from vda_master.testing import RecordingPublisher, demo_graph, make_factsheet
from vda_vehicle.faults import MAX_ERRORS
from vda_vehicle.testing import make_runtime

AGV = AgvId("acme", "robot_0")
ORDER_TOPIC = "uagv/v2/acme/robot_0/order"
INSTANT_TOPIC = "uagv/v2/acme/robot_0/instantActions"
json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**70), max_value=2**70)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4)
    ),
    max_leaves=12,
)
SEEDS = {
    Topic.STATE: json.loads(encode(make_state(last_node_id="7"))),
    Topic.CONNECTION: json.loads(
        encode(Connection.model_validate({**HEADER, "connection_state": "ONLINE"}))
    ),
    Topic.FACTSHEET: json.loads(encode(make_factsheet())),
    Topic.ORDER: json.loads(encode(make_order(["a", "b", "c"], released=2))),
    Topic.INSTANT_ACTIONS: json.loads(encode(make_instant_actions())),
}


def _paths(value: object, prefix: tuple[object, ...] = ()) -> list[tuple[object, ...]]:
    found = [prefix]
    if isinstance(value, dict):
        for key, item in value.items():
            found += _paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            found += _paths(item, (*prefix, index))
    return found


def _replace(value: object, path: tuple[object, ...], new: object) -> object:
    if not path:
        return new
    head, rest = path[0], path[1:]
    if isinstance(value, dict):
        return {**value, head: _replace(value[head], rest, new)}
    if isinstance(value, list) and isinstance(head, int):
        copy = list(value)
        copy[head] = _replace(copy[head], rest, new)
        return copy
    return value


@st.composite
def hostile(draw: st.DrawFn, topic: Topic) -> bytes:
    """Random bytes, a mutated valid message, or a valid message with a huge array."""
    kind = draw(st.sampled_from(["bytes", "mutated", "huge"]))
    if kind == "bytes":
        return draw(st.binary(max_size=200))
    seed = SEEDS[topic]
    if kind == "huge":
        arrays = [p for p in _paths(seed) if isinstance(_get(seed, p), list)]
        path = draw(st.sampled_from(arrays)) if arrays else ()
        item = draw(json_values)
        return json.dumps(_replace(seed, path, [item] * 1000), allow_nan=True).encode()
    path = draw(st.sampled_from(_paths(seed)))
    return json.dumps(_replace(seed, path, draw(json_values)), allow_nan=True).encode()


def _get(value: object, path: tuple[object, ...]) -> object:
    for part in path:
        value = value[part]  # type: ignore[index]
    return value


def _master() -> MasterService:
    service = MasterService(MasterConfig(), demo_graph(), RecordingPublisher(), FakeClock())
    service.ingest(
        build_topic("uagv", 2, AGV, Topic.CONNECTION), orjson.dumps(SEEDS[Topic.CONNECTION])
    )
    return service


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_master_survives_any_inbound_message(data: st.DataObject) -> None:
    """Any state, connection or factsheet payload leaves the master working: it never raises,
    holds one view per vehicle, and still dispatches an order afterwards."""
    service = _master()
    for _ in range(5):
        topic = data.draw(st.sampled_from([Topic.STATE, Topic.CONNECTION, Topic.FACTSHEET]))
        service.ingest(build_topic("uagv", 2, AGV, topic), data.draw(hostile(topic)))
    assert len(service.fleet) == 1
    service.ingest(
        build_topic("uagv", 2, AGV, Topic.CONNECTION), orjson.dumps(SEEDS[Topic.CONNECTION])
    )
    service.ingest(build_topic("uagv", 2, AGV, Topic.STATE), orjson.dumps(SEEDS[Topic.STATE]))
    track = service.create_order(OrderRequest(Target(destination="10"), AGV))
    assert service.active[AGV] == track.order_id


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_vehicle_survives_any_inbound_message(data: st.DataObject) -> None:
    """Any order or instantActions payload leaves the vehicle working: it never raises, its
    errors and action states stay bounded, and afterwards it cancels what it may have accepted
    and drives a valid order to its end."""
    clock = FakeClock()
    vehicle, recorder = make_runtime(clock, stop_between_nodes=True)

    def tick(times: int = 1) -> None:
        for _ in range(times):
            clock.advance(0.2)
            vehicle.tick(0.2, clock.monotonic())

    for _ in range(5):
        topic = data.draw(st.sampled_from([Topic.ORDER, Topic.INSTANT_ACTIONS]))
        payload = data.draw(hostile(topic))
        if topic is Topic.ORDER:
            vehicle.handle_order(ORDER_TOPIC, payload)
        else:
            vehicle.handle_instant_actions(INSTANT_TOPIC, payload)
        tick()
    assert len(vehicle.state.errors) <= MAX_ERRORS
    assert len(vehicle.state.actions) <= 2 * vehicle._caps.limits.instant_actions + 100
    assert recorder.of(Topic.STATE)
    cancel = make_instant_actions(make_action("cancelOrder", "after-fuzz-cancel"))
    vehicle.handle_instant_actions(INSTANT_TOPIC, encode(cancel))
    tick(5)
    here = vehicle.state.pose
    order = make_order(
        ["s", "t"],
        order_id="after-fuzz",
        positions=[(here.x, here.y), (here.x + 1.0, here.y)],
        map_id=here.map_id,
    )
    vehicle.handle_order(ORDER_TOPIC, encode(order))
    assert vehicle.state.order_id == "after-fuzz", vehicle.state.errors[-1:]
    tick(20)
    assert vehicle.state.last_node_id == "t"
