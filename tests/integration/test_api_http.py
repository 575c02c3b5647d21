"""The HTTP API's answers, driven over ASGI without a broker (issue 8 item 4: every 4xx names
what is wrong; GET /orders; /docs works offline)."""

from __future__ import annotations

import itertools
import re
from collections.abc import AsyncIterator
from datetime import UTC, datetime

import httpx
import jsonschema
import pytest
from pydantic import ValidationError

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.errors import ConfigError
from vda5050.models import Connection
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.api import create_app
from vda_master.api_auth import check_exposure
from vda_master.api_documents import stored_order_document
from vda_master.api_models import (
    CreateOrder,
    OrderCreated,
    OrderInfo,
    OrdersCreated,
    VehicleSummary,
)
from vda_master.config import MasterConfig, load_master_config
from vda_master.order_records import plan_document, to_record
from vda_master.service import MasterService
from vda_master.testing import (
    RecordingPublisher,
    demo_graph,
    make_factsheet,
    parse_exposition,
)

AGV = AgvId("acme", "robot_0")
BODY = {"manufacturer": "acme", "serialNumber": "robot_0"}


def _feed(service: MasterService, agv: AgvId, *messages: object) -> None:
    for message in messages:
        kind = {
            "Connection": Topic.CONNECTION,
            "State": Topic.STATE,
            "Factsheet": Topic.FACTSHEET,
        }[type(message).__name__]
        header = {"manufacturer": agv.manufacturer, "serial_number": agv.serial_number}
        stamped = message.model_copy(update=header)  # type: ignore[attr-defined]
        service.ingest(build_topic("uagv", 2, agv, kind), encode(stamped))


def _online() -> Connection:
    return Connection.model_validate({**HEADER, "connection_state": "ONLINE"})


@pytest.fixture
async def api() -> AsyncIterator[tuple[httpx.AsyncClient, MasterService]]:
    service = MasterService(MasterConfig(), demo_graph(), RecordingPublisher(), FakeClock())
    _feed(service, AGV, _online(), make_factsheet(), make_state(last_node_id="7"))
    transport = httpx.ASGITransport(create_app(service))
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
        yield client, service


@pytest.mark.parametrize(
    ("content", "headers", "status", "detail"),
    [
        (
            b'{"destination": "10",\n "manufacturer": }',
            {"content-type": "application/json"},
            422,
            "request body is not valid JSON: Expecting value at line 2 column 18",
        ),
        (
            b'{"destination": "10"}',
            {},
            415,
            "send 'content-type: application/json' (the header is missing)",
        ),
        (
            b'{"destination": "10"}',
            {"content-type": "text/plain"},
            415,
            "(got 'text/plain')",
        ),
        (b"", {"content-type": "application/json"}, 422, "request body is empty"),
        (
            b'{"destination": "\xe9"}',
            {"content-type": "application/json"},
            422,
            "request body is not valid JSON: it is not UTF-8 text (byte 0xe9 at 17)",
        ),
        (
            b"[1, 2]",
            {"content-type": "application/json"},
            422,
            "must be a JSON object, not an array",
        ),
        (
            b'{"destination": "10", "colour": "red"}',
            {"content-type": "application/json"},
            422,
            "unknown field 'colour'",
        ),
    ],
)
async def test_malformed_requests_say_what_is_wrong(
    api: tuple[httpx.AsyncClient, MasterService],
    content: bytes,
    headers: dict[str, str],
    status: int,
    detail: str,
) -> None:
    """Broken JSON gives line and column, a missing content type says so, and so on."""
    client, _ = api
    response = await client.post("/orders", content=content, headers=headers)
    assert response.status_code == status, response.text
    assert detail in response.json()["detail"]


async def test_missing_field_is_named(api: tuple[httpx.AsyncClient, MasterService]) -> None:
    """A missing field is named as the request spells it."""
    client, _ = api
    response = await client.post("/vehicles/acme/robot_0/instantActions", json={"action": []})
    assert response.status_code == 422
    assert "missing field 'actions'" in response.json()["detail"]
    response = await client.post(
        "/vehicles/acme/robot_0/instantActions", json={"actions": [{"blockingType": "HARD"}]}
    )
    assert "missing field 'actions.0.actionType'" in response.json()["detail"]


async def test_unsupported_action_is_422_and_busy_is_409(
    api: tuple[httpx.AsyncClient, MasterService],
) -> None:
    """An action the vehicle's factsheet does not offer can never be served: 422; a vehicle
    running an order cannot take another now: 409."""
    client, _ = api
    url = "/vehicles/acme/robot_0/instantActions"
    unknown = await client.post(url, json={"actions": [{"actionType": "dance"}]})
    assert unknown.status_code == 422
    assert "does not list action 'dance'" in unknown.json()["detail"]
    first = await client.post("/orders", json={**BODY, "destination": "10"})
    assert first.status_code == 201, first.text
    second = await client.post("/orders", json={**BODY, "destination": "2"})
    assert second.status_code == 409
    assert "it runs order" in second.json()["detail"]


async def test_created_order_is_answered_as_it_was_published(
    api: tuple[httpx.AsyncClient, MasterService],
) -> None:
    """POST /orders answers 201 with the OrderCreated body: orderId, the vehicle and the order
    message exactly as published (header included); the OpenAPI schema documents that body."""
    client, service = api
    response = await client.post("/orders", json={**BODY, "destination": "10"})
    assert response.status_code == 201, response.text
    assert response.headers["content-type"] == "application/json"
    body = response.json()
    assert list(body) == ["orderId", "manufacturer", "serialNumber", "destination", "order"]
    assert body == OrderCreated.model_validate(body).model_dump(mode="json")
    assert body["destination"] == "10"
    publisher = service.publisher
    assert isinstance(publisher, RecordingPublisher)
    (published,) = publisher.orders()
    assert body["order"] == published
    assert (body["orderId"], body["manufacturer"], body["serialNumber"]) == (
        published["orderId"],
        "acme",
        "robot_0",
    )
    schema = (await client.get("/openapi.json")).json()
    created = schema["paths"]["/orders"]["post"]["responses"]["201"]
    assert created["content"]["application/json"]["schema"]["$ref"].endswith("OrderCreated")


async def test_a_batch_creates_each_order_as_a_post_would(
    api: tuple[httpx.AsyncClient, MasterService],
) -> None:
    """POST /orders/batch creates its orders in turn, each as POST /orders would: one that
    cannot be created gets the status and detail POST /orders would have answered, the others
    are created, sent and listed all the same; an order without a vehicle sees the vehicles
    that the batch's earlier orders took."""
    client, service = api
    _feed(
        service, AgvId("acme", "robot_9"), _online(), make_factsheet(), make_state(last_node_id="3")
    )
    orders = [
        {**BODY, "destination": "10"},
        {"destination": "2"},  # robot_0 is taken by now: the master picks robot_9
        {"manufacturer": "acme", "serialNumber": "ghost", "destination": "10"},
        {**BODY, "destination": "2"},
        {"destination": "2"},  # no vehicle left
    ]
    response = await client.post("/orders/batch", json={"orders": orders})
    assert response.status_code == 200, response.text
    OrdersCreated.model_validate(response.json())  # the documented answer
    results = response.json()["results"]
    assert [r["status"] for r in results] == [201, 201, 404, 409, 409]
    assert [r.get("serialNumber") for r in results[:2]] == ["robot_0", "robot_9"]
    assert "ghost" in results[2]["detail"]
    assert "it runs order" in results[3]["detail"]
    assert "no available vehicle can reach 2" in results[4]["detail"]
    assert set(results[2]) == {"status", "detail"}
    publisher = service.publisher
    assert isinstance(publisher, RecordingPublisher)
    assert [r["order"] for r in results[:2]] == publisher.orders()
    for created in results[:2]:
        assert set(created) == {
            "status", "orderId", "manufacturer", "serialNumber", "destination", "order"
        }  # fmt: skip
        view = (await client.get(f"/orders/{created['orderId']}")).json()
        assert (view["status"], view["serialNumber"]) == ("SENT", created["serialNumber"])
    schema = (await client.get("/openapi.json")).json()
    answer = schema["paths"]["/orders/batch"]["post"]["responses"]["200"]
    assert answer["content"]["application/json"]["schema"]["$ref"].endswith("OrdersCreated")


@pytest.mark.parametrize(
    ("body", "detail"),
    [
        ({"orders": []}, "field 'orders': List should have at least 1 item"),
        ({"orders": [{**BODY, "destination": "10"}, {"route": 7}]}, "orders.1.route"),
        ({"orders": [{**BODY}]}, "exactly one of destination, route, stationType and stops"),
        ([{**BODY, "destination": "10"}], "must be a JSON object, not an array"),
    ],
)
async def test_an_invalid_batch_is_refused_whole(
    api: tuple[httpx.AsyncClient, MasterService], body: object, detail: str
) -> None:
    """A batch with a malformed order is a client's mistake: 422 naming the order's place in
    the list, and no order of it is created."""
    client, service = api
    response = await client.post("/orders/batch", json=body)
    assert response.status_code == 422, response.text
    assert detail in response.json()["detail"], response.text
    assert service.tracks == {}


async def test_orders_are_listed_newest_first_with_filters(
    api: tuple[httpx.AsyncClient, MasterService],
) -> None:
    """GET /orders lists orders newest first and filters by status and vehicle."""
    client, service = api
    other = AgvId("acme", "robot_9")
    _feed(service, other, _online(), make_factsheet(), make_state(last_node_id="3"))
    first = (await client.post("/orders", json={**BODY, "destination": "10"})).json()
    second = (
        await client.post(
            "/orders", json={"manufacturer": "acme", "serialNumber": "robot_9", "destination": "2"}
        )
    ).json()
    listed = (await client.get("/orders")).json()
    assert [o["orderId"] for o in listed] == [second["orderId"], first["orderId"]]
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z", listed[0]["createdAt"])
    mine = (await client.get("/orders", params={"serialNumber": "robot_0"})).json()
    assert [o["orderId"] for o in mine] == [first["orderId"]]
    assert (await client.get("/orders", params={"status": "FINISHED"})).json() == []
    assert len((await client.get("/orders", params={"limit": 1})).json()) == 1
    bad = await client.get("/orders", params={"status": "DONE"})
    assert bad.status_code == 422
    assert "query parameter 'status'" in bad.json()["detail"]


async def test_docs_work_offline(api: tuple[httpx.AsyncClient, MasterService]) -> None:
    """/docs and its assets are served by the package; the page loads nothing from elsewhere,
    and the OpenAPI schema documents the error bodies."""
    client, _ = api
    page = await client.get("/docs")
    assert page.status_code == 200
    sources = re.findall(r'(?:src|href)="([^"]+)"', page.text)
    assert sources
    assert all(s.startswith("/") for s in sources), sources
    for source in sources:
        assert (await client.get(source)).status_code == 200, source
    assert "https://" not in page.text.replace("https://swagger.io", "")
    schema = (await client.get("/openapi.json")).json()
    errors = schema["paths"]["/orders"]["post"]["responses"]
    assert {"404", "409", "415", "422"} <= set(errors)
    assert errors["409"]["content"]["application/json"]["schema"]["$ref"].endswith("ErrorBody")


@pytest.mark.parametrize(
    ("method", "path", "allowed"),
    [
        ("OPTIONS", "/orders", "GET, POST"),
        ("PUT", "/orders/o-1", "DELETE, GET, PATCH"),
        ("POST", "/vehicles", "GET"),
        ("DELETE", "/vehicles/acme/robot_0/instantActions", "POST"),
    ],
)
async def test_a_wrong_method_is_405_with_every_method_of_the_path_in_allow(
    api: tuple[httpx.AsyncClient, MasterService], method: str, path: str, allowed: str
) -> None:
    """RFC 9110 §15.5.6: ``Allow`` lists all the methods of the path (FastAPI keeps a route
    per method, and Starlette listed only the first one's), and the detail says what to use."""
    client, _ = api
    response = await client.request(method, path)
    assert response.status_code == 405
    assert response.headers["allow"] == allowed
    assert response.json()["detail"] == (
        f"{method} is not allowed on {path}: use {allowed.replace(', ', ' or ')}"
    )
    unknown = await client.request(method, "/no/such/path")
    assert unknown.status_code == 404


_TARGET_VALUES: dict[str, tuple[object, ...]] = {
    "destination": ("10",),
    "route": (["e1"],),
    "stationType": ("drop",),
    "stops": ([{"destination": "10"}, {"stationType": "drop"}],),
    "manufacturer": ("acme",),
    "serialNumber": ("robot_0",),
}


async def test_a_body_the_openapi_schema_of_post_orders_takes_is_one_the_master_takes(
    api: tuple[httpx.AsyncClient, MasterService],
) -> None:
    """Every combination of the six target fields absent, null or given: the published JSON
    schema of ``POST /orders`` (and of each batch entry) accepts exactly the bodies the
    master's validation accepts, so that a client generated from /openapi.json cannot build a
    request the master refuses as malformed (exactly one of destination, route, stationType and
    stops;
    manufacturer and serialNumber both or neither)."""
    client, _ = api
    document = (await client.get("/openapi.json")).json()
    body_ref = document["paths"]["/orders"]["post"]["requestBody"]["content"]["application/json"]
    validator = jsonschema.Draft202012Validator(
        {"$ref": body_ref["schema"]["$ref"], "components": document["components"]}
    )
    absent = object()
    accepted = 0
    for choices in itertools.product(
        *((absent, None, *values) for values in _TARGET_VALUES.values())
    ):
        body = {k: v for k, v in zip(_TARGET_VALUES, choices, strict=True) if v is not absent}
        try:
            CreateOrder.model_validate(body)
        except ValidationError:
            takes = False
        else:
            takes = True
        assert validator.is_valid(body) == takes, body
        accepted += takes
    # one target (4 x 8: the others absent or null) x both names or neither (5: each absent or
    # null)
    assert accepted == 160


async def test_oversized_body_is_413_before_it_is_parsed() -> None:
    """A body over max_body_bytes is refused with 413 and says the limit (issue 14)."""
    config = MasterConfig(max_body_bytes=2048)
    service = MasterService(config, demo_graph(), RecordingPublisher(), FakeClock())
    transport = httpx.ASGITransport(create_app(service))
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
        big = {"destination": "10", "route": None, "padding": "x" * 5000}
        response = await client.post("/orders", json=big)
        assert response.status_code == 413
        assert "larger than the limit of 2048 bytes" in response.json()["detail"]

        async def chunks() -> AsyncIterator[bytes]:
            for _ in range(10):
                yield b" " * 500

        streamed = await client.post(
            "/orders", content=chunks(), headers={"content-type": "application/json"}
        )
        assert streamed.status_code == 413
        small = await client.post("/orders", json={"destination": "10"})
        assert small.status_code == 409  # parsed and answered: no vehicle is available


async def test_instant_actions_beyond_the_vehicles_limits_are_422() -> None:
    """The master honours the vehicle's declared protocolLimits: too many instant actions, too
    many parameters, a too long actionType are refused with 422 naming the limit (R114)."""
    factsheet = make_factsheet(
        array_lens={"instantActions": 2, "actions.actionsParameters": 1},
        string_lens={"enumLen": 12},
        actions=[
            {"actionType": "startPause", "actionScopes": ["INSTANT"]},
            {
                "actionType": "beep",
                "actionScopes": ["INSTANT"],
                "actionParameters": [
                    {"key": "tone", "valueDataType": "STRING", "isOptional": True},
                    {"key": "loud", "valueDataType": "BOOL", "isOptional": True},
                ],
            },
            {"actionType": "aVeryLongVendorAction", "actionScopes": ["INSTANT"]},
        ],
    )
    service = MasterService(MasterConfig(), demo_graph(), RecordingPublisher(), FakeClock())
    _feed(service, AGV, _online(), factsheet, make_state(last_node_id="7"))
    transport = httpx.ASGITransport(create_app(service))
    url = "/vehicles/acme/robot_0/instantActions"
    pause = {"actionType": "startPause"}
    beep = {
        "actionType": "beep",
        "actionParameters": [{"key": "tone", "value": "a"}, {"key": "loud", "value": True}],
    }
    cases = [
        ({"actions": [pause, pause, pause]}, "instantActions holds 3 entries"),
        ({"actions": [beep]}, "actions.actionsParameters holds 2 entries"),
        ({"actions": [{"actionType": "aVeryLongVendorAction"}]}, "enumLen 12"),
    ]
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
        for body, detail in cases:
            response = await client.post(url, json=body)
            assert response.status_code == 422, response.text
            assert detail in response.json()["detail"]
        assert (await client.post(url, json={"actions": [pause]})).status_code == 202


async def test_api_keys_with_viewer_and_operator_roles() -> None:
    """With keys configured: no key 401, a viewer reads but may not act (403), an operator
    acts; /health stays open; keys come as Bearer, X-API-Key or ?key= (issue 14)."""
    config = MasterConfig(api_operator_keys=["op-secret"], api_viewer_keys=["look-only"])
    service = MasterService(config, demo_graph(), RecordingPublisher(), FakeClock())
    _feed(service, AGV, _online(), make_factsheet(), make_state(last_node_id="7"))
    transport = httpx.ASGITransport(create_app(service))
    viewer = {"Authorization": "Bearer look-only"}
    operator = {"X-API-Key": "op-secret"}
    order = {**BODY, "destination": "10"}
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
        assert (await client.get("/health")).status_code == 200
        anonymous = await client.get("/vehicles")
        assert anonymous.status_code == 401
        assert anonymous.headers["www-authenticate"] == "Bearer"
        assert "missing API key" in anonymous.json()["detail"]
        assert (await client.get("/vehicles", headers={"X-API-Key": "guess"})).status_code == 401
        assert (await client.get("/vehicles", headers=viewer)).status_code == 200
        assert (await client.get("/orders", params={"key": "look-only"})).status_code == 200
        assert (await client.get("/alarms")).status_code == 401
        assert (await client.get("/alarms", headers=viewer)).status_code == 200
        refused = await client.post("/orders", json=order, headers=viewer)
        assert refused.status_code == 403
        assert "may only read" in refused.json()["detail"]
        batch = {"orders": [order]}
        assert (await client.post("/orders/batch", json=batch)).status_code == 401
        assert (await client.post("/orders/batch", json=batch, headers=viewer)).status_code == 403
        vehicle = f"/vehicles/{AGV.manufacturer}/{AGV.serial_number}"
        out = {"inService": False}
        assert (await client.patch(vehicle, json=out, headers=viewer)).status_code == 403
        assert service.out_of_service == {}
        assert service.tracks == {}
        assert (await client.post("/orders", json=order, headers=operator)).status_code == 201


async def test_metrics_are_a_prometheus_text_for_readers() -> None:
    """GET /metrics: the Prometheus text format's content type, every line well formed (the
    unit tests' parser), one sample per vehicle; with keys, a viewer's key is needed."""
    config = MasterConfig(api_operator_keys=["op-secret"], api_viewer_keys=["look-only"])
    service = MasterService(config, demo_graph(), RecordingPublisher(), FakeClock())
    _feed(service, AGV, _online(), make_factsheet(), make_state(last_node_id="7"))
    transport = httpx.ASGITransport(create_app(service))
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
        assert (await client.get("/metrics")).status_code == 401
        answer = await client.get("/metrics", headers={"Authorization": "Bearer look-only"})
    assert answer.status_code == 200, answer.text
    assert answer.headers["content-type"] == "text/plain; version=0.0.4; charset=utf-8"
    samples = parse_exposition(answer.text)
    labels = f'{{manufacturer="{AGV.manufacturer}",serial_number="{AGV.serial_number}"}}'
    assert samples[f"vda_master_vehicle_available{labels}"] == 1
    assert samples["vda_master_vehicles_available"] == 1


def test_keys_from_the_environment_may_be_comma_separated() -> None:
    """VDA_API_OPERATOR_KEYS=a,b gives two operator keys."""
    config = load_master_config(None, {}, {"VDA_API_OPERATOR_KEYS": "a, b"})
    assert config.api_operator_keys == ["a", "b"]


def test_key_less_api_off_loopback_is_refused_unless_insecure() -> None:
    """Secure by default: 0.0.0.0 without keys fails at start-up naming the way out; with a key
    or --insecure-api it starts; loopback needs nothing."""
    with pytest.raises(ConfigError, match="--insecure-api"):
        check_exposure(MasterConfig(api_host="0.0.0.0"))  # noqa: S104 - the case under test
    check_exposure(MasterConfig(api_host="0.0.0.0", api_operator_keys=["k"]))  # noqa: S104
    check_exposure(MasterConfig(api_host="0.0.0.0", insecure_api=True))  # noqa: S104
    check_exposure(MasterConfig(api_host="127.0.0.1"))
    check_exposure(MasterConfig(api_host="::1"))


async def test_listed_orders_and_vehicles_are_exactly_what_their_models_dump(
    api: tuple[httpx.AsyncClient, MasterService],
) -> None:
    """GET /orders and GET /vehicles render their items without building models (a thousand
    cost 30 ms of event loop): every item is what OrderInfo / VehicleSummary dump, key for key,
    waits and traffic notes included, the single-object views agree, a stored order reads as it
    did in memory, and the OpenAPI schema still names the models."""
    client, service = api
    other = AgvId("acme", "robot_9")
    _feed(service, other, _online(), make_factsheet(), make_state(last_node_id="3"))
    # robot_9 is sent onto robot_0's node: robot_0 is moved out of the way, each waits.
    body = {"manufacturer": "acme", "serialNumber": "robot_9", "destination": "7"}
    assert (await client.post("/orders", json=body)).status_code == 201
    assert isinstance(service.clock, FakeClock)
    service.clock.advance(2.5)
    listed = (await client.get("/orders")).json()
    assert len(listed) == 2
    assert any(o["waitingFor"] for o in listed)
    assert any(o["note"] for o in listed)
    for order in listed:
        assert order == OrderInfo.model_validate(order).model_dump(mode="json")
        assert list(order) == list(OrderInfo.model_validate(order).model_dump(mode="json"))
        assert (await client.get(f"/orders/{order['orderId']}")).json() == order
    vehicles = (await client.get("/vehicles")).json()
    assert {v["serialNumber"] for v in vehicles} == {"robot_0", "robot_9"}
    for vehicle in vehicles:
        assert vehicle == VehicleSummary.model_validate(vehicle).model_dump(mode="json")
        path = f"/vehicles/acme/{vehicle['serialNumber']}"
        detail = (await client.get(path)).json()
        assert {k: detail[k] for k in vehicle} == vehicle
    track = service.tracks[listed[1]["orderId"]]
    now = datetime.now(UTC)
    record = to_record(track, plan_document(track.plan), created=now, updated=now)
    stored = stored_order_document(record)
    assert stored == OrderInfo.model_validate(stored).model_dump(mode="json")
    assert stored | {"createdAt": None} == listed[1] | {
        "createdAt": None,
        "waitingFor": [],
        "waitingAt": None,
        "waitedS": None,
        "expectedFinishAt": None,  # an order read from the store has ended
    }
    assert listed[1]["expectedFinishAt"] is not None
    schema = (await client.get("/openapi.json")).json()["paths"]
    for path, model in (("/orders", "OrderInfo"), ("/vehicles", "VehicleSummary")):
        answer = schema[path]["get"]["responses"]["200"]["content"]["application/json"]["schema"]
        assert answer["type"] == "array"
        assert answer["items"]["$ref"].endswith(model)


async def test_health_counts_the_vehicles_that_could_take_an_order(
    api: tuple[httpx.AsyncClient, MasterService],
) -> None:
    """/health: vehicles known and available (as GET /vehicles says each); one that is known
    without a state, and one running an order, are not available."""
    client, service = api
    _feed(service, AgvId("acme", "robot_1"), _online())  # no state yet
    health = (await client.get("/health")).json()
    listed = (await client.get("/vehicles")).json()
    assert (health["vehicles"], health["availableVehicles"]) == (2, 1)
    assert sum(vehicle["available"] for vehicle in listed) == 1
    assert (await client.post("/orders", json={**BODY, "destination": "10"})).status_code == 201
    health = (await client.get("/health")).json()
    assert (health["vehicles"], health["availableVehicles"], health["activeOrders"]) == (2, 0, 1)


@pytest.mark.parametrize("traffic_control", [True, False])
async def test_orders_for_a_station_type_go_to_the_stations_of_that_type(
    traffic_control: bool,
) -> None:
    """``stationType`` instead of a destination: the order goes to a node of that type, the one
    the vehicle reaches first; a second order for the type goes to the other station rather
    than queue behind the first (traffic control on: the planner counts the first vehicle's
    stay there; off: a station another vehicle is bound for is passed over while one is
    free). The answer names the station chosen; an unknown type is a 404."""
    config = MasterConfig(traffic_control=traffic_control)
    service = MasterService(config, demo_graph(), RecordingPublisher(), FakeClock())
    west, middle = AgvId("acme", "west"), AgvId("acme", "middle")
    _feed(service, west, _online(), make_factsheet(), make_state(last_node_id="7"))
    _feed(service, middle, _online(), make_factsheet(), make_state(last_node_id="1"))
    transport = httpx.ASGITransport(create_app(service))
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
        drop = {"stationType": "drop", "destinationActions": [{"actionType": "drop"}]}
        first = await client.post("/orders", json=drop)
        assert first.status_code == 201, first.text
        assert (first.json()["serialNumber"], first.json()["destination"]) == ("west", "13")
        second = await client.post("/orders", json=drop)
        assert second.status_code == 201, second.text
        assert (second.json()["serialNumber"], second.json()["destination"]) == ("middle", "14")
        last_node = second.json()["order"]["nodes"][-1]
        assert last_node["nodeId"] == "14"
        assert [a["actionType"] for a in last_node["actions"]] == ["drop"]
        view = (await client.get(f"/orders/{second.json()['orderId']}")).json()
        assert view["nodeIds"][-1] == "14"
        none_left = await client.post("/orders", json=drop)
        assert none_left.status_code == 409
        assert (
            "no available vehicle can reach a node of stationType 'drop'"
            in (none_left.json()["detail"])
        )
        unknown = await client.post("/orders", json={"stationType": "dock"})
        assert unknown.status_code == 404
        assert unknown.json()["detail"] == "no node of the graph has stationType 'dock'"


async def test_a_named_vehicle_sent_to_a_station_type_takes_its_nearest_station(
    api: tuple[httpx.AsyncClient, MasterService],
) -> None:
    """``stationType`` with a vehicle named: that vehicle, to the station of the type it is
    expected at first (robot_0 stands on node 7: pick station 11 by node 1, 8 m, not 12)."""
    client, _ = api
    response = await client.post("/orders", json={**BODY, "stationType": "pick"})
    assert response.status_code == 201, response.text
    assert response.json()["destination"] == "11"
    assert [n["nodeId"] for n in response.json()["order"]["nodes"]] == ["7", "1", "11"]


def _comparable(value: object) -> object:
    """An answer with what differs between two runs (ids, stamps) left out."""
    if isinstance(value, dict):
        return {k: _comparable(v) for k, v in value.items() if k not in {"orderId", "timestamp"}}
    if isinstance(value, list):
        return [_comparable(v) for v in value]
    return value


async def test_post_orders_answers_the_same_on_the_short_way_as_through_fastapi() -> None:
    """``POST /orders`` mostly bypasses FastAPI's machinery (vda_master.api_fast, issue 12);
    every kind of answer must stay what the FastAPI route gives: created, refused by master
    control, refused for the key, and every way a body can be wrong."""
    config = MasterConfig(api_operator_keys=["op-secret"], api_viewer_keys=["look-only"])
    json_type = {"content-type": "application/json"}
    operator = {**json_type, "X-API-Key": "op-secret"}
    order = b'{"manufacturer": "acme", "serialNumber": "robot_0", "destination": "10"}'
    requests: list[tuple[bytes, dict[str, str], str]] = [
        (order, json_type, ""),
        (order, {**json_type, "Authorization": "Bearer look-only"}, ""),
        (order, {**json_type, "X-API-Key": "guess"}, ""),
        (order.replace(b'"10"', b'"nowhere"'), operator, ""),
        (order.replace(b"robot_0", b"robot_9"), operator, ""),
        (order[:-1] + b', "destinationActions": [{"actionType": "dance"}]}', operator, ""),
        (order[:-1] + b', "route": ["e1"]}', operator, ""),
        (order[:-1] + b', "colour": "red"}', operator, ""),
        (b'{"destination": "10",\n "manufacturer": }', operator, ""),
        (b'{"destination": "\xe9"}', operator, ""),
        (b"[1, 2]", operator, ""),
        (b"", operator, ""),
        (order, {"X-API-Key": "op-secret", "content-type": "text/plain"}, ""),
        (order, {"content-type": "application/json; charset=utf-8"}, "op-secret"),
        (order.replace(b'"10"', b'"2"'), operator, ""),
    ]
    answers: dict[bool, list[tuple[int, str | None, object]]] = {}
    for short in (True, False):
        service = MasterService(config, demo_graph(), RecordingPublisher(), FakeClock())
        _feed(service, AGV, _online(), make_factsheet(), make_state(last_node_id="7"))
        transport = httpx.ASGITransport(create_app(service, short_post=short))
        async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
            answers[short] = []
            for content, headers, key in requests:
                params = {"key": key} if key else None
                response = await client.post(
                    "/orders", content=content, headers=headers, params=params
                )
                assert response.headers["content-type"] == "application/json"
                answers[short].append(
                    (
                        response.status_code,
                        response.headers.get("www-authenticate"),
                        _comparable(response.json()),
                    )
                )
    statuses = [status for status, _, _ in answers[True]]
    assert statuses == [401, 403, 401, 404, 404, 422, 422, 422, 422, 422, 422, 422, 415, 201, 409]
    assert answers[True] == answers[False]


async def test_a_whole_fleet_is_paused_at_once_and_told_who_was_not() -> None:
    """POST /vehicles/instantActions sends startPause to every vehicle that may take it and
    lists the others with the status and detail their own endpoint would answer: one OFFLINE
    (409), one whose factsheet lacks startPause (422). A manufacturer narrows it; an unknown one
    is 404."""
    publisher = RecordingPublisher()
    service = MasterService(MasterConfig(), demo_graph(), publisher, FakeClock())
    other = AgvId("acme", "robot_1")
    gone = AgvId("acme", "robot_2")
    vendor = AgvId("beta", "b_1")
    _feed(service, AGV, _online(), make_factsheet(), make_state(last_node_id="7"))
    _feed(service, other, _online(), make_factsheet(), make_state(last_node_id="1"))
    offline = Connection.model_validate({**HEADER, "connection_state": "OFFLINE"})
    _feed(service, gone, offline, make_state(last_node_id="3"))
    no_pause = make_factsheet(actions=[{"actionType": "pick", "actionScopes": ["NODE"]}])
    _feed(service, vendor, _online(), no_pause, make_state(last_node_id="2"))
    transport = httpx.ASGITransport(create_app(service))
    pause = {"actions": [{"actionType": "startPause"}]}
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
        answer = await client.post("/vehicles/instantActions", json=pause)
        assert answer.status_code == 200, answer.text
        body = answer.json()
        only_beta = await client.post(
            "/vehicles/instantActions", json={**pause, "manufacturer": "beta"}
        )
        unknown = await client.post(
            "/vehicles/instantActions", json={**pause, "manufacturer": "gamma"}
        )
    assert body["sent"] == 2
    by_vehicle = {(r["manufacturer"], r["serialNumber"]): r for r in body["results"]}
    assert list(by_vehicle) == [
        ("acme", "robot_0"),
        ("acme", "robot_1"),
        ("acme", "robot_2"),
        ("beta", "b_1"),
    ]
    assert by_vehicle["acme", "robot_2"]["status"] == 409
    assert "its connection state is OFFLINE" in by_vehicle["acme", "robot_2"]["detail"]
    assert by_vehicle["beta", "b_1"]["status"] == 422
    assert "startPause" in by_vehicle["beta", "b_1"]["detail"]
    sent = publisher.messages(Topic.INSTANT_ACTIONS)
    assert sorted((m["serialNumber"], m["actions"][0]["actionId"]) for m in sent) == sorted(
        (serial, r["actionIds"][0]) for (_, serial), r in by_vehicle.items() if r["status"] == 202
    )
    assert {m["actions"][0]["actionType"] for m in sent} == {"startPause"}
    assert only_beta.status_code == 200
    assert [r["serialNumber"] for r in only_beta.json()["results"]] == ["b_1"]
    assert unknown.status_code == 404
    assert unknown.json()["detail"] == "no vehicle of manufacturer 'gamma' is known"


async def test_alarms_list_what_is_wrong_now_worst_first_with_when_it_began(
    api: tuple[httpx.AsyncClient, MasterService],
) -> None:
    """GET /alarms: the errors a vehicle lists and its stopped safety chain, FATAL first; an
    error keeps the time it was first seen while the vehicle goes on listing it, and is gone
    once the vehicle no longer lists it. GET /metrics counts them for alerting."""
    client, service = api
    assert (await client.get("/alarms")).json() == []
    warning = {"error_type": "batteryLow", "error_level": "WARNING"}
    fatal = {"error_type": "driveFault", "error_level": "FATAL", "error_description": "motor 2"}
    _feed(service, AGV, make_state(last_node_id="7", errors=[warning]))
    assert isinstance(service.clock, FakeClock)
    first_seen = service.clock.now()
    service.clock.advance(5.0)
    stopped = {"e_stop": "MANUAL", "field_violation": False}
    _feed(
        service,
        AGV,
        make_state(last_node_id="7", errors=[warning, fatal], safety_state=stopped),
    )
    answer = await client.get("/alarms")
    assert answer.status_code == 200
    alarms = answer.json()
    assert [(a["kind"], a.get("error", {}).get("errorType")) for a in alarms] == [
        ("error", "driveFault"),
        ("safety", None),
        ("error", "batteryLow"),
    ]
    assert alarms[0]["error"]["errorDescription"] == "motor 2"
    assert alarms[1]["safety"] == {"eStop": "MANUAL", "fieldViolation": False}
    assert datetime.fromisoformat(alarms[2]["since"]) == first_seen
    assert datetime.fromisoformat(alarms[0]["since"]) == service.clock.now()
    assert (await client.get("/alarms", params={"manufacturer": "other"})).json() == []
    labels = f'{{manufacturer="{AGV.manufacturer}",serial_number="{AGV.serial_number}"}}'
    samples = parse_exposition((await client.get("/metrics")).text)
    assert samples[f"vda_master_vehicle_fatal_errors{labels}"] == 1
    assert samples[f"vda_master_vehicle_other_errors{labels}"] == 1
    assert samples[f"vda_master_vehicle_safety_stop{labels}"] == 1

    _feed(service, AGV, make_state(last_node_id="7"))
    assert (await client.get("/alarms")).json() == []
    broken = Connection.model_validate({**HEADER, "connection_state": "CONNECTIONBROKEN"})
    _feed(service, AGV, broken)
    [lost] = (await client.get("/alarms")).json()
    assert (lost["kind"], lost["connection"]) == (
        "connection",
        {"connectionState": "CONNECTIONBROKEN"},
    )
    _feed(service, AGV, _online())
    assert (await client.get("/alarms")).json() == []
    samples = parse_exposition((await client.get("/metrics")).text)
    assert samples[f"vda_master_vehicle_other_errors{labels}"] == 0
    assert samples[f"vda_master_vehicle_safety_stop{labels}"] == 0
