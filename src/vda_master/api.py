"""The master HTTP API (architecture §3.4): JSON with camelCase keys, OpenAPI at ``/docs``.

The handlers only translate between HTTP and :class:`vda_master.service.MasterService`; every
answer other than 2xx carries ``{"detail": "<what is wrong>"}``.
"""

from __future__ import annotations

from typing import Annotated

import orjson
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field, JsonValue, model_validator
from pydantic.alias_generators import to_camel

from vda5050.codec import encode
from vda5050.models import BlockingType, ConnectionState, OperatingMode, WireModel
from vda5050.topics import AgvId
from vda_master.capabilities import ActionSpec
from vda_master.dispatcher import OrderStatus, OrderTrack
from vda_master.fleet import VehicleView, is_unreachable, silence_s, unavailable_reason
from vda_master.planner import Target
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService


class ApiModel(BaseModel):
    model_config = ConfigDict(
        alias_generator=to_camel,
        validate_by_name=True,
        validate_by_alias=True,
        serialize_by_alias=True,
        extra="forbid",
    )


class Parameter(ApiModel):
    key: Annotated[str, Field(min_length=1)]
    value: JsonValue


class ActionRequest(ApiModel):
    """An action to send; blockingType defaults to a sensible one the vehicle allows."""

    action_type: Annotated[str, Field(min_length=1)]
    blocking_type: BlockingType | None = None
    action_parameters: list[Parameter] = Field(default_factory=list)

    def spec(self) -> ActionSpec:
        return ActionSpec(
            self.action_type, self.blocking_type, {p.key: p.value for p in self.action_parameters}
        )


class CreateOrder(ApiModel):
    """Exactly one of ``destination`` and ``route``; no vehicle named = the master picks one."""

    manufacturer: str | None = None
    serial_number: str | None = None
    destination: str | None = Field(default=None, description="nodeId to drive to")
    route: list[str] | None = Field(default=None, description="edgeIds to drive, in order")
    destination_actions: list[ActionRequest] = Field(
        default_factory=list, description="node actions at the last node (e.g. pick, drop)"
    )

    @model_validator(mode="after")
    def _one_target(self) -> CreateOrder:
        if (self.destination is None) == (self.route is None):
            msg = "give exactly one of destination and route"
            raise ValueError(msg)
        if (self.manufacturer is None) != (self.serial_number is None):
            msg = "give both manufacturer and serialNumber, or neither"
            raise ValueError(msg)
        return self


class InstantActionsRequest(ApiModel):
    actions: Annotated[list[ActionRequest], Field(min_length=1)]


class ActionIds(ApiModel):
    action_ids: list[str]


class Health(ApiModel):
    status: str
    vehicles: int
    active_orders: int


class VehicleSummary(ApiModel):
    manufacturer: str
    serial_number: str
    version: str | None
    connection_state: ConnectionState | None
    operating_mode: OperatingMode | None
    order_id: str | None
    last_node_id: str | None
    driving: bool | None
    battery_charge: float | None
    reachable: bool
    last_state_age_s: float
    active_order_id: str | None
    available: bool = Field(description="ONLINE, AUTOMATIC, reachable, no FATAL error, idle")
    unavailable_reason: str | None = None


class VehicleDetail(VehicleSummary):
    state: dict[str, JsonValue] | None
    factsheet: dict[str, JsonValue] | None


class OrderCreated(ApiModel):
    order_id: str
    manufacturer: str
    serial_number: str
    order: dict[str, JsonValue]


class OrderInfo(ApiModel):
    order_id: str
    status: OrderStatus
    manufacturer: str
    serial_number: str
    reason: str | None
    order_update_id: int
    confirmed_order_update_id: int | None
    node_ids: list[str]
    edge_ids: list[str]
    released_node_ids: list[str]
    cancel_action_id: str | None


def _wire(model: WireModel) -> dict[str, JsonValue]:
    """A wire model as the JSON object that goes over MQTT."""
    loaded: dict[str, JsonValue] = orjson.loads(encode(model))
    return loaded


def create_app(service: MasterService) -> FastAPI:
    """The FastAPI application over ``service``."""
    app = FastAPI(title="vda-master", description="VDA 5050 master control", version="0.1.0")

    @app.exception_handler(RequestError)
    async def _request_error(_: Request, exc: RequestError) -> JSONResponse:
        return JSONResponse({"detail": exc.message}, status_code=exc.status)

    @app.exception_handler(RequestValidationError)
    async def _invalid(_: Request, exc: RequestValidationError) -> JSONResponse:
        return JSONResponse({"detail": _validation_message(exc)}, status_code=422)

    _add_routes(app, service)
    return app


def _validation_message(exc: RequestValidationError) -> str:
    parts = []
    for error in exc.errors():
        where = ".".join(str(p) for p in error.get("loc", ()) if p != "body")
        message = str(error.get("msg", "invalid")).removeprefix("Value error, ")
        parts.append(f"{where}: {message}" if where else message)
    return "; ".join(parts)


def _add_routes(app: FastAPI, service: MasterService) -> None:
    # The handlers are coroutines although they never await: FastAPI runs plain functions in a
    # worker thread, and the service (and the MQTT outbox) belong to the event loop's thread.
    @app.get("/health")
    async def health() -> Health:
        return Health(status="ok", vehicles=len(service.fleet), active_orders=len(service.active))

    @app.get("/vehicles")
    async def vehicles() -> list[VehicleSummary]:
        return [_summary(service, v) for v in service.fleet]

    @app.get("/vehicles/{manufacturer}/{serial_number}", responses={404: {}})
    async def vehicle(manufacturer: str, serial_number: str) -> VehicleDetail:
        view = service.known_vehicle(AgvId(manufacturer, serial_number))
        return VehicleDetail(
            **_summary(service, view).model_dump(),
            state=_wire(view.state) if view.state else None,
            factsheet=_wire(view.factsheet) if view.factsheet else None,
        )

    @app.post("/orders", status_code=201, responses={404: {}, 409: {}, 422: {}})
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

    @app.get("/orders/{order_id}", responses={404: {}})
    async def order(order_id: str) -> OrderInfo:
        return _order_info(service.known_order(order_id))

    @app.delete("/orders/{order_id}", status_code=202, responses={404: {}, 409: {}})
    async def cancel(order_id: str) -> OrderInfo:
        return _order_info(service.cancel_order(order_id))

    @app.post(
        "/vehicles/{manufacturer}/{serial_number}/instantActions",
        status_code=202,
        responses={404: {}, 409: {}, 422: {}},
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
    reason = unavailable_reason(vehicle, now, service.fleet_settings)
    if reason is None and vehicle.agv in service.active:
        reason = f"it runs order {service.active[vehicle.agv]}"
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
    )


def _order_info(track: OrderTrack) -> OrderInfo:
    plan = track.plan
    return OrderInfo(
        order_id=track.order_id,
        status=track.status,
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
