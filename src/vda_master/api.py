"""The master HTTP API (architecture §3.4): JSON with camelCase keys, OpenAPI at ``/docs``.

The handlers only translate between HTTP and :class:`vda_master.service.MasterService`; every
answer other than 2xx carries ``{"detail": "<what is wrong>"}`` (:mod:`vda_master.api_errors`).
``/docs`` serves Swagger UI from the ``swagger-ui-bundle`` package: nothing loads from the
internet (factories are often offline).
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Annotated, Any, Protocol

import orjson
from fastapi import Depends, FastAPI, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse, PlainTextResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import JsonValue
from starlette.exceptions import HTTPException
from swagger_ui_bundle import swagger_ui_path

from vda5050.access import AccessProblem
from vda5050.clock import format_timestamp
from vda5050.codec import encode
from vda5050.graph_file import GraphZone
from vda5050.models import Order, WireModel
from vda5050.topics import AgvId
from vda_master.alarms import alarm_document
from vda_master.api_auth import Role, api_keys
from vda_master.api_documents import (
    Document,
    any_order_document,
    queued_answer,
    vehicle_document,
    zones_document,
)
from vda_master.api_errors import (
    BodyLimitMiddleware,
    UploadLimit,
    error,
    error_responses,
    http_error,
    invalid_request,
)
from vda_master.api_fast import FastOrderPost, ShortRoute
from vda_master.api_maps import MAPS_PREFIX, add_map_routes
from vda_master.api_models import (
    ActionIds,
    BrokerHealth,
    BrokerProblem,
    ChangeOrder,
    ChangeVehicle,
    CreateOrder,
    CreateOrders,
    FleetActionOutcome,
    FleetActionOutcomes,
    FleetInstantActionsRequest,
    Health,
    InstantActionsRequest,
    OrderCreated,
    OrderInfo,
    OrderQueued,
    OrdersCreated,
    VehicleDetail,
    VehicleSummary,
)
from vda_master.dispatcher import OrderStatus, OrderTrack
from vda_master.metrics import CONTENT_TYPE
from vda_master.monitoring import metrics_text
from vda_master.queue_rules import QueuedOrder
from vda_master.requests import RequestError
from vda_master.service import MasterService
from vda_master.store import OrderRecord, StoreError
from vda_master.web import add_map

DOCS_ASSETS = "/docs/assets"
#: ``POST /orders/batch`` gives the event loop back after every this many orders: a batch of a
#: thousand would otherwise hold it for a few hundred milliseconds.
BATCH_STEP = 25


class BrokerStatus(Protocol):
    """The master's MQTT connection as /health reports it (:class:`vda5050.mqtt.MqttSession`)."""

    @property
    def connected(self) -> bool: ...
    @property
    def access_problems(self) -> tuple[AccessProblem, ...]: ...


def _wire(model: WireModel) -> dict[str, object]:
    """A wire model as the JSON object that goes over MQTT."""
    loaded: dict[str, object] = orjson.loads(encode(model))
    return loaded


def create_app(
    service: MasterService, broker: BrokerStatus | None = None, *, short_post: bool = True
) -> FastAPI:
    """The FastAPI application over ``service``; /health reports ``broker`` when given.
    ``short_post=False`` leaves every ``POST /orders`` to FastAPI (:mod:`vda_master.api_fast`;
    the tests compare both ways)."""
    app = FastAPI(
        title="vda-master",
        description="VDA 5050 master control",
        version="0.1.0",
        docs_url=None,
        redoc_url=None,
    )

    async def _refused(_: Request, exc: Exception) -> Response:
        response = _refusal(exc)
        if response is None:  # only registered for the two classes _refusal answers
            raise exc
        return response

    app.add_exception_handler(RequestError, _refused)
    app.add_exception_handler(StoreError, _refused)
    app.add_exception_handler(RequestValidationError, invalid_request)  # type: ignore[arg-type]
    app.add_exception_handler(HTTPException, http_error)  # type: ignore[arg-type]
    access = _access(service)
    if short_post:
        keys = api_keys(service.config)
        route = ShortRoute(
            path="/orders",
            model=CreateOrder,
            authorized=lambda request: keys.allows(request, Role.OPERATOR),
            handle=lambda body: _create_order(service, body),
            refusal=_refusal,
        )
        app.add_middleware(FastOrderPost[CreateOrder], route=route)
    upload = UploadLimit(MAPS_PREFIX, service.config.max_map_bytes, "max_map_bytes")
    app.add_middleware(  # outside
        BodyLimitMiddleware, max_bytes=service.config.max_body_bytes, upload=upload
    )
    _add_docs(app)
    _add_routes(app, service, broker, access)
    _add_alarm_routes(app, service, access)
    # The page and its assets hold no data; its live stream needs a viewer key.
    add_map(app, service, stream_dependencies=access.reads)
    return app


def _refusal(exc: Exception) -> Response | None:
    """The answer to a refusal raised while handling a request: master control's (with its
    status) or the store's (503); None for anything else."""
    if isinstance(exc, RequestError):
        response = error(exc.status, exc.message)
        if exc.status == 401:  # noqa: PLR2004 - HTTP status
            response.headers["WWW-Authenticate"] = "Bearer"
        return response
    if isinstance(exc, StoreError):
        return error(503, f"the order store is unavailable: {exc}")
    return None


def _add_docs(app: FastAPI) -> None:
    """Swagger UI from the installed package, no CDN."""
    app.mount(DOCS_ASSETS, StaticFiles(directory=str(swagger_ui_path)), name="docs-assets")

    @app.get("/docs", include_in_schema=False)
    async def docs() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=app.openapi_url or "/openapi.json",
            title=f"{app.title} API",
            swagger_js_url=f"{DOCS_ASSETS}/swagger-ui-bundle.js",
            swagger_css_url=f"{DOCS_ASSETS}/swagger-ui.css",
            swagger_favicon_url=f"{DOCS_ASSETS}/favicon-32x32.png",
        )


@dataclass(frozen=True, slots=True)
class _Access:
    """Route dependencies: ``reads`` needs a viewer key, ``acts`` an operator key (when keys
    are configured, :mod:`vda_master.api_auth`)."""

    reads: list[Any]
    acts: list[Any]


def _access(service: MasterService) -> _Access:
    keys = api_keys(service.config)

    async def viewer(request: Request) -> None:
        keys.require(request, Role.VIEWER)

    async def operator(request: Request) -> None:
        keys.require(request, Role.OPERATOR)

    return _Access([Depends(viewer)], [Depends(operator)])


# The handlers are coroutines although they never await: FastAPI runs plain functions in a worker
# thread, and the service (and the MQTT outbox) belong to the event loop's thread.


def _add_alarm_routes(app: FastAPI, service: MasterService, access: _Access) -> None:
    @app.get("/alarms", dependencies=access.reads, responses=error_responses(401))
    async def alarms(manufacturer: str | None = None) -> list[dict[str, JsonValue]]:
        """What is wrong with the fleet now: every error a vehicle lists, every stopped safety
        chain (e-stop, protective field) and every broken connection, most severe first
        (FATAL, connection, safety, a 3.0 robot's CRITICAL and URGENT, WARNING), each with
        the time master control first saw it (docs/master.md, *Webhooks*)."""
        return [alarm_document(a) for a in service.alarms.board.alarms(manufacturer)]


def _add_routes(
    app: FastAPI, service: MasterService, broker: BrokerStatus | None, access: _Access
) -> None:

    @app.get("/health")
    async def health() -> Health:
        now = service.clock.monotonic()
        return Health(
            status="ok",
            vehicles=len(service.fleet),
            available_vehicles=sum(
                service.availability(vehicle, now) is None for vehicle in service.fleet
            ),
            active_orders=len(service.active),
            queued_orders=len(service.queue),
            broker=_broker_health(broker) if broker is not None else None,
        )

    @app.get(
        "/metrics",
        dependencies=access.reads,
        responses=error_responses(401),
        response_class=PlainTextResponse,
    )
    async def metrics() -> PlainTextResponse:
        """Master control's figures in the Prometheus text format (0.0.4): vehicles by
        connection, availability, battery, charging, errors and safety stops per vehicle, active
        orders, traffic waits and deadlocks, and counters of messages received, dropped,
        published and resent, orders created and ended, and order confirmation times."""
        return PlainTextResponse(metrics_text(service), media_type=CONTENT_TYPE)

    @app.get("/traffic", dependencies=access.reads, responses=error_responses(401))
    async def traffic() -> dict[str, JsonValue]:
        """Per vehicle: held resources, the route still waiting for release, whom it waits for
        and for how long; deadlocks resolved so far (docs/traffic.md)."""
        snapshot = service.coordinator.snapshot(service.clock.monotonic()).as_json()
        return {"enabled": service.coordinator.enabled, **snapshot}

    @app.get("/zones", dependencies=access.reads, responses=error_responses(401))
    async def zones() -> list[dict[str, object]]:
        """The zones in force (the graph file's and those added here; ``source`` says which),
        each with what it does to the graph: the edges a BLOCKED zone closes and the nodes
        inside it, the edges a SPEED_LIMIT zone slows down."""
        return zones_document(service.graph, service, service)

    @app.post(
        "/zones",
        status_code=201,
        dependencies=access.acts,
        responses=error_responses(401, 403, 409, 413, 415, 422, 503),
    )
    async def add_zone(body: GraphZone) -> dict[str, object]:
        """Put a zone in force now, kept across restarts: routes, traffic control and the
        orders sent honour it at once; running orders whose way it closes are re-routed, or
        stopped when their released base leads in (docs/master.md, Zones)."""
        await service.add_zone(body)
        return _zone_document(service, body.zone_id)

    @app.get(
        "/zones/{zone_id:path}", dependencies=access.reads, responses=error_responses(401, 404)
    )
    async def zone(zone_id: str) -> dict[str, object]:
        """One zone in force, as ``GET /zones`` lists it."""
        return _zone_document(service, zone_id)

    @app.put(
        "/zones/{zone_id:path}",
        dependencies=access.acts,
        responses=error_responses(401, 403, 404, 409, 413, 415, 422, 503),
    )
    async def change_zone(zone_id: str, body: GraphZone) -> dict[str, object]:
        """Change a zone added through ``POST /zones`` in one step (a spill that grew): its
        area never opens in between. The body's ``zoneId`` is the path's."""
        if body.zone_id != zone_id:
            msg = f"the body's zoneId {body.zone_id!r} is not the path's {zone_id!r}"
            raise RequestError(422, msg)
        await service.replace_zone(body)
        return _zone_document(service, zone_id)

    @app.delete(
        "/zones/{zone_id:path}",
        status_code=204,
        dependencies=access.acts,
        responses=error_responses(401, 403, 404, 409, 503),
    )
    async def remove_zone(zone_id: str) -> Response:
        """Lift a zone added through ``POST /zones`` (the graph file's own stay)."""
        await service.remove_zone(zone_id)
        return Response(status_code=204)

    _add_vehicle_routes(app, service, access)
    _add_order_routes(app, service, access)
    add_map_routes(app, service, access.reads, access.acts)


def _zone_document(service: MasterService, zone_id: str) -> dict[str, object]:
    found = [z for z in zones_document(service.graph, service, service) if z["zoneId"] == zone_id]
    if not found:
        raise RequestError(404, f"no zone {zone_id!r}")
    return found[0]


def _add_vehicle_routes(app: FastAPI, service: MasterService, access: _Access) -> None:
    @app.get(
        "/vehicles",
        response_model=list[VehicleSummary],
        dependencies=access.reads,
        responses=error_responses(401),
    )
    async def vehicles() -> Response:
        return _json_list([vehicle_document(service, v) for v in service.fleet])

    @app.get(
        "/vehicles/{manufacturer}/{serial_number}",
        dependencies=access.reads,
        responses=error_responses(401, 404),
    )
    async def vehicle(manufacturer: str, serial_number: str) -> VehicleDetail:
        view = service.known_vehicle(AgvId(manufacturer, serial_number))
        return VehicleDetail.model_validate(
            {
                **vehicle_document(service, view),
                "state": _wire(view.state) if view.state else None,
                "factsheet": _wire(view.factsheet) if view.factsheet else None,
            }
        )

    @app.post(
        "/vehicles/instantActions",
        dependencies=access.acts,
        responses=error_responses(401, 403, 404, 413, 415, 422),
    )
    async def fleet_instant_actions(body: FleetInstantActionsRequest) -> FleetActionOutcomes:
        """The same instant actions to every vehicle, or to every vehicle of ``manufacturer``:
        a whole fleet paused (``startPause``) and resumed (``stopPause``) at once. Each vehicle
        is checked as by its own ``instantActions`` endpoint; one that may not take them now
        (offline, not in a mode master control drives in, an action its factsheet lacks) is
        listed with the status and detail that endpoint would answer, and the others are sent
        theirs all the same."""
        specs = [a.spec() for a in body.actions]
        outcomes = service.send_fleet_instant_actions(specs, body.manufacturer)
        results = [_fleet_outcome(agv, outcome) for agv, outcome in outcomes]
        sent = sum(result.status == 202 for result in results)  # noqa: PLR2004 - HTTP status
        return FleetActionOutcomes(sent=sent, results=results)

    @app.patch(
        "/vehicles/{manufacturer}/{serial_number}",
        dependencies=access.acts,
        responses=error_responses(401, 403, 404, 413, 415, 422, 503),
    )
    async def change_vehicle(
        manufacturer: str, serial_number: str, body: ChangeVehicle
    ) -> VehicleSummary:
        """Take the vehicle out of service (``inService: false``, with a ``note`` saying why)
        or put it back (``true``); kept across restarts. Out of service, it takes no order:
        none master control chooses (no transport, no charging, no move out of the way) and
        none asked for by name (409; with ``queue: true`` the order waits until it is back).
        An order it runs now runs to its end; instant actions still go to it."""
        agv = AgvId(manufacturer, serial_number)
        view = await service.set_in_service(agv, in_service=body.in_service, note=body.note)
        return VehicleSummary.model_validate(vehicle_document(service, view))

    @app.post(
        "/vehicles/{manufacturer}/{serial_number}/instantActions",
        status_code=202,
        dependencies=access.acts,
        responses=error_responses(401, 403, 404, 409, 413, 415, 422),
    )
    async def instant_actions(
        manufacturer: str, serial_number: str, body: InstantActionsRequest
    ) -> ActionIds:
        specs = [a.spec() for a in body.actions]
        ids = service.send_instant_actions(AgvId(manufacturer, serial_number), specs)
        return ActionIds(action_ids=ids)


def _fleet_outcome(agv: AgvId, outcome: list[str] | RequestError) -> FleetActionOutcome:
    """One vehicle's entry of ``POST /vehicles/instantActions``."""
    if isinstance(outcome, RequestError):
        status, action_ids, detail = outcome.status, None, outcome.message
    else:
        status, action_ids, detail = 202, outcome, None
    return FleetActionOutcome(
        manufacturer=agv.manufacturer,
        serial_number=agv.serial_number,
        status=status,
        action_ids=action_ids,
        detail=detail,
    )


def _add_order_routes(app: FastAPI, service: MasterService, access: _Access) -> None:
    @app.post(
        "/orders",
        status_code=201,
        response_model=OrderCreated,
        dependencies=access.acts,
        responses={
            202: {
                "model": OrderQueued,
                "description": "asked with queue: true and no vehicle can take it now: it "
                "waits (status QUEUED) and is sent once one can",
            },
            **error_responses(401, 403, 404, 409, 413, 415, 422),
        },
    )
    async def create_order(body: CreateOrder) -> Response:
        # Reached by what FastOrderPost leaves to FastAPI (no docstring: it would become the
        # operation's description in the OpenAPI document).
        return await _create_order(service, body)

    @app.post(
        "/orders/batch",
        response_model=OrdersCreated,
        dependencies=access.acts,
        responses=error_responses(401, 403, 413, 415, 422),
    )
    async def create_orders(body: CreateOrders) -> Response:
        """Many orders in one request (a wave of transports from a WMS): each is created in
        turn exactly as ``POST /orders`` would, so an order without a vehicle sees the vehicles
        the earlier ones took. One that cannot be created gets the status and detail that
        ``POST /orders`` would have answered; the others are created all the same. The answer
        comes once all are written ahead."""
        outcomes = await _create_in_turn(service, body.orders)
        parts = [_batch_outcome(service, outcome) for outcome in outcomes]
        created = [o for o in outcomes if not isinstance(o, RequestError)]
        await asyncio.gather(*(service.committed(order.order_id) for order in created))
        return Response(b'{"results":[' + b",".join(parts) + b"]}", media_type="application/json")

    @app.get(
        "/orders",
        response_model=list[OrderInfo],
        dependencies=access.reads,
        responses=error_responses(401, 422, 503),
    )
    async def orders(
        status: OrderStatus | None = None,
        manufacturer: str | None = None,
        serial_number: Annotated[str | None, Query(alias="serialNumber")] = None,
        limit: Annotated[int, Query(ge=1, le=10_000)] = 100,
    ) -> Response:
        """Orders newest first, this run's and earlier runs' (kept ``orderRetentionDays``)."""
        found = await service.find_orders(
            status=status, manufacturer=manufacturer, serial_number=serial_number, limit=limit
        )
        return _json_list([any_order_document(service, order) for order in found])

    @app.get(
        "/orders/{order_id}", dependencies=access.reads, responses=error_responses(401, 404, 503)
    )
    async def order(order_id: str) -> OrderInfo:
        return OrderInfo.model_validate(
            any_order_document(service, await _found(service, order_id))
        )

    @app.get(
        "/orders/{order_id}/events",
        dependencies=access.reads,
        responses=error_responses(401, 404, 503),
    )
    async def order_events(order_id: str) -> list[dict[str, JsonValue]]:
        """The order's history, oldest first: queued (asked with queue: true and no vehicle
        free), created, published (headerId, orderUpdateId), accepted, node_passed, waiting,
        wait_ended, replanned, cancel_requested, status_changed, recovered, reconciled; kept
        across restarts."""
        await _found(service, order_id)
        history = await service.order_history(order_id)
        if history is None:
            raise RequestError(503, "master control runs without a store: no history is kept")
        return [{"time": format_timestamp(e.time), "event": e.event, **e.details} for e in history]

    @app.delete(
        "/orders/{order_id}",
        status_code=202,
        dependencies=access.acts,
        responses=error_responses(401, 403, 404, 409),
    )
    async def cancel(order_id: str) -> OrderInfo:
        return OrderInfo.model_validate(any_order_document(service, service.cancel_order(order_id)))

    @app.patch(
        "/orders/{order_id}",
        dependencies=access.acts,
        responses=error_responses(401, 403, 404, 409, 422),
    )
    async def change_order(order_id: str, body: ChangeOrder) -> OrderInfo:
        """A queued order's priority (it moves in the queue); 409 once a vehicle took it."""
        await _found(service, order_id)
        changed = service.reprioritize_order(order_id, body.priority)
        return OrderInfo.model_validate(any_order_document(service, changed))


async def _create_order(service: MasterService, body: CreateOrder) -> Response:
    """``POST /orders``: create, write ahead, publish; the 201 answer (202 when it waits for
    a vehicle)."""
    track = service.place_order(body.to_request())
    if isinstance(track, QueuedOrder):
        queued = queued_answer(service, track)
        await service.committed(track.order_id)
        return Response(orjson.dumps(queued), status_code=202, media_type="application/json")
    await service.committed(track.order_id)  # written ahead, then published
    head = _created_head(track)
    body_bytes = _with_order(head, service.sent.get(track.order_id, track.message))
    return Response(body_bytes, status_code=201, media_type="application/json")


async def _create_in_turn(
    service: MasterService, orders: list[CreateOrder]
) -> list[OrderTrack | QueuedOrder | RequestError]:
    """Create ``orders`` one after the other; each one's track (or its place in the queue),
    or why it was not created."""
    outcomes: list[OrderTrack | QueuedOrder | RequestError] = []
    for index, item in enumerate(orders, start=1):
        try:
            outcomes.append(service.place_order(item.to_request()))
        except RequestError as exc:
            outcomes.append(exc)
        if index % BATCH_STEP == 0:  # let states in, and the first orders' write-ahead go
            await asyncio.sleep(0)
    return outcomes


def _created_head(track: OrderTrack, **more: object) -> bytes:
    agv = track.plan.agv
    return orjson.dumps(
        {
            **more,
            "orderId": track.order_id,
            "manufacturer": agv.manufacturer,
            "serialNumber": agv.serial_number,
            "destination": track.plan.destination,
        }
    )


def _with_order(head: bytes, sent: Order) -> bytes:
    """The :class:`OrderCreated` answer, rendered directly: the order as it went over MQTT is
    spliced in once encoded, instead of being decoded into a dict, validated as the answer
    model and encoded again (the burst of issue 12 pays for every POST)."""
    return b"".join((head[:-1], b',"order":', encode(sent), b"}"))


def _batch_outcome(
    service: MasterService, outcome: OrderTrack | QueuedOrder | RequestError
) -> bytes:
    """One entry of ``POST /orders/batch``'s ``results`` (:class:`BatchOutcome`)."""
    if isinstance(outcome, RequestError):
        return orjson.dumps({"status": outcome.status, "detail": outcome.message})
    if isinstance(outcome, QueuedOrder):
        queued = queued_answer(service, outcome)
        del queued["status"]  # the order's; the entry's is the HTTP one
        return orjson.dumps({"status": 202, **queued})
    head = _created_head(outcome, status=201)
    return _with_order(head, service.sent.get(outcome.order_id, outcome.message))


def _broker_health(broker: BrokerStatus) -> BrokerHealth:
    problems = [
        BrokerProblem(kind=p.kind.value, topic=p.topic, description=p.description)
        for p in broker.access_problems
    ]
    return BrokerHealth(connected=broker.connected, problems=problems)


async def _found(service: MasterService, order_id: str) -> OrderTrack | QueuedOrder | OrderRecord:
    order = await service.find_order(order_id)
    if order is None:
        raise RequestError(404, f"order {order_id!r} is unknown")
    return order


def _json_list(documents: list[Document]) -> Response:
    """A list endpoint's answer, rendered without models (vda_master.api_documents)."""
    return Response(orjson.dumps(documents), media_type="application/json")
