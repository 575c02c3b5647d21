"""Operator events for simulated vehicles over HTTP (``--control-port``; off by default).

What a real robot's stack reports on its own (:mod:`vda_vehicle.vehicle_status`), a test of a
master control needs to cause on a simulated vehicle: an operator switching it to MANUAL and
back, an emergency stop pressed and released, a protective field violated. This small API
sets them, vehicle by vehicle, through the same seam a real stack uses
(:meth:`vda_vehicle.runtime.VehicleRuntime.on_stack_status`):

- ``GET /vehicles``: every vehicle of the process with its status, order and last node;
- ``GET /vehicles/{serialNumber}``: one of them (404 if unknown);
- ``PATCH /vehicles/{serialNumber}/status`` with any of ``operatingMode`` (AUTOMATIC,
  SEMIAUTOMATIC, MANUAL, SERVICE, TEACHIN), ``eStop`` (AUTOACK, MANUAL, REMOTE, NONE) and
  ``fieldViolation``: what is left out stays; the answer is the vehicle as it is now. A bad
  value is a 422 naming the field;
- ``PUT /vehicles/{serialNumber}/pose`` with ``x``, ``y`` and optionally ``theta`` and
  ``mapId``: an operator pushes the vehicle there, in MANUAL only (409 in any other mode): a
  robot moved by hand, which a master control has to cope with (where it stands, what it may
  hold); a 3.0 vehicle moved away from its last node reports lastNodeId "" (T62).

Not VDA 5050 (the standard has no way to do this over MQTT), so it lives on its own port,
listens on loopback by default, and requires ``control_key`` (``Authorization: Bearer``) to
listen on any other address. Imported only when the port is set: the vehicles' start-up does
not pay for FastAPI.
"""

from __future__ import annotations

import contextlib
import hmac
from collections.abc import Iterator, Mapping, Sequence
from typing import Annotated

import uvicorn
from fastapi import Depends, FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field
from pydantic.alias_generators import to_camel

from vda5050.errors import ConfigError
from vda5050.models import EStop
from vda5050.models.base import Angle
from vda5050.net import bind_problem, is_loopback
from vda_vehicle.model import Pose, RobotMode
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.vehicle_status import StackStatus, status_of

_BEARER = "bearer "


class _Camel(BaseModel):
    model_config = ConfigDict(alias_generator=to_camel, populate_by_name=True, extra="forbid")


class StatusChange(_Camel):
    """What to change; a field left out keeps its value."""

    operating_mode: RobotMode | None = None
    e_stop: EStop | None = None
    field_violation: bool | None = None


FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]


class PoseChange(_Camel):
    """Where an operator pushes the vehicle (map coordinates, metres and radians)."""

    x: FiniteFloat
    y: FiniteFloat
    theta: Angle | None = None
    map_id: Annotated[str, Field(min_length=1)] | None = None


class VehicleView(_Camel):
    """One simulated vehicle as the control API shows it."""

    serial_number: str
    operating_mode: RobotMode
    e_stop: EStop
    field_violation: bool
    order_id: str
    last_node_id: str
    driving: bool
    x: float
    y: float
    theta: float
    map_id: str


def check_control_exposure(host: str, key: str | None) -> None:
    """Secure by default: no key-less control API on an address other machines reach."""
    if key or is_loopback(host):
        return
    msg = (
        f"the vehicle control API would listen on {host} without a key: set control_key "
        "(VDA_CONTROL_KEY) or listen on 127.0.0.1"
    )
    raise ConfigError(msg)


def create_control_app(runtimes: Sequence[VehicleRuntime], *, key: str | None = None) -> FastAPI:
    """The control API over ``runtimes`` (see the module docstring)."""
    expected = key.encode() if key else None

    def authorized(request: Request) -> None:
        if expected is None:
            return
        header = request.headers.get("authorization", "")
        presented = header[len(_BEARER) :] if header.lower().startswith(_BEARER) else ""
        if not hmac.compare_digest(presented.encode(), expected):
            raise HTTPException(401, "this control API needs 'Authorization: Bearer <key>'")

    app = FastAPI(
        title="vda-vehicle control",
        summary="operator events for simulated vehicles (not VDA 5050)",
        dependencies=[Depends(authorized)],
    )
    app.add_exception_handler(RequestValidationError, _invalid)  # type: ignore[arg-type]
    _add_routes(app, {runtime.agv.serial_number: runtime for runtime in runtimes})
    return app


async def _invalid(_: Request, exc: RequestValidationError) -> JSONResponse:
    """422 naming each bad field, without echoing the input (a NaN cannot be written as JSON:
    FastAPI's own answer would fail on it)."""
    detail = [
        {"loc": list(error.get("loc", ())), "msg": error.get("msg", ""), "type": error.get("type")}
        for error in exc.errors()
    ]
    return JSONResponse({"detail": detail}, status_code=422)


def _add_routes(app: FastAPI, by_serial: Mapping[str, VehicleRuntime]) -> None:
    def vehicle(serial_number: str) -> VehicleRuntime:
        runtime = by_serial.get(serial_number)
        if runtime is None:
            raise HTTPException(404, f"no vehicle {serial_number!r} in this process")
        return runtime

    @app.get("/vehicles", response_model_by_alias=True)
    async def list_vehicles() -> list[VehicleView]:
        return [view_of(runtime) for runtime in by_serial.values()]

    @app.get("/vehicles/{serial_number}", response_model_by_alias=True)
    async def get_vehicle(serial_number: str) -> VehicleView:
        return view_of(vehicle(serial_number))

    @app.patch("/vehicles/{serial_number}/status", response_model_by_alias=True)
    async def change_status(serial_number: str, change: StatusChange) -> VehicleView:
        runtime = vehicle(serial_number)
        runtime.on_stack_status(changed(status_of(runtime.state), change))
        return view_of(runtime)

    @app.put("/vehicles/{serial_number}/pose", response_model_by_alias=True)
    async def move(serial_number: str, change: PoseChange) -> VehicleView:
        runtime = vehicle(serial_number)
        refusal = runtime.move_by_hand(moved_to(runtime.state.pose, change))
        if refusal is not None:
            raise HTTPException(409, f"vehicle {serial_number!r} cannot be moved: {refusal}")
        return view_of(runtime)


def changed(status: StackStatus, change: StatusChange) -> StackStatus:
    """``status`` with what ``change`` sets."""
    return StackStatus(
        operating_mode=change.operating_mode or status.operating_mode,
        e_stop=change.e_stop or status.e_stop,
        field_violation=(
            status.field_violation if change.field_violation is None else change.field_violation
        ),
    )


def moved_to(pose: Pose, change: PoseChange) -> Pose:
    """``pose`` with what ``change`` sets (theta and mapId stay unless given)."""
    theta = pose.theta if change.theta is None else change.theta
    return Pose(change.x, change.y, theta, change.map_id or pose.map_id)


def view_of(runtime: VehicleRuntime) -> VehicleView:
    state = runtime.state
    return VehicleView(
        serial_number=runtime.agv.serial_number,
        operating_mode=state.operating_mode,
        e_stop=state.e_stop,
        field_violation=state.field_violation,
        order_id=state.order_id,
        last_node_id=state.last_node_id,
        driving=state.driving,
        x=state.pose.x,
        y=state.pose.y,
        theta=state.pose.theta,
        map_id=state.pose.map_id,
    )


class ControlServer:
    """The control API served by uvicorn on the vehicles' event loop until :meth:`close`."""

    def __init__(
        self, runtimes: Sequence[VehicleRuntime], *, host: str, port: int, key: str | None
    ) -> None:
        check_control_exposure(host, key)
        problem = bind_problem(host, port)
        if problem is not None:
            msg = f"cannot listen on {host}:{port} for the control API: {problem}"
            raise ConfigError(msg)
        config = uvicorn.Config(
            create_control_app(runtimes, key=key),
            host=host,
            port=port,
            log_config=None,
            access_log=False,
            lifespan="off",
        )
        self._server = _EmbeddedServer(config)

    @property
    def port(self) -> int | None:
        """The port it really listens on (useful with port 0), once started."""
        for server in getattr(self._server, "servers", ()):
            for sock in server.sockets:
                port: int = sock.getsockname()[1]
                return port
        return None

    async def serve(self) -> None:
        """Serve until :meth:`close`; the listening sockets are closed in every case."""
        try:
            await self._server.serve()
        finally:
            for server in getattr(self._server, "servers", ()):
                server.close()
                await server.wait_closed()

    def close(self) -> None:
        self._server.should_exit = True


class _EmbeddedServer(uvicorn.Server):
    """uvicorn without its own signal handling: the vehicle process's handlers decide."""

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        yield
