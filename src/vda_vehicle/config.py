"""Configuration of ``vda-vehicle`` (architecture §3.2, house style §3.8) and vehicle placement.

Every config key is also a command-line flag (generated from :class:`VehicleSettings` by
:mod:`vda5050.cli`) and an environment variable ``VDA_<KEY>``; precedence flag > environment >
config file > default (``vda5050.config.load_settings``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from pydantic import ConfigDict, Field

from vda5050.config import BrokerConnectionConfig
from vda5050.errors import ConfigError
from vda5050.graph_file import GraphFile, GraphNode
from vda5050.topics import default_interface_name
from vda_vehicle.action_catalog import default_catalog, for_version, with_durations
from vda_vehicle.capabilities import Capabilities, fields_for
from vda_vehicle.kinematics import Kinematic
from vda_vehicle.limits import extent_of
from vda_vehicle.model import Pose

#: Map of a vehicle started without a graph file.
DEFAULT_MAP = "map"


class VehicleSettings(BrokerConnectionConfig):
    """Every setting of a vehicle process. Units are in the names; times in seconds.

    The broker keys (``broker_url``, ``username``, ``password``, ``client_id``, ``qos``,
    ``keepalive_s`` (default 15, §6.14), ``clean_session``, ``connect_timeout_s``) come from
    :class:`vda5050.config.BrokerConnectionConfig`; ``client_id`` defaults to
    ``<interface>-<manufacturer>-<serial>`` and becomes a prefix with ``--count``.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    interface_name: str | None = Field(
        default=None,
        description="first topic level (default: uagv for 2.x, vda5050 for 3.x)",
    )
    manufacturer: str = Field(default="vda-sim", description="manufacturer (topic and header)")
    serial_number: str = Field(
        default="vehicle", description="serial number; with --count N: <S>-1 ... <S>-N"
    )
    vda_version: Literal["2.0.0", "2.1.0", "3.0.0"] = Field(
        default="2.1.0",
        description="protocol version the vehicle speaks (3.0.0: topics under v3, 3.0 payloads)",
    )
    graph: Path | None = Field(
        default=None,
        description="graph file the vehicles stand on; without one they stand 2 m apart on "
        "the x axis of map --map-id",
    )
    start_node: str | None = Field(
        default=None, description="node the (first) vehicle stands on (default: the first node)"
    )
    map_id: str | None = Field(
        default=None,
        description=f"map a vehicle without a graph stands on (default {DEFAULT_MAP!r}); with a "
        "graph it must be the graph's mapId",
    )
    count: Annotated[int, Field(ge=1, le=10_000)] = Field(
        default=1,
        description="vehicles in this process, each on its own graph node (there must be "
        "enough nodes)",
    )
    time_lapse: Annotated[float, Field(gt=0)] = Field(
        default=1.0,
        description="simulated seconds per wall second (speeds, actions, battery); the "
        "factsheet states speeds as seen in wall time (x time_lapse)",
    )
    tick_hz: Annotated[float, Field(gt=0, le=100)] = Field(
        default=5.0, description="simulation ticks per second; a tick's events share one state"
    )
    state_interval_s: Annotated[float, Field(gt=0, le=30)] = Field(
        default=30.0, description="state heartbeat without events, wall time (§6.10: <= 30 s)"
    )
    visualization_interval_s: Annotated[float, Field(ge=0)] = Field(
        default=1.0, description="visualization period; 0 disables visualization"
    )
    action_durations_s: dict[str, Annotated[float, Field(ge=0)]] = Field(
        default_factory=dict,
        description="simulated run seconds per actionType, e.g. {pick: 3.0}",
    )
    load_types: Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)] = Field(
        default_factory=lambda: ["EPAL"],
        description="load types the vehicle handles (a factsheet loadSet each); a pick or drop "
        "naming another loadType is rejected, e.g. [EPAL, KLT]",
    )
    kinematics: Kinematic = Field(
        default="OMNI",
        description="OMNI holds any edge orientation; DIFF (differential drive) drives along "
        "edges, forwards or backwards, and rejects an order whose edge orientation it cannot "
        "hold (R34)",
    )
    speed_max_mps: Annotated[float, Field(gt=0)] = Field(default=1.5, description="top speed")
    angular_speed_max_radps: Annotated[float, Field(gt=0)] = Field(
        default=1.0, description="top turning speed"
    )
    battery_drain_pct_per_m: Annotated[float, Field(ge=0)] = Field(
        default=0.05, description="battery used per metre driven"
    )
    battery_start_pct: Annotated[float, Field(ge=0, le=100)] = Field(
        default=100.0, description="the simulated battery's charge at start (%)"
    )
    battery_stop_pct: Annotated[float, Field(ge=0, le=90)] = Field(
        default=1.0,
        description="under this charge (%) the simulated vehicle stops driving and reports the "
        "FATAL error batteryLowError until it has charged 10 % above it (0: it never stops)",
    )
    charge_rate_pct_per_s: Annotated[float, Field(ge=0)] = Field(
        default=0.5, description="battery charged per simulated second while charging"
    )
    stop_between_nodes: bool = Field(
        default=False,
        description="on cancelOrder stop at once between nodes instead of finishing the edge "
        "on the next node (§6.6.3)",
    )
    control_port: Annotated[int, Field(ge=0, le=65535)] | None = Field(
        default=None,
        description="port of the HTTP API that sets a simulated vehicle's operatingMode and "
        "e-stop as an operator would (not VDA 5050; off when unset, 0: any free port)",
    )
    control_host: str = Field(default="127.0.0.1", description="address the control API listens on")
    control_key: str | None = Field(
        default=None,
        description="key the control API requires as 'Authorization: Bearer <key>' (needed to "
        "listen on an address other than loopback)",
    )
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = Field(
        default="INFO", description="log level"
    )

    @property
    def major_version(self) -> int:
        """The major of ``vda_version``: 2 or 3 (it selects the topic prefix and payloads)."""
        return int(self.vda_version.split(".", 1)[0])

    @property
    def speaks_v3(self) -> bool:
        """True for ``--vda-version 3.0.0`` (3.0 payloads under ``v3`` topics)."""
        return self.vda_version.startswith("3.")

    @property
    def topic_interface_name(self) -> str:
        """The interface name in use: the configured one, else the default of the major
        (``uagv`` for 2.x, ``vda5050`` for 3.x; 3.0 §4.2)."""
        return self.interface_name or default_interface_name(self.major_version)


@dataclass(frozen=True, slots=True)
class Placement:
    """Where one simulated vehicle starts: its pose and lastNodeId ("" without a graph)."""

    serial_number: str
    pose: Pose
    last_node_id: str


def load_graph(path: Path) -> GraphFile:
    """Read and validate a graph file; ConfigError with the reason otherwise."""
    try:
        return GraphFile.model_validate_json(path.read_bytes())
    except OSError as exc:
        msg = f"cannot read graph file {path}: {exc.strerror or exc}"
        raise ConfigError(msg) from None
    except ValueError as exc:
        msg = f"graph file {path} is invalid: {exc}"
        raise ConfigError(msg) from None


def serial_numbers(settings: VehicleSettings) -> list[str]:
    """``<S>`` for one vehicle, ``<S>-1`` … ``<S>-N`` for several (architecture §3.2)."""
    if settings.count == 1:
        return [settings.serial_number]
    return [f"{settings.serial_number}-{index}" for index in range(1, settings.count + 1)]


def placements(settings: VehicleSettings, graph: GraphFile | None) -> list[Placement]:
    """Each vehicle on its own graph node from the start node on (graph file order); without a
    graph they stand 2 m apart on the x axis of map ``map_id``. More vehicles than nodes is a
    ConfigError: two vehicles on one node would collide at once."""
    serials = serial_numbers(settings)
    if graph is None:
        map_id = settings.map_id or DEFAULT_MAP
        return [
            Placement(serial, Pose(2.0 * index, 0.0, 0.0, map_id), "")
            for index, serial in enumerate(serials)
        ]
    nodes = _nodes_from_start(graph, settings.start_node)
    if len(serials) > len(nodes):
        msg = (
            f"--count {len(serials)} needs {len(serials)} distinct nodes to place the vehicles, "
            f"but the graph {settings.graph} has {len(nodes)}; use a larger graph, fewer "
            "vehicles, or no graph (vehicles then stand 2 m apart on the x axis)"
        )
        raise ConfigError(msg)
    return [_placed(serial, nodes[index], graph.map_id) for index, serial in enumerate(serials)]


def _nodes_from_start(graph: GraphFile, start_node: str | None) -> list[GraphNode]:
    ids = [node.node_id for node in graph.nodes]
    if start_node is None:
        return list(graph.nodes)
    if start_node not in ids:
        msg = f"start node {start_node!r} is not in the graph"
        raise ConfigError(msg)
    first = ids.index(start_node)
    return [*graph.nodes[first:], *graph.nodes[:first]]


def _placed(serial: str, node: GraphNode, default_map: str) -> Placement:
    pose = Pose(node.x, node.y, node.theta or 0.0, node.map_id or default_map)
    return Placement(serial, pose, node.node_id)


def capabilities(settings: VehicleSettings, graph: GraphFile | None) -> Capabilities:
    """The vehicle's capabilities from its settings; it holds a map per mapId of its graph."""
    if graph is None:
        map_ids = frozenset({settings.map_id or DEFAULT_MAP})
    else:
        if settings.map_id is not None and settings.map_id != graph.map_id:
            msg = (
                f"map_id {settings.map_id!r} does not match the graph's mapId {graph.map_id!r}; "
                "leave --map-id out when a graph is given"
            )
            raise ConfigError(msg)
        map_ids = frozenset({graph.map_id} | {n.map_id for n in graph.nodes if n.map_id})
    try:
        catalog = with_durations(
            for_version(default_catalog(), settings.vda_version), settings.action_durations_s
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    extents = {}
    if graph is not None:
        for map_id in map_ids:
            extent = extent_of(
                (node.x, node.y) for node in graph.nodes if (node.map_id or graph.map_id) == map_id
            )
            if extent is not None:
                extents[map_id] = extent
    return Capabilities(
        map_ids=map_ids,
        map_extents=extents,
        catalog=catalog,
        supported_fields=fields_for(settings.vda_version),
        speed_max_mps=settings.speed_max_mps,
        angular_speed_max_radps=settings.angular_speed_max_radps,
        battery_drain_pct_per_m=settings.battery_drain_pct_per_m,
        battery_stop_pct=settings.battery_stop_pct,
        charge_rate_pct_per_s=settings.charge_rate_pct_per_s,
        stop_between_nodes=settings.stop_between_nodes,
        load_types=tuple(dict.fromkeys(settings.load_types)),
        kinematic=settings.kinematics,
    )
