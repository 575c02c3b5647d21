"""Map distribution on the vehicle (§6.7, 2.1 and 3.0; R35, R87-R91): downloadMap from a map
server, enableMap, deleteMap, and what the state and the factsheet say about them."""

from __future__ import annotations

import asyncio
import functools
import hashlib
from collections.abc import Iterator
from typing import Any

import pytest
from jsonschema import Draft202012Validator, FormatChecker

from tests.map_server import serving_map
from tests.spec_files import needs_official_schemas, official_schema
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import Action, ActionStatus
from vda5050.testing import make_instant_action_v3, make_instant_actions_v3, make_order
from vda5050.topics import Topic
from vda_vehicle.action_catalog import MAP_ACTIONS, default_catalog, for_version
from vda_vehicle.instant import receive_instant_actions
from vda_vehicle.map_download import fetch_map
from vda_vehicle.maps import (
    DownloadRequest,
    download_finished,
    download_request,
    enabled_map_ids,
)
from vda_vehicle.model import HeldMap, VehicleState
from vda_vehicle.order_executor import Accept, Reject, decide_order
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.testing import (
    Recorder,
    instant,
    make_caps,
    make_runtime,
    make_runtime_v3,
    make_vehicle,
    run,
)

CAPS = make_caps()
S = ActionStatus
MAP_FILE = b'{"mapId": "map", "nodes": []}' * 10
Json = dict[str, Any]


def map_action(kind: str, action_id: str, version: str = "2", **extra: str) -> Action:
    parameters = {"mapId": "map", "mapVersion": version, **extra}
    return Action.model_validate(
        {
            "actionType": kind,
            "actionId": action_id,
            "blockingType": "NONE",
            "actionParameters": [{"key": k, "value": v} for k, v in parameters.items()],
        }
    )


def received(state: VehicleState, *actions: Action) -> VehicleState:
    return run(receive_instant_actions(state, instant(*actions), CAPS), CAPS, 0.1)


def statuses(state: VehicleState) -> dict[str, ActionStatus]:
    return {r.action_id: r.status for r in state.actions}


def with_version_2(state: VehicleState, *, enabled: bool = False) -> VehicleState:
    """``state`` after a successful download of map version 2 (and enableMap if asked)."""
    action = map_action("downloadMap", "dl", mapDownloadLink="http://maps.example/map-2")
    state = download_finished(received(state, action), "dl", None)
    return received(state, map_action("enableMap", "en")) if enabled else state


# -- the core ------------------------------------------------------------------------------------


def test_a_vehicle_starts_with_its_graph_maps_enabled() -> None:
    """§6.7.2: one map per mapId, version 1, ENABLED; orders may use exactly those (R35)."""
    state = make_vehicle()
    assert state.maps == (HeldMap("map", "1", enabled=True),)
    assert enabled_map_ids(state) == {"map"}


def test_a_downloaded_map_is_added_disabled_once_ready() -> None:
    """R88: RUNNING while the file is fetched and not in ``maps`` yet; then added DISABLED,
    the action FINISHED, version 1 untouched."""
    action = map_action("downloadMap", "dl", mapDownloadLink="http://maps.example/map-2")
    state = received(make_vehicle(), action)
    assert statuses(state)["dl"] is S.RUNNING
    assert [m.map_version for m in state.maps] == ["1"]
    done = download_finished(state, "dl", None)
    assert statuses(done)["dl"] is S.FINISHED
    assert done.maps == (HeldMap("map", "1", enabled=True), HeldMap("map", "2", enabled=False))
    assert done.revision > state.revision


def test_a_map_already_held_is_not_downloaded_again() -> None:
    """R87: downloadMap of a mapId and mapVersion already on the vehicle FAILS with an error,
    and the maps stay as they were."""
    state = received(
        make_vehicle(), map_action("downloadMap", "dl", "1", mapDownloadLink="http://x/m")
    )
    problem = download_request(state, "dl")
    assert problem == "map 'map' version '1' is already on the vehicle"
    failed = download_finished(state, "dl", problem if isinstance(problem, str) else None)
    assert statuses(failed)["dl"] is S.FAILED
    assert failed.maps == state.maps
    assert failed.errors[-1].error_description == problem
    assert failed.errors[-1].error_type == "duplicateMap"


def test_a_failed_download_changes_no_map() -> None:
    """A download that fails (server unreachable, wrong hash) FAILS with the reason."""
    state = received(make_vehicle(), map_action("downloadMap", "dl", mapDownloadLink="http://x/m"))
    failed = download_finished(state, "dl", "the map server answered 404 for http://x/m")
    assert statuses(failed)["dl"] is S.FAILED
    assert failed.maps == state.maps
    assert "404" in (failed.errors[-1].error_description or "")


def test_only_http_links_are_fetched() -> None:
    """The vehicle fetches http:// and https:// addresses only."""
    state = received(
        make_vehicle(), map_action("downloadMap", "dl", mapDownloadLink="file:///etc/passwd")
    )
    assert isinstance(download_request(state, "dl"), str)
    state = received(make_vehicle(), map_action("downloadMap", "ok", mapDownloadLink="https://x/m"))
    assert download_request(state, "ok") == DownloadRequest("ok", "map", "2", "https://x/m", None)


def test_enable_map_enables_one_version_of_a_map_id() -> None:
    """R89: the requested version ENABLED, every other version of its mapId DISABLED; orders
    may use the map as before."""
    state = with_version_2(make_vehicle(), enabled=True)
    assert statuses(state)["en"] is S.FINISHED
    assert state.maps == (HeldMap("map", "1", enabled=False), HeldMap("map", "2", enabled=True))
    back = received(state, map_action("enableMap", "en1", "1"))
    assert back.maps == (HeldMap("map", "1", enabled=True), HeldMap("map", "2", enabled=False))
    assert isinstance(decide_order(back, make_order(["a"]), CAPS), Accept)


def test_enable_or_delete_of_a_map_not_held_fails() -> None:
    """R90: enableMap or deleteMap of an unknown pair FAIL with an error; nothing changes."""
    state = make_vehicle()
    for kind in ("enableMap", "deleteMap"):
        after = received(state, map_action(kind, "x", "7"))
        assert statuses(after)["x"] is S.FAILED
        assert after.maps == state.maps
        assert after.errors[-1].error_description == "map 'map' version '7' is not on the vehicle"


def test_delete_map_removes_it_but_not_the_map_in_use() -> None:
    """R91: a DISABLED version is removed from ``maps``; R90: the ENABLED map the vehicle
    stands on is in use and is not; deleting a removed one again FAILS."""
    state = with_version_2(make_vehicle())
    in_use = received(state, map_action("deleteMap", "d1", "1"))
    assert statuses(in_use)["d1"] is S.FAILED
    assert "in use" in (in_use.errors[-1].error_description or "")
    deleted = received(state, map_action("deleteMap", "d2", "2"))
    assert statuses(deleted)["d2"] is S.FINISHED
    assert deleted.maps == (HeldMap("map", "1", enabled=True),)
    again = received(deleted, map_action("deleteMap", "d3", "2"))
    assert statuses(again)["d3"] is S.FAILED


def test_orders_use_enabled_maps_only() -> None:
    """R35: with no ENABLED version of a mapId, an order on it is rejected."""
    caps = make_caps(map_ids=frozenset({"map", "hall"}))
    state = make_vehicle(
        maps=(HeldMap("map", "1", enabled=True), HeldMap("hall", "1", enabled=False))
    )
    assert isinstance(decide_order(state, make_order(["a"], map_id="hall"), caps), Reject)


def test_a_2_0_vehicle_offers_no_map_actions() -> None:
    """2.0 has no maps: its factsheet declares none of the three actions; 2.1 and 3.0 do."""
    assert not MAP_ACTIONS & set(for_version(default_catalog(), "2.0.0"))
    assert set(for_version(default_catalog(), "2.1.0")) >= MAP_ACTIONS


# -- the download, against a map server --------------------------------------------------------


@pytest.fixture
def map_server() -> Iterator[str]:
    """A map server on a free port: ``/maps/map-2`` is the map file, everything else 404."""
    with serving_map("/maps/map-2", MAP_FILE) as url:
        yield f"{url}/maps"


def _request(link: str, map_hash: str | None = None) -> DownloadRequest:
    return DownloadRequest("dl", "map", "2", link, map_hash)


async def test_fetch_checks_the_hash_and_the_server_answer(map_server: str) -> None:
    """The file is fetched whole; a SHA-256 (or SHA-1, MD5) mapHash must match; a 404, an
    unreachable server, a file over the size limit and an unknown hash kind are reasons."""
    link = f"{map_server}/map-2"
    assert await fetch_map(_request(link)) is None
    assert await fetch_map(_request(link, hashlib.sha256(MAP_FILE).hexdigest())) is None
    assert await fetch_map(_request(link, hashlib.md5(MAP_FILE).hexdigest().upper())) is None  # noqa: S324
    wrong = await fetch_map(_request(link, "0" * 64))
    assert wrong is not None
    assert "does not match mapHash" in wrong
    missing = await fetch_map(_request(f"{map_server}/map-9"))
    assert missing == f"the map server answered 404 for {map_server}/map-9"
    assert "larger than 10 bytes" in (await fetch_map(_request(link), max_bytes=10) or "")
    assert "not a hex SHA-256" in (await fetch_map(_request(link, "abc")) or "")
    refused = await fetch_map(_request("http://127.0.0.1:9/nothing"))
    assert refused is not None
    assert refused.startswith("cannot download http://127.0.0.1:9/")


def _send(runtime: VehicleRuntime, topic: str, *actions: Action) -> None:
    runtime.handle_instant_actions(topic, encode(instant(*actions)))


async def _until_ended(runtime: VehicleRuntime, action_id: str) -> None:
    async with asyncio.timeout(5):
        while True:
            record = next((r for r in runtime.state.actions if r.action_id == action_id), None)
            if record is not None and record.terminal:
                return
            await asyncio.sleep(0.01)


@functools.cache
def _schema(version: str, topic: str) -> Draft202012Validator:
    return Draft202012Validator(official_schema(version, topic), format_checker=FormatChecker())


def _maps(sent: Recorder) -> list[Json]:
    maps: list[Json] = sent.of(Topic.STATE)[-1]["maps"]  # type: ignore[assignment]
    return maps


@needs_official_schemas
async def test_download_enable_delete_end_to_end_on_a_2_1_vehicle(map_server: str) -> None:
    """The whole distribution (Figure 13) on the runtime: download (DISABLED), enable (the
    other version DISABLED), delete the old one; every state and the factsheet fit the
    official 2.1 schemas."""
    clock = FakeClock()
    runtime, sent = make_runtime(clock)
    runtime.on_connected()
    topic = "uagv/v2/acme/robot_0/instantActions"
    digest = hashlib.sha256(MAP_FILE).hexdigest()
    _send(
        runtime,
        topic,
        map_action("downloadMap", "dl", mapDownloadLink=f"{map_server}/map-2", mapHash=digest),
    )
    await _until_ended(runtime, "dl")
    clock.advance(1.0)
    runtime.tick(1.0, clock.monotonic())
    assert _maps(sent) == [
        {"mapId": "map", "mapVersion": "1", "mapStatus": "ENABLED"},
        {"mapId": "map", "mapVersion": "2", "mapStatus": "DISABLED"},
    ]
    _send(runtime, topic, map_action("enableMap", "en"))
    clock.advance(1.0)
    runtime.tick(1.0, clock.monotonic())
    _send(runtime, topic, map_action("deleteMap", "del", "1"))
    clock.advance(1.0)
    runtime.tick(1.0, clock.monotonic())
    assert _maps(sent) == [{"mapId": "map", "mapVersion": "2", "mapStatus": "ENABLED"}]
    last = sent.of(Topic.STATE)[-1]
    done = {a["actionId"]: a["actionStatus"] for a in last["actionStates"]}  # type: ignore[attr-defined]
    assert done == {"dl": "FINISHED", "en": "FINISHED", "del": "FINISHED"}
    for kind in (Topic.STATE, Topic.FACTSHEET):
        for message in sent.of(kind):
            assert not list(_schema("2.1.0", kind.value).iter_errors(message))
    (factsheet,) = sent.of(Topic.FACTSHEET)
    declared = {a["actionType"] for a in factsheet["protocolFeatures"]["agvActions"]}  # type: ignore[index]
    assert declared >= MAP_ACTIONS
    assert isinstance(decide_order(runtime.state, make_order(["a"]), CAPS), Accept)


async def test_a_download_from_a_missing_file_fails_and_says_why(map_server: str) -> None:
    """A 404 ends downloadMap FAILED with a WARNING naming the answer; maps unchanged."""
    clock = FakeClock()
    runtime, sent = make_runtime(clock)
    topic = "uagv/v2/acme/robot_0/instantActions"
    _send(runtime, topic, map_action("downloadMap", "dl", mapDownloadLink=f"{map_server}/nope"))
    await _until_ended(runtime, "dl")
    clock.advance(1.0)
    runtime.tick(1.0, clock.monotonic())
    state = sent.of(Topic.STATE)[-1]
    assert state["maps"] == [{"mapId": "map", "mapVersion": "1", "mapStatus": "ENABLED"}]
    errors: list[Json] = state["errors"]  # type: ignore[assignment]
    expected = f"the map server answered 404 for {map_server}/nope"
    assert [e["errorDescription"] for e in errors] == [expected]


@needs_official_schemas
async def test_a_3_0_vehicle_downloads_and_enables_a_map(map_server: str) -> None:
    """3.0 §6.3 (T97, T98; the same three actions): the state reports the new version
    DISABLED, then ENABLED with version 1 DISABLED; a second download of it FAILS with
    DUPLICATE_MAP (WARNING); states and factsheet fit the official 3.0.0 schemas."""
    clock = FakeClock()
    runtime, sent = make_runtime_v3(clock)
    runtime.on_connected()
    topic = "vda5050/v3/acme/robot_0/instantActions"
    link = f"{map_server}/map-2"
    download = make_instant_action_v3(
        "downloadMap", "dl", mapId="map", mapVersion="2", mapDownloadLink=link
    )
    runtime.handle_instant_actions(topic, encode(make_instant_actions_v3(download)))
    await _until_ended(runtime, "dl")
    clock.advance(1.0)
    runtime.tick(1.0, clock.monotonic())
    assert _maps(sent)[-1] == {"mapId": "map", "mapVersion": "2", "mapStatus": "DISABLED"}
    enable = make_instant_action_v3("enableMap", "en", mapId="map", mapVersion="2")
    runtime.handle_instant_actions(topic, encode(make_instant_actions_v3(enable)))
    clock.advance(1.0)
    runtime.tick(1.0, clock.monotonic())
    assert _maps(sent) == [
        {"mapId": "map", "mapVersion": "1", "mapStatus": "DISABLED"},
        {"mapId": "map", "mapVersion": "2", "mapStatus": "ENABLED"},
    ]
    again = make_instant_action_v3(
        "downloadMap", "dl2", mapId="map", mapVersion="2", mapDownloadLink=link
    )
    runtime.handle_instant_actions(topic, encode(make_instant_actions_v3(again)))
    clock.advance(1.0)
    runtime.tick(1.0, clock.monotonic())
    errors: list[Json] = sent.of(Topic.STATE)[-1]["errors"]  # type: ignore[assignment]
    assert [(e["errorType"], e["errorLevel"]) for e in errors] == [("DUPLICATE_MAP", "WARNING")]
    for kind in (Topic.STATE, Topic.FACTSHEET):
        for message in sent.of(kind):
            assert not list(_schema("3.0.0", kind.value).iter_errors(message))
