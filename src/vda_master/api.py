"""The master HTTP API (architecture §3.4): JSON with camelCase keys, OpenAPI at ``/docs``.

The handlers only translate between HTTP and :class:`vda_master.service.MasterService`; every
answer other than 2xx carries ``{"detail": "<what is wrong>"}`` (:mod:`vda_master.api_errors`).
``/docs`` serves Swagger UI from the ``swagger-ui-bundle`` package: nothing loads from the
internet (factories are often offline).
"""

from __future__ import annotations

from typing import Annotated

import orjson
from fastapi import FastAPI, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from swagger_ui_bundle import swagger_ui_path

from vda5050.codec import encode
from vda5050.models import WireModel
from vda5050.topics import AgvId
from vda_master.api_errors import (
    BodyLimitMiddleware,
    error,
    error_responses,
    invalid_request,
)
from vda_master.api_models import (
    ActionIds,
    CreateOrder,
    Health,
    InstantActionsRequest,
    OrderCreated,
    OrderInfo,
    VehicleDetail,
    VehicleSummary,
)
from vda_master.dispatcher import OrderStatus, OrderTrack
from vda_master.fleet import VehicleView, is_unreachable, silence_s
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.web import add_map

DOCS_ASSETS = "/docs/assets"


def _wire(model: WireModel) -> dict[str, object]:
    """A wire model as the JSON object that goes over MQTT."""
    loaded: dict[str, object] = orjson.loads(encode(model))
    return loaded


def create_app(service: MasterService) -> FastAPI:
    """The FastAPI application over ``service``."""
    app = FastAPI(
        title="vda-master",
        description="VDA 5050 master control",
        version="0.1.0",
        docs_url=None,
        redoc_url=None,
    )

    @app.exception_handler(RequestError)
    async def _request_error(_: Request, exc: RequestError) -> JSONResponse:
        return error(exc.status, exc.message)

    app.add_exception_handler(RequestValidationError, invalid_request)  # type: ignore[arg-type]
    app.add_middleware(BodyLimitMiddleware, max_bytes=service.config.max_body_bytes)
    _add_docs(app)
    _add_routes(app, service)
    add_map(app, service)
    return app


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


def _add_routes(app: FastAPI, service: MasterService) -> None:
    # The handlers are coroutines although they never await: FastAPI runs plain functions in a
    # worker thread, and the service (and the MQTT outbox) belong to the event loop's thread.
    @app.get("/health")
    async def health() -> Health:
        return Health(status="ok", vehicles=len(service.fleet), active_orders=len(service.active))

    @app.get("/vehicles")
    async def vehicles() -> list[VehicleSummary]:
        return [_summary(service, v) for v in service.fleet]

    @app.get("/vehicles/{manufacturer}/{serial_number}", responses=error_responses(404))
    async def vehicle(manufacturer: str, serial_number: str) -> VehicleDetail:
        view = service.known_vehicle(AgvId(manufacturer, serial_number))
        return VehicleDetail(
            **_summary(service, view).model_dump(),
            state=_wire(view.state) if view.state else None,
            factsheet=_wire(view.factsheet) if view.factsheet else None,
        )

    @app.post("/orders", status_code=201, responses=error_responses(404, 409, 413, 415, 422))
    async def create_order(body: CreateOrder) -> OrderCreated:
        agv = None
        if body.manufacturer is not None and body.serial_number is not None:
            agv = AgvId(body.manufacturer, body.serial_number)
        route = tuple(body.route) if body.route is not None else None
        target = Target(destination=body.destination, route=route)
        actions = tuple(a.spec() for a in body.destination_actions)
        track = service.create_order(OrderRequest(target, agv, actions))
        sent = service.sent.get(track.order_id, track.message)
        return OrderCreated(
            order_id=track.order_id,
            manufacturer=track.plan.agv.manufacturer,
            serial_number=track.plan.agv.serial_number,
            order=_wire(sent),
        )

    @app.get("/orders", responses=error_responses(422))
    async def orders(
        status: OrderStatus | None = None,
        manufacturer: str | None = None,
        serial_number: Annotated[str | None, Query(alias="serialNumber")] = None,
        limit: Annotated[int, Query(ge=1, le=10_000)] = 100,
    ) -> list[OrderInfo]:
        tracks = service.list_orders(
            status=status, manufacturer=manufacturer, serial_number=serial_number, limit=limit
        )
        return [_order_info(track) for track in tracks]

    @app.get("/orders/{order_id}", responses=error_responses(404))
    async def order(order_id: str) -> OrderInfo:
        return _order_info(service.known_order(order_id))

    @app.delete("/orders/{order_id}", status_code=202, responses=error_responses(404, 409))
    async def cancel(order_id: str) -> OrderInfo:
        return _order_info(service.cancel_order(order_id))

    @app.post(
        "/vehicles/{manufacturer}/{serial_number}/instantActions",
        status_code=202,
        responses=error_responses(404, 409, 413, 415, 422),
    )
    async def instant_actions(
        manufacturer: str, serial_number: str, body: InstantActionsRequest
    ) -> ActionIds:
        specs = [a.spec() for a in body.actions]
        ids = service.send_instant_actions(AgvId(manufacturer, serial_number), specs)
        return ActionIds(action_ids=ids)


def _summary(service: MasterService, vehicle: VehicleView) -> VehicleSummary:
    now = service.clock.monotonic()
    state = vehicle.state
    reason = service.availability(vehicle, now)
    return VehicleSummary(
        manufacturer=vehicle.agv.manufacturer,
        serial_number=vehicle.agv.serial_number,
        version=vehicle.version,
        connection_state=vehicle.connection,
        operating_mode=state.operating_mode if state else None,
        order_id=state.order_id if state else None,
        last_node_id=state.last_node_id if state else None,
        driving=state.driving if state else None,
        battery_charge=state.battery_state.battery_charge if state else None,
        reachable=not is_unreachable(vehicle, now, service.fleet_settings),
        last_state_age_s=round(silence_s(vehicle, now), 3),
        active_order_id=service.active.get(vehicle.agv),
        available=reason is None,
        unavailable_reason=reason,
        has_factsheet=vehicle.factsheet is not None,
        factsheet_problem=vehicle.factsheet_problem,
    )


def _order_info(track: OrderTrack) -> OrderInfo:
    plan = track.plan
    return OrderInfo(
        order_id=track.order_id,
        status=track.status,
        created_at=track.created_utc,
        manufacturer=plan.agv.manufacturer,
        serial_number=plan.agv.serial_number,
        reason=track.reason or None,
        order_update_id=track.update_id,
        confirmed_order_update_id=track.confirmed_update_id,
        node_ids=[n.node_id for n in plan.nodes],
        edge_ids=[e.edge_id for e in plan.edges],
        released_node_ids=[n.node_id for n in plan.nodes[: track.released_end + 1]],
        cancel_action_id=track.cancel_action_id,
    )
