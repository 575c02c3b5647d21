"""The release gate: how far a vehicle's base may be released now (issue 9 §2, §3).

A route is the node and edge sequence of an order plan: node *i*, edge *i* from node *i* to node
*i + 1*. The vehicle has last traversed node ``progress`` and its base is released up to node
``released_end``; it holds nodes ``progress … released_end`` and the edges between them.

The gate extends the base *step by step* while every resource of the next step is free for the
vehicle (:meth:`ReservationTable.refusal`), and stops once the end reaches ``desired_end`` (the
release window). What a step is carries the deadlock *avoidance* rule:

**A base only ends on a waiting node.** Node *i* of a route is a *waiting node* when it is the
route's last node or when the route leaves it over an edge that is not one-lane (an edge is
one-lane when its opposite edge exists: traffic both ways shares the lane, see
:meth:`ConflictMap.is_one_lane`). A step therefore runs from the current end over the next edge
and on through every following one-lane edge, up to the next waiting node: a vehicle never
stops inside a one-lane stretch, nor on the node where one begins, unless its route ends there
(or it stands on the stretch's last node before the exit: the exception below).
Consequences, each a deliberate trade-off:

- a one-lane corridor is entered only when the whole corridor (up to its exit, or to its last
  node before the exit, below) is free, so a vehicle coming the other way can never meet it
  inside; the opposing vehicle waits *before* the corridor's entry node, which keeps that node
  free for the vehicle leaving the corridor;
- following another vehicle through a one-lane corridor waits until the leader is out (the
  rule cannot tell a follower from an opposing vehicle without the leader's future);
- the base may be released beyond ``desired_end``, up to the next waiting node, when the window
  ends inside a one-lane stretch. The dispatcher's ``max_nodes`` cap may cut the message
  shorter; the vehicle then holds more than it was released, which is safe.

**Nor inside a RELEASE zone.** A node from which a vehicle reaches into a RELEASE zone
(:attr:`ConflictMap.release_nodes`) is no waiting node either, unless the route ends there: the
zone is entered only when the way through it and out is free, so the one vehicle inside never
waits there for another one, which may be waiting for the zone.

**One exception: the exit comes last.** A stretch's *exit* is the waiting node it ends on (an
aisle's junction with a lane), perhaps after crossing other lanes on the way (leaving an aisle
for the far lane of a corridor crosses the near one). When the route goes on from the exit over
an edge that is not one-lane, the step ends on the stretch's last node before those lane nodes
(inside the stretch: one-lane edges lead to it and away from it, and it is on no lane), and the
lane nodes follow as the next step: the vehicle holds them only from the time it is within the
release window of them, not for the whole way through the aisle, and when they are taken it
waits inside the aisle, off every lane, instead of stopping on a crossed lane or before the
aisle (every vehicle on that lane behind it would wait meanwhile). This cannot deadlock two
vehicles: a vehicle coming into the stretch from the exit needs the node the waiting one stands
on, and is released onto the exit only together with it (the exit and the crossed lane nodes
are no waiting nodes for it), so it waits before the exit; whoever holds a lane node there goes
on along its lane and needs nothing of the stretch. The exit must not be the route's end: a
destination inside an aisle may be held by a vehicle about to leave it towards this one.

**Late orders go first** (:mod:`.priority`): the caller may pass the claims of late waiting
vehicles; a step that is free but touches a claim is refused like a taken one, naming the
claimant (``Blocked.claim``).

The result also names what blocks: the first resource of the refused step that is not free, the
vehicle holding a conflicting resource, and every vehicle that holds something the step needs.
Pure and O(steps × conflict-set size).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from vda5050.topics import AgvId
from vda_master.routing import Route
from vda_master.traffic.conflicts import ConflictMap, Resource, edge, node
from vda_master.traffic.reservations import Refused, ReservationTable


@dataclass(frozen=True, slots=True)
class Blocked:
    """The step beyond the granted end is not free: ``refused`` names the first conflict."""

    refused: Refused
    #: Every other vehicle holding a resource that conflicts with the refused step.
    holders: frozenset[AgvId]
    #: The node index the refused step would have reached.
    step_end: int
    #: The step is free but claimed by a late vehicle (``refused.holder``), see :mod:`.priority`.
    claim: bool = False


@dataclass(frozen=True, slots=True)
class Grant:
    """How far the base may be released now (never below the given ``released_end``)."""

    end: int
    blocked: Blocked | None = None


def is_waiting_node(conflicts: ConflictMap, route: Route, index: int) -> bool:
    """Whether a base may end on node ``index`` of ``route`` (see the module docstring)."""
    return index >= len(route.edge_ids) or not (
        conflicts.is_one_lane(route.edge_ids[index])
        or route.node_ids[index] in conflicts.release_nodes
    )


def is_last_before_exit(conflicts: ConflictMap, route: Route, index: int) -> bool:
    """Whether node ``index`` lies inside a one-lane stretch (one-lane edges lead to it and away
    from it, and it is on no lane) and what follows up to the stretch's exit, a waiting node the
    route goes on from, is only lane nodes: the exit and any lane the stretch crosses on its way
    there. A base may end there too (module docstring, *the exit comes last*)."""
    if not (
        0 < index < len(route.edge_ids)
        and conflicts.is_one_lane(route.edge_ids[index - 1])
        and conflicts.is_one_lane(route.edge_ids[index])
        and route.node_ids[index] not in conflicts.lane_nodes
        and route.node_ids[index] not in conflicts.release_nodes
    ):
        return False
    exit_index = next_waiting_index(conflicts, route, index)
    return exit_index < len(route.edge_ids) and all(
        node_id in conflicts.lane_nodes for node_id in route.node_ids[index + 1 : exit_index + 1]
    )


def next_waiting_index(conflicts: ConflictMap, route: Route, index: int) -> int:
    """The first waiting node after node ``index`` (the route's last node at the latest)."""
    following = index + 1
    while not is_waiting_node(conflicts, route, following):
        following += 1
    return following


def route_resources(route: Route, first: int, last: int) -> list[Resource]:
    """Nodes ``first … last`` and the edges between them, in driving order."""
    found = [node(route.node_ids[first])]
    for index in range(first, last):
        found += (edge(route.edge_ids[index]), node(route.node_ids[index + 1]))
    return found


def decide_release_end(
    table: ReservationTable,
    agv: AgvId,
    route: Route,
    *,
    progress: int,
    released_end: int,
    desired_end: int,
    claimed: Callable[[list[Resource]], Refused | None] | None = None,
) -> Grant:
    """The furthest node index the base of ``agv`` on ``route`` may be released to now.

    ``claimed`` (if given) refuses a free step that touches what a late vehicle claims
    (:mod:`.priority`): the refusal names the claimant, who is then the only blocker."""
    last = len(route.edge_ids)
    end = min(max(released_end, progress), last)
    target = min(desired_end, last)
    while end < target:
        stop, step = next_step(table.conflicts, route, end)
        refused = table.refusal(agv, step)
        if refused is not None:
            return Grant(end, Blocked(refused, table.blockers(agv, step), stop))
        refused = claimed(step) if claimed is not None else None
        if refused is not None:
            return Grant(end, Blocked(refused, frozenset({refused.holder}), stop, claim=True))
        end = stop
    return Grant(end)


def next_step(conflicts: ConflictMap, route: Route, end: int) -> tuple[int, list[Resource]]:
    """The step from node ``end``: where it ends (:func:`step_end`) and the resources it needs
    beyond node ``end``."""
    stop = step_end(conflicts, route, end)
    return stop, route_resources(route, end, stop)[1:]


def step_end(conflicts: ConflictMap, route: Route, end: int) -> int:
    """Where the step from node ``end`` ends: the next waiting node, or, when the stretch up to
    it ends in a crossing of lanes, the last node inside the stretch before that crossing
    (module docstring, *the exit comes last*)."""
    following = next_waiting_index(conflicts, route, end)
    inside = following - 1
    while inside > end and route.node_ids[inside] in conflicts.lane_nodes:
        inside -= 1  # never on a lane the stretch crosses: before the crossing
    if inside > end and is_last_before_exit(conflicts, route, inside):
        return inside
    return following
