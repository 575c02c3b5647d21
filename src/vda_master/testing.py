"""Factories for master-control tests and tools: factsheets, graphs, ids."""

from __future__ import annotations

import itertools
import json
import math
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import orjson

from vda5050.codec import encode
from vda5050.models import (
    ActionState,
    ActionStatus,
    Connection,
    ConnectionState,
    EdgeState,
    Factsheet,
    NodeState,
    State,
)
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master import capabilities as caps
from vda_master.graph import Graph, build_graph, load_graph
from vda_master.order_builder import OrderPlan

#: The demo warehouse shipped in ``config/graphs/demo.json``.
DEMO_GRAPH = Path(__file__).resolve().parents[2] / "config" / "graphs" / "demo.json"

#: Every optional order field the master can fill in.
ALL_FIELDS = tuple(sorted(caps.FILLABLE_FIELDS))

#: A pick/drop declaration as a forklift would publish it (§6.8.1 pick/drop parameters).
LOAD_ACTIONS: tuple[dict[str, object], ...] = (
    {
        "actionType": "pick",
        "actionScopes": ["NODE"],
        "actionParameters": [
            {"key": "stationType", "valueDataType": "STRING", "isOptional": True},
            {"key": "stationName", "valueDataType": "STRING", "isOptional": True},
            {"key": "loadType", "valueDataType": "STRING", "isOptional": True},
        ],
    },
    {
        "actionType": "drop",
        "actionScopes": ["NODE"],
        "actionParameters": [
            {"key": "stationType", "valueDataType": "STRING", "isOptional": True},
            {"key": "stationName", "valueDataType": "STRING", "isOptional": True},
        ],
    },
    {"actionType": "cancelOrder", "actionScopes": ["INSTANT"]},
    {"actionType": "startPause", "actionScopes": ["INSTANT"]},
    {"actionType": "stopPause", "actionScopes": ["INSTANT"]},
    {"actionType": "startCharging", "actionScopes": ["INSTANT", "NODE"]},
)


def make_factsheet(
    *,
    supported: Iterable[str] = ALL_FIELDS,
    required: Iterable[str] = (),
    actions: Sequence[Mapping[str, object]] = LOAD_ACTIONS,
    array_lens: Mapping[str, int] | None = None,
    string_lens: Mapping[str, object] | None = None,
    min_order_interval: float = 0.0,
    default_state_interval: float | None = None,
    **header: object,
) -> Factsheet:
    """A valid factsheet declaring ``supported``/``required`` optional fields and ``actions``."""
    optional = [{"parameter": p, "support": "SUPPORTED"} for p in supported]
    optional += [{"parameter": p, "support": "REQUIRED"} for p in required]
    timing: dict[str, object] = {
        "minOrderInterval": min_order_interval,
        "minStateInterval": 0.1,
    }
    if default_state_interval is not None:
        timing["defaultStateInterval"] = default_state_interval
    return Factsheet.model_validate(
        {
            **HEADER,
            **header,
            "typeSpecification": {
                "seriesName": "test",
                "agvKinematic": "DIFF",
                "agvClass": "CARRIER",
                "maxLoadMass": 100,
                "localizationTypes": ["NATURAL"],
                "navigationTypes": ["AUTONOMOUS"],
            },
            "physicalParameters": {
                "speedMin": 0.01,
                "speedMax": 2.0,
                "accelerationMax": 1.0,
                "decelerationMax": 1.0,
                "heightMax": 0.5,
                "width": 0.8,
                "length": 1.2,
            },
            "protocolLimits": {
                "maxStringLens": dict(string_lens or {}),
                "maxArrayLens": dict(array_lens or {}),
                "timing": timing,
            },
            "protocolFeatures": {"optionalParameters": optional, "agvActions": list(actions)},
            "agvGeometry": {},
            "loadSpecification": {},
        }
    )


class RecordingPublisher:
    """A publisher that keeps every published (topic, payload), payloads built at once."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, bytes]] = []

    def publish(self, topic: str, kind: Topic, payload: bytes | Callable[[], bytes]) -> None:
        del kind
        self.sent.append((topic, payload() if callable(payload) else payload))

    def messages(self, topic: Topic) -> list[dict[str, Any]]:
        """The decoded JSON of every message published on ``topic``, oldest first."""
        return [orjson.loads(p) for t, p in self.sent if t.endswith("/" + topic.value)]

    def orders(self) -> list[dict[str, Any]]:
        return self.messages(Topic.ORDER)


def demo_graph() -> Graph:
    """The shipped demo warehouse graph."""
    return load_graph(DEMO_GRAPH)


def demo_graph_with_zones(*zones: Mapping[str, object]) -> Graph:
    """The demo warehouse graph with ``zones`` (graph-file JSON objects) added."""
    raw = json.loads(DEMO_GRAPH.read_text(encoding="utf-8"))
    return build_graph({**raw, "zones": list(zones)}, source=f"{DEMO_GRAPH} with zones")


def zone(
    zone_id: str, zone_type: str, vertices: list[list[float]], **more: object
) -> dict[str, object]:
    """A graph-file zone object."""
    return {
        "zoneId": zone_id,
        "zoneType": zone_type,
        "vertices": [{"x": x, "y": y} for x, y in vertices],
        **more,
    }


def line_graph(count: int, *, spacing_m: float = 2.0, map_id: str = "line") -> Graph:
    """Nodes ``n0``…``n<count-1>`` on the x axis joined by edges ``e<i>`` both ways."""
    nodes = [{"nodeId": f"n{i}", "x": spacing_m * i, "y": 0.0} for i in range(count)]
    edges = [
        {"edgeId": f"e{i}", "startNodeId": f"n{i}", "endNodeId": f"n{i + 1}"}
        for i in range(count - 1)
    ] + [
        {"edgeId": f"r{i}", "startNodeId": f"n{i + 1}", "endNodeId": f"n{i}"}
        for i in range(count - 1)
    ]
    return build_graph({"mapId": map_id, "nodes": nodes, "edges": edges}, source="line")


def quarter_circle(radius: float) -> dict[str, Any]:
    """A graph-file ``trajectory``: the quarter circle round the origin from (radius, 0) to
    (0, radius), as a rational degree 2 NURBS (exactly on the circle)."""
    return {
        "degree": 2,
        "knotVector": [0, 0, 0, 1, 1, 1],
        "controlPoints": [
            {"x": radius, "y": 0.0},
            {"x": radius, "y": radius, "weight": math.sqrt(2) / 2},
            {"x": 0.0, "y": radius},
        ],
    }


def id_source(prefix: str = "a") -> Iterator[str]:
    """``a1``, ``a2``, … for action ids in tests."""
    return (f"{prefix}{n}" for n in itertools.count(1))


def plan_state(
    plan: OrderPlan,
    *,
    update_id: int = 0,
    passed: int = 0,
    released_end: int | None = None,
    actions: Mapping[str, ActionStatus] | None = None,
    **fields: object,
) -> State:
    """The state of a vehicle running ``plan``: node ``passed`` is its last node, the nodes and
    edges after it are still to go, released up to node ``released_end`` (default: all)."""
    end = plan.last_index if released_end is None else released_end
    node_states = [
        NodeState(node_id=n.node_id, sequence_id=n.sequence_id, released=i <= end)
        for i, n in enumerate(plan.nodes)
        if i > passed
    ]
    edge_states = [
        EdgeState(edge_id=e.edge_id, sequence_id=e.sequence_id, released=i < end)
        for i, e in enumerate(plan.edges)
        if i >= passed
    ]
    statuses = dict.fromkeys(plan.action_ids(), ActionStatus.WAITING)
    statuses.update(actions or {})
    action_states = [ActionState(action_id=i, action_status=s) for i, s in statuses.items()]
    base: dict[str, object] = {
        "order_id": plan.order_id,
        "order_update_id": update_id,
        "last_node_id": plan.nodes[passed].node_id,
        "last_node_sequence_id": plan.nodes[passed].sequence_id,
        "node_states": node_states,
        "edge_states": edge_states,
        "action_states": action_states,
        "manufacturer": plan.agv.manufacturer,
        "serial_number": plan.agv.serial_number,
    }
    return make_state(**{**base, **fields})


class _Ingests(Protocol):
    def ingest(self, topic: str, payload: bytes) -> None: ...


def report_online(service: _Ingests, agv: AgvId, node_id: str) -> None:
    """``agv`` (2.x, interface ``uagv``) tells ``service`` it is ONLINE, its factsheet
    (:func:`make_factsheet`) and a state on ``node_id``."""
    online = Connection.model_validate({**HEADER, "connection_state": ConnectionState.ONLINE})
    identity = {"manufacturer": agv.manufacturer, "serial_number": agv.serial_number}
    for kind, message in (
        (Topic.CONNECTION, online),
        (Topic.FACTSHEET, make_factsheet()),
        (Topic.STATE, make_state(last_node_id=node_id)),
    ):
        stamped = message.model_copy(update=identity)
        service.ingest(build_topic("uagv", 2, agv, kind), encode(stamped))


_SAMPLE = re.compile(
    r'^(?P<name>[a-zA-Z_:][a-zA-Z0-9_:]*)(\{(?P<labels>([a-zA-Z_][a-zA-Z0-9_]*="(\\.|[^"\\])*",?)*)\})?'
    r" (?P<value>-?[0-9.e+-]+|NaN|[+-]Inf)$"
)


def parse_exposition(text: str) -> dict[str, float]:
    """Every sample of a Prometheus text exposition (0.0.4, ``GET /metrics``) as
    ``name{labels}`` → value; AssertionError on a line that is neither a comment nor a
    well-formed sample, on a sample of a family no ``# TYPE`` declared, or on a sample twice."""

    def check(condition: object, problem: str) -> None:
        if not condition:
            raise AssertionError(problem)

    check(text.endswith("\n"), "the text does not end with a line feed")
    types: dict[str, str] = {}
    samples: dict[str, float] = {}
    for line in text.splitlines():
        if line.startswith("# TYPE "):
            _, _, name, kind = line.split(" ")
            types[name] = kind
            continue
        if line.startswith("# HELP "):
            continue
        match = _SAMPLE.match(line)
        check(match, f"not a sample line: {line!r}")
        assert match is not None  # noqa: S101 - for the type checker; check() raised otherwise
        family = re.sub(r"_(bucket|sum|count)$", "", match["name"])
        declared = match["name"] in types or types.get(family) == "histogram"
        check(declared, f"no # TYPE for {line!r}")
        key = line.rsplit(" ", 1)[0]
        check(key not in samples, f"sample twice: {key}")
        samples[key] = float(match["value"])
    return samples
