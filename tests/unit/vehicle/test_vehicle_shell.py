"""The shell's synchronous parts without a broker: settings, placement, inbound handling."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest

from vda5050.cli import flag_name, known_flags
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.config import load_settings
from vda5050.errors import ConfigError
from vda5050.graph_file import GraphFile
from vda5050.testing import make_order
from vda5050.topics import Topic
from vda_vehicle.__main__ import parser, settings_from
from vda_vehicle.config import VehicleSettings, capabilities, placements, serial_numbers
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.service import DeferredStates
from vda_vehicle.testing import Recorder, make_runtime

GRAPH = GraphFile.model_validate(
    {
        "mapId": "map",
        "nodes": [{"nodeId": n, "x": 10.0 * i, "y": 0.0} for i, n in enumerate("abc")],
        "edges": [],
    }
)


def runtime(clock: FakeClock | None = None) -> tuple[VehicleRuntime, Recorder]:
    return make_runtime(clock or FakeClock())


def test_settings_precedence_flag_env_file_default(tmp_path: Path) -> None:
    """Architecture §3.2: flag > VDA_<FLAG> > config file > default, for every flag."""
    config = tmp_path / "vehicle.yaml"
    config.write_text("serial_number: from-file\ncount: 2\ntime_lapse: 3\n", encoding="utf-8")
    environ = {"VDA_CONFIG": str(config), "VDA_COUNT": "4", "VDA_INTERFACE_NAME": "env"}
    settings = settings_from(["--interface-name", "flag"], environ)
    assert (settings.serial_number, settings.count, settings.interface_name) == (
        "from-file",
        4,
        "flag",
    )
    assert settings.time_lapse == 3.0
    assert settings.broker_url == "mqtt://127.0.0.1:1883"


def test_example_config_loads() -> None:
    """The shipped config/vehicle.yaml is valid."""
    path = Path(__file__).resolve().parents[3] / "config" / "vehicle.yaml"
    assert load_settings(VehicleSettings, config_path=path, environ={}).keepalive_s == 15


def test_unknown_config_key_fails_fast(tmp_path: Path) -> None:
    """House style §3.8: a typo in the config file fails at start-up."""
    config = tmp_path / "vehicle.yaml"
    config.write_text("speed: 3\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="speed"):
        load_settings(VehicleSettings, config_path=config, environ={})


def test_count_gives_serials_and_distinct_start_nodes() -> None:
    """--count N: serials <S>-1..<S>-N on distinct nodes from the start node on."""
    settings = VehicleSettings(serial_number="r", count=3, start_node="b")
    assert serial_numbers(settings) == ["r-1", "r-2", "r-3"]
    assert [p.last_node_id for p in placements(settings, GRAPH)] == ["b", "c", "a"]
    assert serial_numbers(VehicleSettings(serial_number="r")) == ["r"]
    with pytest.raises(ConfigError, match="start node"):
        placements(VehicleSettings(start_node="zz"), GRAPH)


def test_more_vehicles_than_nodes_is_refused_with_the_reason() -> None:
    """--count beyond the graph's nodes would stack vehicles on one node: refused, saying why."""
    with pytest.raises(ConfigError, match=r"--count 4 needs 4 distinct nodes .* has 3"):
        placements(VehicleSettings(serial_number="r", count=4), GRAPH)


def test_map_id_places_a_vehicle_without_graph() -> None:
    """--map-id: the map a vehicle without a graph stands on (issue 8); the vehicle holds it."""
    settings = VehicleSettings(map_id="hall-3", count=2)
    assert {p.pose.map_id for p in placements(settings, None)} == {"hall-3"}
    assert capabilities(settings, None).map_ids == {"hall-3"}
    with pytest.raises(ConfigError, match="does not match the graph's mapId"):
        capabilities(VehicleSettings(map_id="hall-3"), GRAPH)


def test_every_setting_is_a_flag() -> None:
    """The command line is generated from the settings: every key is a flag (issue 8)."""
    flags = set(known_flags(parser()))
    assert {flag_name(key) for key in VehicleSettings.model_fields} <= flags
    args = vars(parser().parse_args(["--map-id", "m2", "--stop-between-nodes", "--count", "2"]))
    assert (args["map_id"], args["stop_between_nodes"], args["count"]) == ("m2", True, 2)


def test_connect_publishes_online_factsheet_and_state() -> None:
    """R09: after (re)connect ONLINE, the factsheet and a state are queued."""
    vehicle, sent = runtime()
    vehicle.on_connected()
    assert [kind for _, kind, _ in sent.sent] == [Topic.CONNECTION, Topic.FACTSHEET, Topic.STATE]
    assert sent.of(Topic.CONNECTION)[0]["connectionState"] == "ONLINE"
    assert json.loads(vehicle.will().payload)["connectionState"] == "CONNECTIONBROKEN"


def test_bad_order_payload_becomes_validation_error() -> None:
    """Issue item 7, R27: a payload that is not JSON is a validationError WARNING in state."""
    vehicle, sent = runtime()
    vehicle.handle_order("uagv/v2/acme/robot_0/order", b"\xff not json")
    (state,) = sent.of(Topic.STATE)
    errors = state["errors"]
    assert isinstance(errors, list)
    (error,) = errors
    assert error["errorType"] == "validationError"
    assert error["errorLevel"] == "WARNING"
    assert {"referenceKey": "topic", "referenceValue": "order"} in error["errorReferences"]


def test_order_for_another_vehicle_is_rejected_and_running_order_goes_on() -> None:
    """R18, issue item 7: a header naming another vehicle is refused; the order goes on."""
    clock = FakeClock()
    vehicle, sent = runtime(clock)
    topic = "uagv/v2/acme/robot_0/order"
    vehicle.handle_order(topic, encode(make_order(["a", "b"])))
    vehicle.handle_order(topic, encode(make_order(["a"], order_id="x", serial_number="other")))
    vehicle.handle_order(topic, encode(make_order(["a"], order_id="y", version="3.0.0")))
    clock.advance(0.2)  # R94: the rejections share the next tick's state
    vehicle.tick(0.2, clock.monotonic())
    last = sent.of(Topic.STATE)[-1]
    assert last["orderId"] == "order-1"
    assert [e["errorType"] for e in last["errors"]] == ["validationError"] * 2  # type: ignore[attr-defined]


def test_heartbeat_state_every_interval() -> None:
    """R92: without events a state goes out at least every state_interval_s."""
    clock = FakeClock()
    vehicle, sent = runtime(clock)
    vehicle.tick(0.2, clock.monotonic())
    first = len(sent.of(Topic.STATE))
    clock.advance(29.0)
    vehicle.tick(0.2, clock.monotonic())
    assert len(sent.of(Topic.STATE)) == first
    clock.advance(1.5)
    vehicle.tick(0.2, clock.monotonic())
    assert len(sent.of(Topic.STATE)) == first + 1


def test_visualization_rate_and_factsheet_request() -> None:
    """R109, R80: visualization at its interval; factsheetRequest republishes the factsheet."""
    clock = FakeClock()
    vehicle, sent = runtime(clock)
    for _ in range(10):
        clock.advance(0.2)
        vehicle.tick(0.2, clock.monotonic())
    assert len(sent.of(Topic.VISUALIZATION)) == 2
    actions = {
        "headerId": 1, "timestamp": "2026-01-01T00:00:00.000Z", "version": "2.1.0",
        "manufacturer": "acme", "serialNumber": "robot_0",
        "actions": [{"actionType": "factsheetRequest", "actionId": "f", "blockingType": "NONE"}],
    }  # fmt: skip
    vehicle.handle_instant_actions(
        "uagv/v2/acme/robot_0/instantActions", json.dumps(actions).encode()
    )
    assert len(sent.of(Topic.FACTSHEET)) == 1
    assert sent.of(Topic.STATE)[-1]["actionStates"] == [
        {"actionId": "f", "actionType": "factsheetRequest", "actionStatus": "FINISHED"}
    ]


def test_visualizations_follow_the_vehicle_after_standing() -> None:
    """R109: every visualization has a fresh header and the pose of the moment, also when the
    body of a standing vehicle is reused: after an order moved it, the new pose is sent."""
    clock = FakeClock()
    vehicle, sent = make_runtime(clock, speed_max_mps=2.0)
    for _ in range(10):  # 2 s standing at (0, 0): two visualizations
        clock.advance(0.2)
        vehicle.tick(0.2, clock.monotonic())
    order = make_order(["a", "b"], positions=[(0.0, 0.0), (10.0, 0.0)])
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order))
    for _ in range(5):  # 1 s driving at 2 m/s
        clock.advance(0.2)
        vehicle.tick(0.2, clock.monotonic())
    poses = [v["agvPosition"] for v in sent.of(Topic.VISUALIZATION)]
    ids = [v["headerId"] for v in sent.of(Topic.VISUALIZATION)]
    assert ids == list(range(len(ids)))
    assert poses[0] == poses[1]
    assert poses[1]["x"] == 0.0  # type: ignore[index]
    assert poses[-1]["x"] == pytest.approx(2.0)  # type: ignore[index]


def test_states_are_never_closer_than_min_state_interval() -> None:
    """R94: an order arriving right after a state is answered on the next tick, in one message
    with everything that changed meanwhile, never sooner than minStateInterval."""
    clock = FakeClock()
    vehicle, recorder = runtime(clock)
    vehicle.publish_state()
    clock.advance(0.01)
    order = make_order(["a", "b"], manufacturer="acme", serial_number="robot_0", released=2)
    vehicle.handle_order("uagv/v2/acme/robot_0/order", encode(order))
    assert len(recorder.of(Topic.STATE)) == 1, "the acceptance state must wait"
    clock.advance(0.2)
    vehicle.tick(0.2, clock.monotonic())
    states = recorder.of(Topic.STATE)
    assert len(states) == 2
    assert states[1]["orderId"] == "order-1"
    factsheet = vehicle_factsheet(vehicle, recorder)
    assert factsheet["protocolLimits"]["timing"]["minStateInterval"] == 0.1  # type: ignore[index]


async def test_a_deferred_state_goes_out_when_min_state_interval_has_passed() -> None:
    """R94 with the shell's timer: the acceptance state of an order that came 10 ms after a
    state goes out once minStateInterval (0.1 s) has passed, with no tick in between; before
    that, nothing."""
    clock = FakeClock()
    vehicle, recorder = runtime(clock)
    deferred = DeferredStates(clock)
    vehicle.publish_state()
    clock.advance(0.01)
    order = make_order(["a", "b"], manufacturer="acme", serial_number="robot_0", released=2)
    vehicle.handle_order("uagv/v2/acme/robot_0/order", encode(order))
    deferred.schedule(vehicle)
    deferred.schedule(vehicle)  # one timer per vehicle however many messages
    await asyncio.sleep(0.03)
    assert len(recorder.of(Topic.STATE)) == 1
    clock.advance(0.09)
    await asyncio.sleep(0.1)
    states = recorder.of(Topic.STATE)
    assert [s["orderId"] for s in states[1:]] == ["order-1"]
    assert vehicle.deferred_state_due() is None


def vehicle_factsheet(vehicle: VehicleRuntime, recorder: Recorder) -> dict[str, object]:
    vehicle.publish_factsheet()
    return recorder.of(Topic.FACTSHEET)[-1]


def test_a_vehicle_set_going_between_ticks_drives_only_from_the_message_on() -> None:
    """The tick after an order reaches a standing vehicle simulates only the time since the
    order, not the part of the tick period before it (a simulated vehicle never drives ahead
    of its orders: a 0.2 s tick with the order after 0.15 s moves it 0.05 s worth)."""
    clock = FakeClock()
    vehicle, _ = make_runtime(clock, speed_max_mps=2.0)
    vehicle.tick(0.2, clock.monotonic())
    clock.advance(0.15)
    order = make_order(["a", "b"], positions=[(0.0, 0.0), (10.0, 0.0)])
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order))
    clock.advance(0.05)
    vehicle.tick(0.2, clock.monotonic())
    assert vehicle.state.pose.x == pytest.approx(0.1)  # 2 m/s for 0.05 s
    clock.advance(0.2)
    vehicle.tick(0.2, clock.monotonic())  # once going, every tick is a whole one
    assert vehicle.state.pose.x == pytest.approx(0.5)


def test_the_state_acknowledging_an_order_already_shows_the_vehicle_under_way() -> None:
    """R93, R94, R100 (§6.10): the order's state follows at once, and it says what the vehicle
    does from then on (driving, on the first edge), so no second state follows one tick later
    only to say that it started; the vehicle has not moved yet."""
    clock = FakeClock()
    vehicle, sent = make_runtime(clock, speed_max_mps=2.0)
    order = make_order(["a", "b"], positions=[(0.0, 0.0), (10.0, 0.0)])
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order))
    (acknowledging,) = sent.of(Topic.STATE)
    assert acknowledging["orderId"] == "order-1"
    assert acknowledging["driving"] is True
    assert acknowledging["agvPosition"]["x"] == 0.0  # type: ignore[index]
    for _ in range(5):
        clock.advance(0.2)
        vehicle.tick(0.2, clock.monotonic())
    assert len(sent.of(Topic.STATE)) == 1  # cruising on the edge: nothing new to say
    assert vehicle.state.pose.x == pytest.approx(2.0)


def test_a_message_to_a_driving_vehicle_does_not_shorten_its_tick() -> None:
    """Only a vehicle that stood with nothing under way loses the time before the message:
    one already driving keeps driving through the whole tick."""
    clock = FakeClock()
    vehicle, _ = make_runtime(clock, speed_max_mps=2.0)
    order = make_order(["a", "b", "c"], positions=[(0.0, 0.0), (10.0, 0.0), (20.0, 0.0)])
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(order))
    vehicle.tick(0.2, clock.monotonic())
    clock.advance(0.2)
    vehicle.tick(0.2, clock.monotonic())
    assert vehicle.state.driving
    x = vehicle.state.pose.x
    clock.advance(0.15)
    update = make_order(
        ["a", "b", "c"], order_update_id=1, positions=[(0.0, 0.0), (10.0, 0.0), (20.0, 0.0)]
    )
    vehicle.handle_order(vehicle.topics[Topic.ORDER], encode(update))
    clock.advance(0.05)
    vehicle.tick(0.2, clock.monotonic())
    assert vehicle.state.pose.x == pytest.approx(x + 0.4)
