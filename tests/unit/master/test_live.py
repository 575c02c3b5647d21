"""The live view: visualization poses parsed cheaply and a change feed that coalesces and
stays bounded for a slow reader."""

from __future__ import annotations

import orjson
from structlog.testing import capture_logs

from vda5050.codec import encode
from vda5050.models import AgvPosition, Visualization
from vda5050.testing import HEADER
from vda5050.topics import AgvId
from vda_master.live import LiveView, Pose, parse_pose

AGV = AgvId("acme", "robot_0")
OTHER = AgvId("acme", "robot_1")


def _visualization(x: float = 1.0, y: float = 2.0, theta: float = 0.5) -> bytes:
    position = AgvPosition(x=x, y=y, theta=theta, map_id="demo", position_initialized=True)
    return encode(Visualization.model_validate({**HEADER, "agv_position": position}))


def test_parse_pose_reads_the_agv_position_of_a_real_message() -> None:
    """x, y, theta and mapId come from the message, the time from the caller."""
    assert parse_pose(_visualization(), 7.0) == Pose(1.0, 2.0, 0.5, "demo", 7.0)


def test_parse_pose_names_what_is_missing() -> None:
    """Messages without a usable position are refused with a reason, never half-read."""
    assert parse_pose(b"{", 0.0) == "not JSON"
    assert parse_pose(orjson.dumps({"headerId": 1}), 0.0) == "no agvPosition"
    bad = {"agvPosition": {"x": "1", "y": 2, "theta": 0, "mapId": "m"}}
    assert "numeric" in str(parse_pose(orjson.dumps(bad), 0.0))
    huge = b'{"agvPosition": {"x": 1e999, "y": 2, "theta": 0, "mapId": "m"}}'
    assert isinstance(parse_pose(huge, 0.0), str)
    flag = {"agvPosition": {"x": True, "y": 2, "theta": 0, "mapId": "m"}}
    assert isinstance(parse_pose(orjson.dumps(flag), 0.0), str)


def test_a_bad_visualization_is_dropped_with_one_warning_per_vehicle() -> None:
    """The pose stays as it was and the log gets one line, not one per message."""
    live = LiveView()
    live.observe_visualization(AGV, _visualization(), 1.0)
    with capture_logs() as logs:
        live.observe_visualization(AGV, b"nonsense", 2.0)
        live.observe_visualization(AGV, b"nonsense", 3.0)
    assert live.poses[AGV].at == 1.0
    assert [e["event"] for e in logs] == ["message.dropped"]


def test_changes_coalesce_per_reader_until_drained() -> None:
    """Repeated changes of one vehicle are one entry; a pose of a vehicle that also changed as
    a whole is not sent twice; draining empties the reader."""
    live = LiveView(wall=lambda: 100.0)
    reader = live.subscribe()
    for _ in range(3):
        live.observe_visualization(AGV, _visualization(), 1.0)
    live.observe_visualization(OTHER, _visualization(), 1.0)
    live.vehicle_changed(AGV)
    live.order_changed("o1")
    assert reader.ready.is_set()
    changes = live.drain(reader)
    assert changes.vehicles == {AGV}
    assert changes.poses == {OTHER}
    assert changes.orders == {"o1"}
    assert live.received[AGV] == 100.0
    assert not reader.ready.is_set()
    assert live.drain(reader).vehicles == frozenset()


def test_every_reader_gets_every_change() -> None:
    """Two open pages each see the change; a page that left sees nothing more."""
    live = LiveView()
    first, second = live.subscribe(), live.subscribe()
    live.vehicle_changed(AGV)
    live.unsubscribe(second)
    live.vehicle_changed(OTHER)
    assert live.drain(first).vehicles == {AGV, OTHER}
    assert live.drain(second).vehicles == {AGV}
    assert live.readers == 1


def test_a_reader_that_falls_behind_is_told_to_resync_instead_of_growing() -> None:
    """Past max_pending keys the reader's sets are dropped and it gets a snapshot next."""
    live = LiveView(max_pending=10)
    reader = live.subscribe()
    for index in range(25):
        live.order_changed(f"o{index}")
    assert reader.pending <= 10
    changes = live.drain(reader)
    assert changes.resync
    assert not live.drain(reader).resync


def test_close_wakes_every_reader() -> None:
    """Stopping the master ends every open stream."""
    live = LiveView()
    reader = live.subscribe()
    live.close()
    assert reader.closed
    assert reader.ready.is_set()


def test_traffic_changes_are_flagged() -> None:
    """Traffic control's notification reaches the reader once."""
    live = LiveView()
    reader = live.subscribe()
    live.traffic_changed()
    assert live.drain(reader).traffic
    assert not live.drain(reader).traffic
