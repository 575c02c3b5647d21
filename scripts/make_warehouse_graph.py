# ruff: noqa: INP001 - a stand-alone script, not a package
"""Generate ``config/graphs/warehouse.json``: a warehouse for traffic-control tests and demos.

Run from the repository root: ``python scripts/make_warehouse_graph.py [--output FILE]``. The
output is deterministic; the file in the repository is this script's output.

Layout (metres; y grows northwards)::

    P1  P2  P3  DR2 P4  P5  P6  DR4                parking spurs, drop bays (north of the ring)
    NO ←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←  north outer lane, westbound   y = 29
    NI →→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→  north inner lane, eastbound   y = 26
    ↓↑  A6  B6  C6  D6  E6  F6  G6  H6          ↑↓
    WO  ┃   ┃   ┃   ┃   ┃   ┃   ┃   ┃           EI EO → CH1..CH3 charger spurs (east)
    WI  A1  B1  C1… one-lane aisles A–H,         ↑↓
    ↓↑  positions at y = 7 … 22, each with a     ↑↓
        passing place beside position 4 (Ap … Hp)
    SI ←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←←  south inner lane, westbound   y = 3
    SO →→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→→  south outer lane, eastbound   y = 0
         ↓ ↗             ↓ ↗
         DQ1 DX1         DQ3 DX3
         DQ1b→DR1        DQ3b→DR3                  drive-through drop bays (south of the ring)

- **Two-way main corridors**: a ring road of two one-way lanes 3 m apart (further than the
  safety distance of 1.69 m for the simulated 1.2 m × 0.8 m vehicles, so the lanes never
  conflict): the outer lane runs counter-clockwise, the inner lane clockwise.
- **One-lane aisles** A–H, 4 m apart, between the south and the north corridor: edges both ways
  along one line (opposite edges conflict), so vehicles cannot pass each other inside an aisle
  but at its **passing place**: in the middle of each aisle, the way north leaves the aisle's
  line at position 3 for a node 2 m east of it (``Ap`` for aisle A, halfway to the next aisle,
  in place of position 4) and rejoins it at position 5, while the way south runs straight on
  from 5 to 3. Each aisle is thus two one-lane stretches, positions 1-3 and 5-6, and vehicles
  meeting in it pass where the two ways run apart. An aisle joins the inner lane, and the inner
  lane the outer one, by short two-way crossings.
- **Short lane segments**: the south and north lanes have a node halfway between each pair of
  columns (segments of 2 m between the aisles; not on the end segments at the corners). Traffic
  control grants whole edges, so a vehicle following another on a lane keeps one short segment
  behind it instead of one aisle pitch.
- **Lane changes** between the ring's lanes: the aisle crossings and two crossings on each side.
- **Stations** (``stationType``): ``pick`` at aisle positions 2 and 5 (inside the aisles),
  ``parking`` P1–P6 and ``charging`` CH1–CH3, each on a dead-end two-way spur, and ``drop``
  DR1–DR4 in drive-through bays, two south and two north of the ring: one way in from the outer
  lane through two queue nodes (DQ1 and DQ1b for DR1), one way out through a node halfway (DX1)
  to the same lane 2 m further on. A vehicle leaving a drop station never meets one that
  arrives, two more can queue for it off the lane, and the next one in the queue gets the
  station once the last one has reached the node halfway out, not only once it is on the lane.

Node ids: ``A3`` aisle A position 3, ``Ap`` its passing place; ``SO5`` / ``SI5`` south outer /
inner lane at aisle column 5 (``0`` and ``9`` are the corners), ``SO5m`` the node halfway from
column 5 to column 6; ``NO5`` / ``NI5`` / ``NO5m`` likewise in the north; ``WO1``/``WI1`` and
``EO1``/``EI1`` the west and east lanes' nodes between the corners; ``P3`` parking 3; ``CH1``
charger 1; ``DR2`` drop station 2 and ``DQ2``, ``DQ2b`` its queue nodes, ``DX2`` the node on its
way out (``C`` and ``D`` name aisles).
"""

from __future__ import annotations

import argparse
import json
from itertools import pairwise
from pathlib import Path

AISLES = "ABCDEFGH"
AISLE_X = [7.0 + 4.0 * i for i in range(len(AISLES))]  # 7, 11, ..., 35
AISLE_Y = [7.0, 10.0, 13.0, 16.0, 19.0, 22.0]
PICK_POSITIONS = (2, 5)
#: Aisles with a passing place: beside position 4, 2 m east of the aisle (halfway to the next
#: aisle, so no conflict with either), in place of that position's node.
PASSING_AISLES = "ABCDEFGH"
PASSING_POSITION = 4
PASSING_OFFSET_M = 2.0
#: x of the ring columns: west corner, one per aisle, east corner (outer lane).
OUTER_X = [0.0, *AISLE_X, 42.0]
INNER_X = [3.0, *AISLE_X, 39.0]
SOUTH_OUTER_Y, SOUTH_INNER_Y, NORTH_INNER_Y, NORTH_OUTER_Y = 0.0, 3.0, 26.0, 29.0
SIDE_Y = [10.0, 19.0]  # the side lanes' nodes between the corners
#: Drop bays (outer lane, column): below aisles B and F, above aisles D and H, so that the
#: transports to them share out over the south and the north corridor.
DROP_BAYS = (("SO", 2), ("NO", 4), ("SO", 6), ("NO", 8))
PARKING_COLUMNS = (1, 2, 3, 5, 6, 7)  # above aisles A-C and E-G, between the north bays
STATION_DEVIATION_M = 0.1
#: The south and north lanes: (node id prefix, column x, y, description).
LANES = (
    ("SO", OUTER_X, SOUTH_OUTER_Y, "south corridor, outer lane"),
    ("SI", INNER_X, SOUTH_INNER_Y, "south corridor, inner lane"),
    ("NI", INNER_X, NORTH_INNER_Y, "north corridor, inner lane"),
    ("NO", OUTER_X, NORTH_OUTER_Y, "north corridor, outer lane"),
)


class Builder:
    """Collects nodes and edges in file order."""

    def __init__(self) -> None:
        self.nodes: list[dict[str, object]] = []
        self.edges: list[dict[str, object]] = []

    def node(self, node_id: str, x: float, y: float, description: str, **extra: object) -> None:
        self.nodes.append({"nodeId": node_id, "x": x, "y": y, "description": description, **extra})

    def station(self, node_id: str, x: float, y: float, station_type: str, what: str) -> None:
        self.node(
            node_id,
            x,
            y,
            what,
            allowedDeviationXY=STATION_DEVIATION_M,
            stationType=station_type,
            stationName=node_id,
        )

    def one_way(self, start: str, end: str) -> None:
        self.edges.append({"edgeId": f"{start}-{end}", "startNodeId": start, "endNodeId": end})

    def two_way(self, a: str, b: str) -> None:
        self.one_way(a, b)
        self.one_way(b, a)

    def lane(self, node_ids: list[str]) -> None:
        for start, end in pairwise(node_ids):
            self.one_way(start, end)


def build(passing_aisles: str = PASSING_AISLES) -> dict[str, object]:
    """The warehouse graph document; ``passing_aisles``: the aisles with a passing place (tests
    of one-lane stretches build the floor without them)."""
    b = Builder()
    last = len(OUTER_X) - 1
    _ring_nodes(b, last)
    _aisle_nodes(b, passing_aisles)
    _station_nodes(b, last)
    _ring(b, last)
    _aisles(b, passing_aisles)
    for k, (lane, c) in enumerate(DROP_BAYS, start=1):
        # out to the node halfway on along the lane (south: eastbound, north: westbound)
        exit_node = f"SO{c}m" if lane == "SO" else f"NO{c - 1}m"
        b.lane([f"{lane}{c}", f"DQ{k}", f"DQ{k}b", f"DR{k}", f"DX{k}", exit_node])
    for k, c in enumerate(PARKING_COLUMNS, start=1):
        b.two_way(f"NO{c}", f"P{k}")
    b.two_way("EO1", "CH1")
    b.two_way("EO2", "CH2")
    b.two_way(f"NO{last}", "CH3")
    return {"mapId": "warehouse", "nodes": b.nodes, "edges": b.edges}


def _ring_nodes(b: Builder, last: int) -> None:
    for c in range(last + 1):
        b.node(f"SO{c}", OUTER_X[c], SOUTH_OUTER_Y, f"south corridor, outer lane, column {c}")
        b.node(f"SI{c}", INNER_X[c], SOUTH_INNER_Y, f"south corridor, inner lane, column {c}")
        b.node(f"NI{c}", INNER_X[c], NORTH_INNER_Y, f"north corridor, inner lane, column {c}")
        b.node(f"NO{c}", OUTER_X[c], NORTH_OUTER_Y, f"north corridor, outer lane, column {c}")
    for c in range(last):
        for lane, xs, y, what in LANES:
            if not _has_halfway(c, last):
                continue
            x = (xs[c] + xs[c + 1]) / 2
            b.node(f"{lane}{c}m", x, y, f"{what}, halfway from column {c} to {c + 1}")
    for k, y in enumerate(SIDE_Y, start=1):
        b.node(f"WO{k}", OUTER_X[0], y, f"west corridor, outer lane, node {k}")
        b.node(f"WI{k}", INNER_X[0], y, f"west corridor, inner lane, node {k}")
        b.node(f"EI{k}", INNER_X[last], y, f"east corridor, inner lane, node {k}")
        b.node(f"EO{k}", OUTER_X[last], y, f"east corridor, outer lane, node {k}")


def _aisle_nodes(b: Builder, passing_aisles: str) -> None:
    for aisle, x in zip(AISLES, AISLE_X, strict=True):
        for position, y in enumerate(AISLE_Y, start=1):
            node_id = f"{aisle}{position}"
            if position == PASSING_POSITION and aisle in passing_aisles:
                b.node(f"{aisle}p", x + PASSING_OFFSET_M, y, f"aisle {aisle}, passing place")
            elif position in PICK_POSITIONS:
                b.station(node_id, x, y, "pick", f"aisle {aisle}, pick station {node_id}")
            else:
                b.node(node_id, x, y, f"aisle {aisle}, position {position}")


def _station_nodes(b: Builder, last: int) -> None:
    for k, (lane, c) in enumerate(DROP_BAYS, start=1):
        x = OUTER_X[c]
        # below the eastbound lane (out 2 m east) or above the westbound one (out 2 m west)
        away, onwards = (-1.0, 2.0) if lane == "SO" else (1.0, -2.0)
        y = SOUTH_OUTER_Y if lane == "SO" else NORTH_OUTER_Y
        b.node(f"DQ{k}", x, y + 2.5 * away, f"first queue node before drop station DR{k}")
        b.node(f"DQ{k}b", x, y + 4.5 * away, f"second queue node before drop station DR{k}")
        b.station(f"DR{k}", x + onwards, y + 5.5 * away, "drop", f"drop station DR{k}")
        b.node(f"DX{k}", x + onwards, y + 2.75 * away, f"way out of drop station DR{k}")
    for k, c in enumerate(PARKING_COLUMNS, start=1):
        b.station(f"P{k}", OUTER_X[c], NORTH_OUTER_Y + 4.0, "parking", f"parking place P{k}")
    for k, y in enumerate((*SIDE_Y, NORTH_OUTER_Y), start=1):
        b.station(f"CH{k}", OUTER_X[last] + 4.0, y, "charging", f"charger CH{k}")


def _ring(b: Builder, last: int) -> None:
    """Outer lane counter-clockwise, inner lane clockwise, crossings between them."""
    outer = [*_eastwards("SO", last), "EO1", "EO2", *reversed(_eastwards("NO", last))]
    b.lane([*outer, "WO2", "WO1", "SO0"])
    inner = [*reversed(_eastwards("SI", last)), "WI1", "WI2", *_eastwards("NI", last)]
    b.lane([*inner, "EI2", "EI1", f"SI{last}"])
    for k in (1, 2):
        b.two_way(f"WO{k}", f"WI{k}")
        b.two_way(f"EI{k}", f"EO{k}")


def _eastwards(lane: str, last: int) -> list[str]:
    """A south or north lane's nodes from west to east: columns and the nodes halfway."""
    nodes = [f"{lane}0"]
    for c in range(1, last + 1):
        if _has_halfway(c - 1, last):
            nodes.append(f"{lane}{c - 1}m")
        nodes.append(f"{lane}{c}")
    return nodes


def _has_halfway(c: int, last: int) -> bool:
    """Whether a south or north lane has a node halfway from column ``c`` to ``c + 1``:
    everywhere but on the end segments at the corners (4 m on the inner lanes, 7 m on the outer
    ones; no station there), to stay within 150 nodes with a node on each drop bay's way out."""
    return c not in {0, last - 1}


def _aisles(b: Builder, passing_aisles: str) -> None:
    """Each aisle: outer lane ⇄ inner lane ⇄ positions 1…6 ⇄ inner lane ⇄ outer lane (north);
    with a passing place, the positions either side of it are joined by two one-way ways
    instead: northwards round the passing place, southwards straight on."""
    for column, aisle in enumerate(AISLES, start=1):
        chain = [f"SO{column}", f"SI{column}"]
        chain += [f"{aisle}{p}" for p in range(1, len(AISLE_Y) + 1)]
        chain += [f"NI{column}", f"NO{column}"]
        halves = [chain]
        if aisle in passing_aisles:
            k = chain.index(f"{aisle}{PASSING_POSITION}")
            halves = [chain[:k], chain[k + 1 :]]
            b.lane([chain[k - 1], f"{aisle}p", chain[k + 1]])
            b.one_way(chain[k + 1], chain[k - 1])
        for half in halves:
            for a, z in pairwise(half):
                b.two_way(a, z)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path, default=Path("config/graphs/warehouse.json"))
    args = parser.parse_args()
    args.output.write_text(json.dumps(build(), indent=1) + "\n", encoding="utf-8")
    print(f"wrote {args.output}")  # noqa: T201 - a command-line tool


if __name__ == "__main__":
    main()
