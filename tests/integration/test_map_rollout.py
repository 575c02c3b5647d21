"""Master control as the fleet's map server (``/maps``; docs/master.md, *Maps*), in one process
with hand-made states: map files kept and served by token, a version never changed, downloads
and enables sent per vehicle with a reason for each one left out, a download enabled once the
vehicle lists it, and orders sent only onto a map the vehicle has ENABLED (§6.7.1)."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest
from structlog.testing import capture_logs

from tests.integration.service_on_store import AGV, in_process_api, journaled, online, report
from vda5050.codec import encode
from vda5050.models import ActionStatus, Connection, ConnectionState
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.service import MasterService

pytestmark = pytest.mark.integration

OPERATOR = {"Authorization": "Bearer act"}
VIEWER = {"Authorization": "Bearer look"}
KEYS = {"api_operator_keys": ["act"], "api_viewer_keys": ["look"]}
PUBLIC = "http://master.example:8050"
MAP_FILE = b"occupancy grid\n" * 500
OLD = AgvId("acme", "old_2_0")


def _maps(*listed: tuple[str, str]) -> list[dict[str, str]]:
    return [{"mapId": "line", "mapVersion": v, "mapStatus": s} for v, s in listed]


def _old_vehicle(service: MasterService) -> None:
    """A 2.0.0 vehicle (no map distribution) ONLINE on n5."""
    header = {**HEADER, "version": "2.0.0", "serial_number": OLD.serial_number}
    online = Connection.model_validate({**header, "connection_state": ConnectionState.ONLINE})
    service.ingest(build_topic("uagv", 2, OLD, Topic.CONNECTION), encode(online))
    state = make_state(**header, last_node_id="n5")
    service.ingest(build_topic("uagv", 2, OLD, Topic.STATE), encode(state))


def _downloads(service_publisher: Any) -> list[dict[str, Any]]:
    return [a for m in service_publisher.messages(Topic.INSTANT_ACTIONS) for a in m["actions"]]


def _parameters(action: dict[str, Any]) -> dict[str, Any]:
    return {p["key"]: p["value"] for p in action["actionParameters"]}


async def test_a_map_file_is_stored_served_by_its_link_and_never_changed(tmp_path: Path) -> None:
    """PUT stores it (operator key), the same bytes again change nothing, other bytes are
    refused; the download link sent to the vehicle carries a token that fetches the file
    without a key; a viewer key fetches it too; deleted, it is gone."""
    settings: dict[str, Any] = {
        **KEYS,
        "public_url": PUBLIC + "/",
        "max_map_bytes": 8192,
    }
    async with (
        journaled(tmp_path, **settings) as (service, publisher, _, _),
        in_process_api(service) as client,
    ):
        online(service)
        report(service, last_node_id="n0", maps=_maps(("1", "ENABLED")))
        assert (await client.put("/maps/line/2", content=MAP_FILE)).status_code == 401
        assert (
            await client.put("/maps/line/2", content=MAP_FILE, headers=VIEWER)
        ).status_code == 403
        with capture_logs() as logs:
            created = await client.put("/maps/line/2", content=MAP_FILE, headers=OPERATOR)
        assert created.status_code == 201, created.text
        body = created.json()
        digest = hashlib.sha256(MAP_FILE).hexdigest()
        assert (body["stored"], body["sizeBytes"], body["sha256"]) == (True, len(MAP_FILE), digest)
        assert [e["event"] for e in logs] == ["maps.uploaded"]
        same = await client.put("/maps/line/2", content=MAP_FILE, headers=OPERATOR)
        assert (same.status_code, same.json()["uploaded"]) == (200, body["uploaded"])
        other = await client.put("/maps/line/2", content=b"another grid", headers=OPERATOR)
        assert other.status_code == 409
        assert "a map version never changes" in other.json()["detail"]
        empty = await client.put("/maps/line/3", content=b"", headers=OPERATOR)
        assert (empty.status_code, empty.json()["detail"]) == (
            422,
            "the map file is empty: send its bytes as the request body",
        )
        large = await client.put("/maps/line/4", content=b"x" * 9000, headers=OPERATOR)
        assert large.status_code == 413
        assert "max_map_bytes" in large.json()["detail"]
        control = await client.put("/maps/line/2%07b", content=b"x", headers=OPERATOR)
        assert (control.status_code, control.json()["detail"]) == (
            422,
            "mapVersion contains a control character",
        )

        listed = (await client.get("/maps", headers=VIEWER)).json()
        assert [(m["mapVersion"], m["stored"], m["vehicles"]) for m in listed] == [
            (
                "1",
                False,
                [{"manufacturer": "acme", "serialNumber": "robot_0", "mapStatus": "ENABLED"}],
            ),
            ("2", True, []),
        ]

        sent = await client.post("/maps/line/2/distribute", json={}, headers=OPERATOR)
        assert sent.status_code == 200, sent.text
        assert sent.json()["sent"] == 1
        (download,) = _downloads(publisher)
        assert download["actionType"] == "downloadMap"
        parameters = _parameters(download)
        link = urlsplit(parameters["mapDownloadLink"])
        assert (parameters["mapId"], parameters["mapVersion"], parameters["mapHash"]) == (
            "line",
            "2",
            digest,
        )
        assert f"{link.scheme}://{link.netloc}" == PUBLIC
        by_link = await client.get(f"{link.path}?{link.query}")  # no key, as a vehicle fetches it
        assert (by_link.status_code, by_link.content) == (200, MAP_FILE)
        assert by_link.headers["content-type"] == "application/octet-stream"
        assert (await client.get(link.path)).status_code == 401
        assert (await client.get(f"{link.path}?token=0123")).status_code == 401
        assert (await client.get("/maps/line/1/file?" + link.query)).status_code == 401
        assert (await client.get(link.path, headers=VIEWER)).content == MAP_FILE

        assert (await client.delete("/maps/line/2", headers=OPERATOR)).status_code == 204
        assert (await client.get(link.path, headers=VIEWER)).status_code == 404
        gone = await client.post("/maps/line/2/distribute", json={}, headers=OPERATOR)
        assert (gone.status_code, gone.json()["detail"]) == (
            404,
            "map 'line' version '2' is not stored on master control",
        )
    assert len(list((tmp_path / "maps").glob("*.map"))) == 0


async def test_a_distribution_is_enabled_once_downloaded_and_each_vehicle_left_out_says_why(
    tmp_path: Path,
) -> None:
    """With ``enable``, the 2.1 vehicle is sent downloadMap and, once its state lists the
    version DISABLED, enableMap; the 2.0 vehicle is listed with a 422. Until the new version
    is ENABLED, orders are not sent onto a map it has only DISABLED."""
    settings: dict[str, Any] = {"public_url": PUBLIC}
    async with (
        journaled(tmp_path, **settings) as (service, publisher, _, _),
        in_process_api(service) as client,
    ):
        online(service)
        report(service, last_node_id="n0", maps=_maps(("1", "ENABLED")))
        _old_vehicle(service)
        assert (await client.put("/maps/line/2", content=MAP_FILE)).status_code == 201
        answer = await client.post("/maps/line/2/distribute", json={"enable": True})
        assert answer.status_code == 200, answer.text
        results = {r["serialNumber"]: r for r in answer.json()["results"]}
        assert answer.json()["sent"] == 1
        assert results["robot_0"]["status"] == 202
        download_id = results["robot_0"]["actionIds"][0]
        assert results["old_2_0"]["status"] == 422
        assert results["old_2_0"]["detail"] == (
            "vehicle acme/old_2_0 cannot take map 'line' version '2': it speaks VDA 5050 2.0.0, "
            "which has no map distribution (new in 2.1, §6.7)"
        )
        waiting = (await client.get("/maps/line/2")).json()
        assert waiting["enablingAfterDownload"] == ["acme/robot_0"]

        running = [
            {"actionId": download_id, "actionType": "downloadMap", "actionStatus": "RUNNING"}
        ]
        report(service, last_node_id="n0", maps=_maps(("1", "ENABLED")), action_states=running)
        assert [a["actionType"] for a in _downloads(publisher)] == ["downloadMap"]
        finished = [{**running[0], "actionStatus": ActionStatus.FINISHED.value}]
        downloaded = _maps(("1", "DISABLED"), ("2", "DISABLED"))
        report(service, last_node_id="n0", maps=downloaded, action_states=finished)
        vehicle = (await client.get(f"/vehicles/{AGV.manufacturer}/{AGV.serial_number}")).json()
        assert vehicle["available"] is False
        assert vehicle["unavailableReason"] == (
            "no version of map 'line' is ENABLED on it: it holds version '1' (DISABLED), '2' "
            "(DISABLED) and none ENABLED (enableMap, §6.7.1)"
        )
        assert vehicle["maps"] == downloaded
        refused = await client.post(
            "/orders", json={"manufacturer": "acme", "serialNumber": "robot_0", "destination": "n3"}
        )
        assert refused.status_code == 409
        assert "no version of map 'line' is ENABLED on it" in refused.json()["detail"]
        actions = _downloads(publisher)
        assert [a["actionType"] for a in actions] == ["downloadMap", "enableMap"]
        assert _parameters(actions[1]) == {"mapId": "line", "mapVersion": "2"}
        assert (await client.get("/maps/line/2")).json()["enablingAfterDownload"] == []

        report(service, last_node_id="n0", maps=_maps(("1", "DISABLED"), ("2", "ENABLED")))
        taken = await client.post(
            "/orders", json={"manufacturer": "acme", "serialNumber": "robot_0", "destination": "n3"}
        )
        assert taken.status_code == 201, taken.text
        again = await client.post("/maps/line/2/distribute", json={"serialNumbers": ["robot_0"]})
        (only,) = again.json()["results"]
        assert (only["status"], only["detail"]) == (
            200,
            "it holds map 'line' version '2' already (ENABLED)",
        )


async def test_a_download_to_enable_is_enabled_after_a_restart_of_master_control(
    tmp_path: Path,
) -> None:
    """Master control restarts between the vehicle's download and its enable: the new master
    control still waits for the download, and enables it once the state lists it; the
    deletion of a version being distributed outlives a restart too."""
    settings: dict[str, Any] = {"public_url": PUBLIC}
    async with (
        journaled(tmp_path, **settings) as (service, publisher, _, _),
        in_process_api(service) as client,
    ):
        online(service)
        report(service, last_node_id="n0", maps=_maps(("1", "ENABLED")))
        for version in ("2", "3"):
            content = MAP_FILE + version.encode()
            assert (await client.put(f"/maps/line/{version}", content=content)).status_code == 201
        answer = await client.post("/maps/line/2/distribute", json={"enable": True})
        assert [r["status"] for r in answer.json()["results"]] == [202]
        assert [a["actionType"] for a in _downloads(publisher)] == ["downloadMap"]

    async with (
        journaled(tmp_path, **settings) as (service, publisher, _, _),
        in_process_api(service) as client,
    ):
        waiting = (await client.get("/maps/line/2")).json()
        assert waiting["enablingAfterDownload"] == ["acme/robot_0"]
        online(service)
        report(service, last_node_id="n0", maps=_maps(("1", "ENABLED"), ("2", "DISABLED")))
        actions = _downloads(publisher)
        assert [a["actionType"] for a in actions] == ["enableMap"]
        assert _parameters(actions[0]) == {"mapId": "line", "mapVersion": "2"}
        assert (await client.get("/maps/line/2")).json()["enablingAfterDownload"] == []
        # A distribution to enable version 3, whose file is then deleted: nothing to wait for.
        report(service, last_node_id="n0", maps=_maps(("1", "DISABLED"), ("2", "ENABLED")))
        answer = await client.post("/maps/line/3/distribute", json={"enable": True})
        assert [r["status"] for r in answer.json()["results"]] == [202]
        assert (await client.delete("/maps/line/3")).status_code == 204

    async with journaled(tmp_path, **settings) as (service, _, _, _):
        overview = service.map_overview()
        assert [(m["mapVersion"], m["enablingAfterDownload"]) for m in overview] == [("2", [])]


async def test_enable_switches_the_versions_the_vehicles_hold(tmp_path: Path) -> None:
    """``…/enable`` sends enableMap where the version is held DISABLED (stored here or not),
    says so where it is ENABLED, and names the vehicles that do not hold it; unknown vehicles
    are a 404."""
    async with (
        journaled(tmp_path) as (service, publisher, _, _),
        in_process_api(service) as client,
    ):
        online(service)
        report(service, last_node_id="n0", maps=_maps(("1", "ENABLED"), ("7", "DISABLED")))
        switched = await client.post("/maps/line/7/enable", json={"manufacturer": "acme"})
        assert switched.status_code == 200, switched.text
        assert [r["status"] for r in switched.json()["results"]] == [202]
        assert [a["actionType"] for a in _downloads(publisher)] == ["enableMap"]
        missing = await client.post("/maps/line/9/enable", json={})
        (result,) = missing.json()["results"]
        assert result["status"] == 409
        assert result["detail"].startswith(
            "vehicle acme/robot_0 cannot take map 'line' version '9': it does not hold map"
        )
        unknown = await client.post("/maps/line/7/enable", json={"serialNumbers": ["ghost"]})
        assert (unknown.status_code, unknown.json()["detail"]) == (
            404,
            "no vehicle with serialNumber 'ghost' is known",
        )
        nobody = await client.post("/maps/line/7/enable", json={"manufacturer": "other"})
        assert nobody.status_code == 404
        no_map = await client.get("/maps/line/9")
        assert no_map.status_code == 404


async def test_without_an_address_vehicles_can_reach_no_download_is_sent(tmp_path: Path) -> None:
    """An API on every interface (0.0.0.0) without ``public_url``: 409 naming the setting."""
    settings: dict[str, Any] = {
        "api_host": "0.0.0.0",  # noqa: S104 - never bound here
        "insecure_api": True,
    }
    async with (
        journaled(tmp_path, **settings) as (service, publisher, _, _),
        in_process_api(service) as client,
    ):
        online(service)
        assert (await client.put("/maps/line/2", content=MAP_FILE)).status_code == 201
        answer = await client.post("/maps/line/2/distribute", json={})
        assert answer.status_code == 409
        assert "set public_url (VDA_PUBLIC_URL)" in answer.json()["detail"]
        assert publisher.messages(Topic.INSTANT_ACTIONS) == []
