"""Request and answer bodies of the master HTTP API (architecture §3.4): camelCase JSON."""

from __future__ import annotations

import unicodedata
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, JsonValue, field_validator, model_validator
from pydantic.alias_generators import to_camel

from vda5050.models import BlockingType, ConnectionState, OperatingMode
from vda5050.topics import AgvId
from vda_master.capabilities import ActionSpec
from vda_master.dispatcher import OrderStatus
from vda_master.planner import Target, target_problem
from vda_master.requests import OrderRequest
from vda_master.stops import MAX_STOPS, Stop, repeated_stop


class ApiModel(BaseModel):
    model_config = ConfigDict(
        alias_generator=to_camel,
        validate_by_name=True,
        validate_by_alias=True,
        serialize_by_alias=True,
        extra="forbid",
    )


class Parameter(ApiModel):
    key: Annotated[str, Field(min_length=1, max_length=256)]
    value: JsonValue


class ActionRequest(ApiModel):
    """An action to send; blockingType defaults to a sensible one the vehicle allows."""

    action_type: Annotated[str, Field(min_length=1, max_length=256)]
    blocking_type: BlockingType | None = None
    action_parameters: list[Parameter] = Field(default_factory=list, max_length=100)

    def spec(self) -> ActionSpec:
        return ActionSpec(
            self.action_type, self.blocking_type, {p.key: p.value for p in self.action_parameters}
        )


#: What ``CreateOrder``'s validator enforces, said in its JSON schema too, so that a request
#: valid by the OpenAPI document is one the master takes (architecture §3.4): exactly one of
#: destination, route, stationType and stops (not null; stops carry their own actions), and
#: manufacturer and serialNumber both or neither.
_CREATE_ORDER_RULES: dict[str, JsonValue] = {
    "allOf": [
        {
            "oneOf": [
                {"required": ["destination"], "properties": {"destination": {"type": "string"}}},
                {"required": ["route"], "properties": {"route": {"type": "array"}}},
                {"required": ["stationType"], "properties": {"stationType": {"type": "string"}}},
                {
                    "required": ["stops"],
                    "properties": {
                        "stops": {"type": "array"},
                        "destinationActions": {"type": "array", "maxItems": 0},
                    },
                },
            ]
        },
        {
            "anyOf": [
                {
                    "required": ["manufacturer", "serialNumber"],
                    "properties": {
                        "manufacturer": {"type": "string"},
                        "serialNumber": {"type": "string"},
                    },
                },
                {
                    "properties": {
                        "manufacturer": {"type": "null"},
                        "serialNumber": {"type": "null"},
                    }
                },
            ]
        },
    ]
}


ONE_TARGET = "give exactly one of destination, route, stationType and stops"


class StopRequest(ApiModel):
    """One stop of an order with ``stops``: a node, or the nearest node of a stationType (from
    the stop before it), and the actions to do there."""

    model_config = ConfigDict(
        json_schema_extra={
            "oneOf": [
                {"required": ["destination"], "properties": {"destination": {"type": "string"}}},
                {"required": ["stationType"], "properties": {"stationType": {"type": "string"}}},
            ]
        }
    )

    destination: str | None = Field(default=None, description="nodeId of the stop")
    station_type: str | None = Field(
        default=None,
        description="the nearest node of this stationType: for the first stop the one the "
        "vehicle is expected at first, counting traffic; for a later one, from the stop before",
    )
    actions: list[ActionRequest] = Field(
        default_factory=list, max_length=100, description="node actions at the stop"
    )

    def stop(self) -> Stop:
        return Stop(self.destination, self.station_type, tuple(a.spec() for a in self.actions))

    @model_validator(mode="after")
    def _one_place(self) -> StopRequest:
        if (self.destination is None) == (self.station_type is None):
            msg = "give each stop exactly one of destination and stationType"
            raise ValueError(msg)
        return self


class CreateOrder(ApiModel):
    """Exactly one of ``destination``, ``route``, ``stationType`` and ``stops``; no vehicle
    named = the master picks one."""

    model_config = ConfigDict(json_schema_extra=_CREATE_ORDER_RULES)

    manufacturer: str | None = None
    serial_number: str | None = None
    destination: str | None = Field(default=None, description="nodeId to drive to")
    route: list[str] | None = Field(
        default=None, max_length=10_000, description="edgeIds to drive, in order"
    )
    station_type: str | None = Field(
        default=None,
        description=(
            "drive to a node of this stationType (e.g. drop): the one the vehicle is expected "
            "at first, counting traffic"
        ),
    )
    destination_actions: list[ActionRequest] = Field(
        default_factory=list,
        max_length=100,
        description="node actions at the last node (e.g. pick, drop)",
    )
    stops: list[StopRequest] | None = Field(
        default=None,
        min_length=1,
        max_length=MAX_STOPS,
        description="one order that drives to each stop in turn and does its actions there "
        "(e.g. pick at one, drop at the next); the vehicle is chosen for the first stop",
    )
    queue: bool = Field(
        default=False,
        description="when no vehicle can take the order now, keep it (202, status QUEUED) and "
        "send it once one can, instead of answering 409",
    )
    priority: Annotated[int, Field(ge=-1_000_000, le=1_000_000)] = Field(
        default=0,
        description="among queued orders, higher goes first; equal ones first come, first served",
    )
    queue_timeout_s: Annotated[float, Field(gt=0, le=30 * 24 * 3600)] | None = Field(
        default=None,
        description="a queued order that no vehicle has taken after this many (simulated) "
        "seconds ends FAILED, saying why it waited; none: it waits as long as it takes",
    )

    def to_request(self) -> OrderRequest:
        """What master control is asked to do."""
        agv = None
        if self.manufacturer is not None and self.serial_number is not None:
            agv = AgvId(self.manufacturer, self.serial_number)
        onward: tuple[Stop, ...] = ()
        if self.stops:
            first, *rest = (stop.stop() for stop in self.stops)
            target = Target(destination=first.destination, station_type=first.station_type)
            actions, onward = first.actions, tuple(rest)
        else:
            route = tuple(self.route) if self.route is not None else None
            target = Target(
                destination=self.destination, route=route, station_type=self.station_type
            )
            actions = tuple(a.spec() for a in self.destination_actions)
        return OrderRequest(
            target,
            agv,
            actions,
            queue=self.queue,
            priority=self.priority,
            queue_timeout_s=self.queue_timeout_s,
            onward=onward,
        )

    @model_validator(mode="after")
    def _one_target(self) -> CreateOrder:
        if self.stops is not None:
            if any(t is not None for t in (self.destination, self.route, self.station_type)):
                raise ValueError(ONE_TARGET)
            if self.destination_actions:
                msg = "with stops, give each stop its actions (not destinationActions)"
                raise ValueError(msg)
            repeated = repeated_stop([stop.stop() for stop in self.stops])
            if repeated is not None:
                raise ValueError(repeated)
        elif target_problem(self.destination, self.route, self.station_type) is not None:
            raise ValueError(ONE_TARGET)
        if (self.manufacturer is None) != (self.serial_number is None):
            msg = "give both manufacturer and serialNumber, or neither"
            raise ValueError(msg)
        return self


class ChangeOrder(ApiModel):
    """``PATCH /orders/{orderId}``: what may change of an order that waits for a vehicle."""

    priority: Annotated[int, Field(ge=-1_000_000, le=1_000_000)] = Field(
        description="its new priority among the queued orders (higher goes first)"
    )


#: Longest note on why a vehicle is out of service.
MAX_SERVICE_NOTE = 500


class ChangeVehicle(ApiModel):
    """``PATCH /vehicles/{manufacturer}/{serialNumber}``: take a vehicle out of service, or put
    it back."""

    in_service: bool = Field(
        description="false: master control sends it no order (none it chooses, none asked for "
        "by name: 409, or queued with queue: true) until it is put back with true"
    )
    note: Annotated[str, Field(max_length=MAX_SERVICE_NOTE)] = Field(
        default="",
        description="why it is out of service (shown with it); ignored when putting it back",
    )

    @field_validator("note")
    @classmethod
    def _printable(cls, note: str) -> str:
        """One line of text: a control character (a NUL, a line break) would not show, and
        PostgreSQL stores no NUL."""
        bad = next((c for c in note if unicodedata.category(c) == "Cc"), None)
        if bad is not None:
            msg = f"control character {bad!r} in note: give one line of text"
            raise ValueError(msg)
        return note.strip()


#: Most orders one ``POST /orders/batch`` may carry.
MAX_BATCH_ORDERS = 1000


class CreateOrders(ApiModel):
    """Orders to create in one request, in this order, each as ``POST /orders`` would."""

    orders: Annotated[list[CreateOrder], Field(min_length=1, max_length=MAX_BATCH_ORDERS)]


class InstantActionsRequest(ApiModel):
    actions: Annotated[list[ActionRequest], Field(min_length=1, max_length=1000)]


class ActionIds(ApiModel):
    action_ids: list[str]


#: Most actions one ``POST /vehicles/instantActions`` sends to each vehicle.
MAX_FLEET_ACTIONS = 20


class FleetInstantActionsRequest(ApiModel):
    """``POST /vehicles/instantActions``: the same instant actions to every vehicle, or to
    every vehicle of one manufacturer (a whole fleet paused at once)."""

    actions: Annotated[list[ActionRequest], Field(min_length=1, max_length=MAX_FLEET_ACTIONS)]
    manufacturer: str | None = Field(
        default=None, description="only this manufacturer's vehicles (default: every vehicle)"
    )


class FleetActionOutcome(ApiModel):
    """One vehicle's share: ``status`` 202 with the ``actionIds`` sent to it, or the status
    ``POST /vehicles/{manufacturer}/{serialNumber}/instantActions`` would have answered (409,
    422) with its ``detail``."""

    manufacturer: str
    serial_number: str
    status: int
    action_ids: list[str] | None = None
    detail: str | None = None


class FleetActionOutcomes(ApiModel):
    sent: int = Field(description="how many vehicles the actions were sent to")
    results: list[FleetActionOutcome] = Field(
        description="one per vehicle, by manufacturer and serial number"
    )


class MapSelection(ApiModel):
    """``POST /maps/{mapId}/{mapVersion}/enable``: which vehicles (default: every one)."""

    manufacturer: str | None = Field(
        default=None, description="only this manufacturer's vehicles (default: every vehicle)"
    )
    serial_numbers: Annotated[list[str], Field(min_length=1, max_length=10_000)] | None = Field(
        default=None, description="only these vehicles (of ``manufacturer``, if given)"
    )


class MapDistribution(MapSelection):
    """``POST /maps/{mapId}/{mapVersion}/distribute``."""

    enable: bool = Field(
        default=False,
        description="enable the version on each vehicle once it has downloaded it (at once "
        "where it holds it DISABLED already)",
    )


class MapHolder(ApiModel):
    manufacturer: str
    serial_number: str
    map_status: str = Field(description="ENABLED or DISABLED, as the vehicle's state lists it")


class MapInfo(ApiModel):
    """A map version stored on master control (its file, served to the vehicles) or held by a
    vehicle, with every vehicle that holds it."""

    map_id: str
    map_version: str
    stored: bool = Field(description="master control holds its file and can distribute it")
    size_bytes: int | None
    sha256: str | None = Field(description="sent to the vehicles as mapHash")
    uploaded: str | None = Field(description="when its file was uploaded (UTC)")
    vehicles: list[MapHolder]
    enabling_after_download: list[str] = Field(
        description="vehicles (manufacturer/serialNumber) downloading it, to be sent enableMap "
        "once they hold it"
    )


class BrokerProblem(ApiModel):
    kind: str = Field(description="subscribe_denied or publish_denied")
    topic: str = Field(description="the subscription filter, or the topic published on")
    description: str


class BrokerHealth(ApiModel):
    connected: bool
    problems: list[BrokerProblem] = Field(
        description="what the broker refuses the master (its ACL, probably); empty when all is well"
    )


class Health(ApiModel):
    status: str
    vehicles: int
    available_vehicles: int = Field(
        description="vehicles that could take an order now (GET /vehicles: available)"
    )
    active_orders: int
    queued_orders: int = Field(default=0, description="orders waiting for a vehicle")
    broker: BrokerHealth | None = None


class VehicleSummary(ApiModel):
    manufacturer: str
    serial_number: str
    version: str | None
    connection_state: ConnectionState | None
    hibernating: bool = Field(
        default=False,
        description="3.0 HIBERNATING (connectionState then reads OFFLINE); wake it with the "
        "instant action stopHibernation",
    )
    operating_mode: OperatingMode | None
    intervened: bool = Field(
        default=False,
        description="3.0 INTERVENED (operatingMode then reads MANUAL): an operator steers, the "
        "order is kept, and only cancelOrder is sent",
    )
    reported_operating_mode: str | None = Field(
        default=None,
        description="the operatingMode in the vehicle's own version's words: for a 3.0 robot "
        "STARTUP, INTERVENED or TEACH_IN where operatingMode reads SERVICE, MANUAL or TEACHIN "
        "(the 2.x terms every vehicle is judged by); otherwise the same as operatingMode",
    )
    order_id: str | None
    last_node_id: str | None
    driving: bool | None
    battery_charge: float | None
    charging: bool | None = Field(
        default=None,
        description="batteryState.charging (VDA 5050 §6.8.2: send the instant action "
        "stopCharging before the vehicle's next order)",
    )
    loads: list[dict[str, JsonValue]] | None = Field(
        default=None,
        description="the loads the vehicle reports carrying (state.loads); null when it does "
        "not report them. A pick goes to a vehicle with a free load position, a drop to one "
        "that carries the load",
    )
    load_types: list[str] | None = Field(
        default=None,
        description="the load types its factsheet's loadSets take; a pick or drop naming "
        "another loadType is not sent to it. null: its factsheet lists no load sets (or none "
        "is known), and it is refused no load type",
    )
    maps: list[dict[str, str]] | None = Field(
        default=None,
        description="the map versions it holds (state.maps, 2.1 and 3.0: mapId, mapVersion, "
        "mapStatus); null when it lists none. An order goes to it only on a map it has ENABLED",
    )
    reachable: bool
    last_state_age_s: float
    active_order_id: str | None
    in_service: bool = Field(
        default=True,
        description="false: an operator took it out of service (PATCH this vehicle); master "
        "control sends it no order until it is put back",
    )
    out_of_service_since: str | None = Field(
        default=None, description="when it was taken out of service (UTC)"
    )
    out_of_service_note: str | None = Field(
        default=None, description="the operator's note on why it is out of service"
    )
    available: bool = Field(
        description="in service, ONLINE, AUTOMATIC, reachable, no FATAL error, idle, not "
        "charging, and its next order can be planned from where it stands"
    )
    unavailable_reason: str | None = None
    has_factsheet: bool = Field(description="a valid factsheet narrows what the vehicle is sent")
    factsheet_problem: str | None = Field(
        default=None, description="why the last factsheet received was not used"
    )


class VehicleDetail(VehicleSummary):
    state: dict[str, JsonValue] | None
    factsheet: dict[str, JsonValue] | None


class OrderCreated(ApiModel):
    order_id: str
    manufacturer: str
    serial_number: str
    destination: str = Field(description="the node the order ends at (its last node)")
    order: dict[str, JsonValue]


class OrderQueued(ApiModel):
    """``POST /orders`` with ``queue: true`` that no vehicle could take now (202)."""

    order_id: str
    status: OrderStatus = Field(description="QUEUED")
    manufacturer: str | None = Field(description="the vehicle asked for; null: any will do")
    serial_number: str | None
    priority: int
    queue_position: int = Field(description="1 goes next")
    reason: str = Field(description="why no vehicle could take it now")


class BatchOutcome(ApiModel):
    """One order of a batch: ``status`` 201 with the fields of :class:`OrderCreated`, 202 with
    those of :class:`OrderQueued`, or the status ``POST /orders`` would have answered (404,
    409, 422) with its ``detail``."""

    status: int
    order_id: str | None = None
    manufacturer: str | None = None
    serial_number: str | None = None
    destination: str | None = None
    order: dict[str, JsonValue] | None = None
    priority: int | None = None
    queue_position: int | None = None
    reason: str | None = None
    detail: str | None = None


class OrdersCreated(ApiModel):
    results: list[BatchOutcome] = Field(description="one per requested order, in its place")


class OrderInfo(ApiModel):
    order_id: str
    status: OrderStatus
    created_at: str = Field(description="when the order was created (UTC, ISO 8601)")
    manufacturer: str | None = Field(
        description="its vehicle; null only for a queued order that any vehicle may take"
    )
    serial_number: str | None
    reason: str | None
    order_update_id: int
    confirmed_order_update_id: int | None
    node_ids: list[str]
    edge_ids: list[str]
    released_node_ids: list[str]
    cancel_action_id: str | None
    waiting_for: list[str] = Field(
        default_factory=list, description="vehicles this order's vehicle waits for in traffic"
    )
    waiting_at: str | None = Field(default=None, description="the node it waits on")
    waited_s: float | None = Field(default=None, description="how long it has waited so far")
    expected_finish_at: str | None = Field(
        default=None,
        description="when master control expects the order to finish (UTC, ISO 8601): the way "
        "left at the vehicle's speed and the pace and dwell learned from earlier orders; null "
        "once it ended and while it waits in the queue",
    )
    note: str | None = Field(
        default=None, description="why master control created the order itself (traffic)"
    )
    priority: int | None = Field(
        default=None, description="a queued order's priority (asked with queue: true)"
    )
    queue_position: int | None = Field(
        default=None, description="while QUEUED, where it stands in the queue (1 goes next)"
    )
    stops_ahead: list[dict[str, JsonValue]] = Field(
        default_factory=list,
        description="an order asked for with stops: those after the last of nodeIds, not yet "
        "appended to it ({destination or stationType, actions}), in order",
    )
