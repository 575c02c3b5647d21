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
stops inside a one-lane stretch, nor on the node where one begins, unless its route ends there.
Consequences, each a deliberate trade-off:

- a one-lane corridor is entered only when the whole corridor up to its exit is free, so a
  vehicle coming the other way can never meet it inside; the opposing vehicle waits *before*
  the corridor's entry node, which keeps that node free for the vehicle leaving the corridor;
- following another vehicle through a one-lane corridor waits until the leader is out (the
  rule cannot tell a follower from an opposing vehicle without the leader's future);
- the base may be released beyond ``desired_end``, up to the next waiting node, when the window
  ends inside a one-lane stretch. The dispatcher's ``max_nodes`` cap may cut the message
  shorter; the vehicle then holds more than it was released, which is safe.

The result also names what blocks: the first resource of the refused step that is not free, the
vehicle holding a conflicting resource, and every vehicle that holds something the step needs.
Pure and O(steps × conflict-set size).
"""

from __future__ import annotations

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


@dataclass(frozen=True, slots=True)
class Grant:
    """How far the base may be released now (never below the given ``released_end``)."""

    end: int
    blocked: Blocked | None = None


def is_waiting_node(conflicts: ConflictMap, route: Route, index: int) -> bool:
    """Whether a base may end on node ``index`` of ``route`` (see the module docstring)."""
    return index >= len(route.edge_ids) or not conflicts.is_one_lane(route.edge_ids[index])


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
) -> Grant:
    """The furthest node index the base of ``agv`` on ``route`` may be released to now."""
    last = len(route.edge_ids)
    end = min(max(released_end, progress), last)
    target = min(desired_end, last)
    while end < target:
        following = next_waiting_index(table.conflicts, route, end)
        step = route_resources(route, end, following)[1:]
        refused = table.refusal(agv, step)
        if refused is not None:
            return Grant(end, Blocked(refused, table.blockers(agv, step), following))
        end = following
    return Grant(end)
