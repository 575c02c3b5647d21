"""Configuration of ``vda-vehicle`` (architecture §3.2, house style §3.8) and vehicle placement.

Every command-line flag is also a config-file key and an environment variable ``VDA_<FLAG>``;
precedence flag > environment > config file > default (``vda5050.config.load_settings``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from pydantic import ConfigDict, Field

from vda5050.config import BrokerConnectionConfig
from vda5050.errors import ConfigError
from vda5050.graph_file import GraphFile, GraphNode
from vda_vehicle.action_catalog import default_catalog, with_durations
from vda_vehicle.capabilities import Capabilities
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

    interface_name: str = "uagv"
    manufacturer: str = "vda-sim"
    serial_number: str = "vehicle"
    vda_version: Literal["2.0.0", "2.1.0"] = "2.1.0"
    #: Graph file (architecture §3.3); without one the vehicle stands at (0, 0) on map "map".
    graph: Path | None = None
    #: Where the (first) vehicle stands; default: the graph's first node.
    start_node: str | None = None
    #: Vehicles in this process, serials <serial_number>-1 … -N (just <serial_number> for 1).
    count: Annotated[int, Field(ge=1, le=10_000)] = 1
    #: Simulated time runs this many times faster than wall time (speeds, actions, battery).
    time_lapse: Annotated[float, Field(gt=0)] = 1.0
    #: Simulation ticks per second; events of one tick share one state message.
    tick_hz: Annotated[float, Field(gt=0, le=100)] = 5.0
    #: Longest gap between two states without events (§6.10: at most 30 s). Wall time.
    state_interval_s: Annotated[float, Field(gt=0, le=30)] = 30.0
    #: Visualization period; 0 disables visualization.
    visualization_interval_s: Annotated[float, Field(ge=0)] = 1.0
    #: Run duration per actionType, e.g. {pick: 5.0}; simulated seconds.
    action_durations_s: dict[str, Annotated[float, Field(ge=0)]] = Field(default_factory=dict)
    speed_max_mps: Annotated[float, Field(gt=0)] = 1.5
    angular_speed_max_radps: Annotated[float, Field(gt=0)] = 1.0
    battery_drain_pct_per_m: Annotated[float, Field(ge=0)] = 0.05
    charge_rate_pct_per_s: Annotated[float, Field(ge=0)] = 0.5
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = "INFO"


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
    """Each vehicle on its own graph node from the start node on, where the graph has enough;
    without a graph they stand 2 m apart on the x axis of map ``map``."""
    serials = serial_numbers(settings)
    if graph is None:
        return [
            Placement(serial, Pose(2.0 * index, 0.0, 0.0, DEFAULT_MAP), "")
            for index, serial in enumerate(serials)
        ]
    nodes = _nodes_from_start(graph, settings.start_node)
    return [
        _placed(serial, nodes[index % len(nodes)], graph.map_id)
        for index, serial in enumerate(serials)
    ]


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
        map_ids = frozenset({DEFAULT_MAP})
    else:
        map_ids = frozenset({graph.map_id} | {n.map_id for n in graph.nodes if n.map_id})
    try:
        catalog = with_durations(default_catalog(), settings.action_durations_s)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    return Capabilities(
        map_ids=map_ids,
        catalog=catalog,
        speed_max_mps=settings.speed_max_mps,
        angular_speed_max_radps=settings.angular_speed_max_radps,
        battery_drain_pct_per_m=settings.battery_drain_pct_per_m,
        charge_rate_pct_per_s=settings.charge_rate_pct_per_s,
    )
