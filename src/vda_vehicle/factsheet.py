"""The factsheet of the simulated vehicle (§6.15; 2.0 §6.16), built from its Capabilities.

Everything declared here comes from the same tables the vehicle checks orders against, so the
factsheet is complete and truthful (R110, R111): every action with its scopes, parameters and
blocking types, every optional order field it acts on, its limits and timing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata
from typing import TypeVar, cast

from vda5050.codec import EncodedBody
from vda5050.memo import IdentityMemo
from vda5050.models import Factsheet, WireModel
from vda5050.models.factsheet import (
    AgvAction,
    AgvActionParameter,
    AgvClass,
    AgvGeometry,
    AgvKinematic,
    Envelope2d,
    LoadSet,
    LoadSpecification,
    MaxArrayLens,
    MaxStringLens,
    OptionalParameter,
    PhysicalParameters,
    PolygonPoint,
    ProtocolFeatures,
    ProtocolLimits,
    Support,
    Timing,
    TypeSpecification,
    VehicleConfig,
    VersionInfo,
    WheelDefinition,
    WheelPosition,
    WheelType,
)
from vda_vehicle.actions import ActionSpec
from vda_vehicle.capabilities import FIELD_NOTES, REQUIRED_FIELDS, Capabilities
from vda_vehicle.faults import MAX_ERRORS
from vda_vehicle.reporter import PLACEHOLDER_HEADER

T = TypeVar("T")
#: The load handling device of the simulated vehicle (pick/drop ``lhd``, state ``loadPosition``).
LOAD_POSITION = "front"


@dataclass(frozen=True, slots=True)
class FactsheetTiming:
    """Seconds. min_state_interval is one tick: events of a tick share one state (R94).

    ``time_lapse``: a simulation running F times faster moves F times faster in the wall time
    master control plans in, so the factsheet's speeds are F times (accelerations F² times) the
    simulated ones; at 1 they are the simulated vehicle's own.
    """

    min_state_interval_s: float
    state_interval_s: float
    visualization_interval_s: float
    time_lapse: float = 1.0


#: How the factsheet's seriesDescription names each kinematic.
_DRIVES = {"OMNI": "omnidirectional", "DIFF": "differential-drive"}


def build_factsheet(caps: Capabilities, timing: FactsheetTiming, *, version: str) -> Factsheet:
    """The vehicle's factsheet; ``vehicleConfig`` and 2.1-only fields only for 2.1."""
    newer = version != "2.0.0"
    lapse = timing.time_lapse
    return Factsheet(
        **PLACEHOLDER_HEADER,
        type_specification=TypeSpecification(
            series_name="vda-sim",
            series_description=f"simulated {_DRIVES[caps.kinematic]} carrier of the vda5050-stack",
            agv_kinematic=AgvKinematic(caps.kinematic),
            agv_class=AgvClass.CARRIER,
            max_load_mass=500.0,
            localization_types=["NATURAL"],
            # The order's edges (straight, or along their trajectory), no own path planning:
            # no trajectories to report (R108).
            navigation_types=["VIRTUAL_LINE_GUIDED"],
        ),
        physical_parameters=PhysicalParameters(
            speed_min=0.0,
            speed_max=caps.speed_max_mps * lapse,
            angular_speed_min=0.0 if newer else None,
            angular_speed_max=caps.angular_speed_max_radps * lapse if newer else None,
            acceleration_max=1.0 * lapse**2,
            deceleration_max=1.0 * lapse**2,
            height_min=caps.height_m,
            height_max=caps.height_m,
            width=caps.width_m,
            length=caps.length_m,
        ),
        protocol_limits=_limits(caps, timing),
        protocol_features=ProtocolFeatures(
            optional_parameters=_optional_parameters(caps),
            agv_actions=[_agv_action(spec, newer=newer) for spec in caps.catalog.values()],
        ),
        agv_geometry=_geometry(caps),
        load_specification=LoadSpecification(
            load_positions=[LOAD_POSITION],
            load_sets=[
                LoadSet(
                    set_name=load_type,
                    load_type=load_type,
                    load_positions=[LOAD_POSITION],
                    max_weight=500.0,
                )
                for load_type in caps.load_types
            ],
        ),
        vehicle_config=_vehicle_config() if newer else None,
    )


def _limits(caps: Capabilities, timing: FactsheetTiming) -> ProtocolLimits:
    """§6.15 protocolLimits; 0 or absent means no explicit limit."""
    limits = caps.limits
    return ProtocolLimits(
        max_string_lens=MaxStringLens(
            msg_len=limits.msg_len,
            topic_serial_len=limits.topic_serial_len,
            topic_elem_len=limits.topic_elem_len,
            id_len=limits.id_len,
            id_numerical_only=False,
            enum_len=limits.enum_len,
            load_id_len=limits.load_id_len,
        ),
        max_array_lens=MaxArrayLens.model_validate(
            {
                "order.nodes": limits.order_nodes,
                "order.edges": limits.order_edges,
                "node.actions": limits.node_actions,
                "edge.actions": limits.edge_actions,
                "actions.actionsParameters": limits.actions_parameters,
                "instantActions": limits.instant_actions,
                "trajectory.knotVector": limits.trajectory_knot_vector,
                "trajectory.controlPoints": limits.trajectory_control_points,
                "state.errors": MAX_ERRORS,
            }
        ),
        timing=Timing(
            min_order_interval=timing.min_state_interval_s,
            min_state_interval=timing.min_state_interval_s,
            default_state_interval=timing.state_interval_s,
            visualization_interval=timing.visualization_interval_s or None,
        ),
    )


def _optional_parameters(caps: Capabilities) -> list[OptionalParameter]:
    return [
        OptionalParameter(
            parameter=path,
            support=Support.REQUIRED if path in REQUIRED_FIELDS else Support.SUPPORTED,
            description=FIELD_NOTES.get(path),
        )
        for path in sorted(caps.supported_fields)
    ]


def _agv_action(spec: ActionSpec, *, newer: bool) -> AgvAction:
    return AgvAction(
        action_type=spec.action_type,
        action_description=spec.description,
        action_scopes=sorted(spec.scopes),
        action_parameters=[
            AgvActionParameter(
                key=parameter.key,
                value_data_type=parameter.value_type,
                description=parameter.description,
                is_optional=parameter.optional,
            )
            for parameter in spec.parameters
        ]
        or None,
        result_description=spec.result_description,
        blocking_types=sorted(spec.blocking_types) if newer else None,
    )


def _geometry(caps: Capabilities) -> AgvGeometry:
    half_length, half_width = caps.length_m / 2, caps.width_m / 2
    corners = [(half_length, half_width), (-half_length, half_width)]
    corners += [(-half_length, -half_width), (half_length, -half_width)]
    wheels = [
        WheelDefinition(
            type=WheelType.MECANUM,
            is_active_driven=True,
            is_active_steered=False,
            position=WheelPosition(x=x * 0.8, y=y * 0.8),
            diameter=0.2,
            width=0.08,
        )
        for x, y in corners
    ]
    return AgvGeometry(
        wheel_definitions=wheels,
        envelopes2d=[
            Envelope2d(
                set="default",
                polygon_points=[PolygonPoint(x=x, y=y) for x, y in corners],
                description="vehicle outline without load",
            )
        ],
    )


def _vehicle_config() -> VehicleConfig:
    try:
        software = metadata.version("vda5050-stack")
    except metadata.PackageNotFoundError:
        software = "source checkout"
    return VehicleConfig(versions=[VersionInfo(key="vda5050-stack", value=software)])


class SharedFactsheets:
    """What a builder (:func:`build_factsheet`, the 3.0 one) returns, built once per
    capabilities object, timing and version: the vehicles of one process share their
    capabilities, and a factsheet is ~150 immutable objects (400 µs to build; a thousand
    vehicles connecting at once built a thousand alike). The builders are pure, so this is
    only a memo; the capabilities are compared by identity (they are not hashable)."""

    def __init__(self) -> None:
        self._built: IdentityMemo[object] = IdentityMemo(limit=16)

    def get(
        self, caps: Capabilities, timing: FactsheetTiming, version: str, build: Callable[[], T]
    ) -> T:
        """The memo of ``build()`` (which builds the factsheet of these three)."""
        return cast("T", self._built.get(caps, (timing, version), build))

    def body(
        self,
        caps: Capabilities,
        timing: FactsheetTiming,
        version: str,
        build: Callable[[], WireModel],
    ) -> EncodedBody:
        """That factsheet encoded without its header, once for all the vehicles that share it
        (each stamps its own header in front: ``HeaderStamper.encode_body``)."""
        return cast(
            "EncodedBody",
            self._built.get(
                caps,
                (timing, version, EncodedBody),
                lambda: EncodedBody.of(self.get(caps, timing, version, build)),
            ),
        )


#: The factsheets of this process's vehicles (see :class:`SharedFactsheets`).
SHARED_FACTSHEETS = SharedFactsheets()
