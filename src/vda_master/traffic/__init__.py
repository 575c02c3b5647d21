"""Fleet traffic control, the pure core (issue 9; design note: ``docs/traffic.md``).

=================  ===========================================================================
``conflicts``      resources (nodes, edges), conflict sets from geometry, safety distance
``reservations``   the immutable reservation table and its invariant
``gate``           how far a base may be released; deadlock avoidance on one-lane stretches
``waits``          who waits for whom, deadlocks, resolution proposals
``passages``       expected passages (resource × time interval) of planned routes
``planner``        time-aware routing (safe-interval A*), earliest expected arrival
``state``          the controller's immutable state and its transitions
``advice``         deadlocks, over-long waits and idle vehicles in the way, as proposals
``controller``     :class:`TrafficController`, the fold the master shell calls
``snapshot``       advice and the ``GET /traffic`` view
=================  ===========================================================================

Nothing here awaits, reads a clock or touches MQTT; time is passed in.
"""

from vda_master.traffic.conflicts import (
    ConflictMap,
    Resource,
    ResourceKind,
    build_conflicts,
    default_safety_distance_m,
)
from vda_master.traffic.controller import (
    AtNode,
    OffGraph,
    OnRoute,
    Position,
    Release,
    TrafficController,
)
from vda_master.traffic.gate import Blocked, Grant, decide_release_end
from vda_master.traffic.passages import PassageSettings, SpeedModel
from vda_master.traffic.planner import PlannedRoute
from vda_master.traffic.reservations import Refused, ReservationTable
from vda_master.traffic.snapshot import Advice, Resolution, TrafficSnapshot, VehicleSnapshot
from vda_master.traffic.state import TrafficSettings, VehicleTraffic
from vda_master.traffic.waits import (
    BackOff,
    Deadlock,
    MoveToParking,
    Proposal,
    Replan,
    SearchBudget,
    Wait,
)

__all__ = [
    "Advice",
    "AtNode",
    "BackOff",
    "Blocked",
    "ConflictMap",
    "Deadlock",
    "Grant",
    "MoveToParking",
    "OffGraph",
    "OnRoute",
    "PassageSettings",
    "PlannedRoute",
    "Position",
    "Proposal",
    "Refused",
    "Release",
    "Replan",
    "ReservationTable",
    "Resolution",
    "Resource",
    "ResourceKind",
    "SearchBudget",
    "SpeedModel",
    "TrafficController",
    "TrafficSettings",
    "TrafficSnapshot",
    "VehicleSnapshot",
    "VehicleTraffic",
    "Wait",
    "build_conflicts",
    "decide_release_end",
    "default_safety_distance_m",
]
