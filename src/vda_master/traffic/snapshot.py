"""What the traffic controller tells the shell: advice to act on and the ``GET /traffic`` view.

``as_json`` gives the camelCase document the API serves (architecture §3.5: per vehicle the
resources it holds, what it waits for and since when), so the shell only wraps it.
"""

from __future__ import annotations

from dataclasses import dataclass

from pydantic import JsonValue

from vda5050.topics import AgvId
from vda_master.traffic.waits import BackOff, Deadlock, MoveToParking, Proposal, Replan

_KINDS: dict[type, str] = {Replan: "replan", BackOff: "backOff", MoveToParking: "moveToParking"}


@dataclass(frozen=True, slots=True)
class Advice:
    """What the shell should do about traffic now; every part may be empty."""

    deadlocks: tuple[Deadlock, ...]
    #: Detours for vehicles that waited longer than ``max_wait_s`` (not in a deadlock).
    replans: tuple[Replan | BackOff, ...]
    #: Idle vehicles that waiting vehicles wait for, to be sent to parking.
    moves: tuple[MoveToParking, ...]


@dataclass(frozen=True, slots=True)
class Resolution:
    """A proposal the shell carried out."""

    time: float
    kind: str
    agv: AgvId
    #: Where the vehicle was sent (the new route's destination or the back-off node).
    node_id: str
    #: The deadlock it resolved; empty for a re-plan after a long wait or a parking move.
    vehicles: tuple[AgvId, ...]
    reason: str

    def as_json(self) -> dict[str, JsonValue]:
        """camelCase JSON for the API."""
        return {
            "time": self.time,
            "kind": self.kind,
            "vehicle": str(self.agv),
            "nodeId": self.node_id,
            "deadlock": [str(a) for a in self.vehicles],
            "reason": self.reason,
        }


def resolution_of(proposal: Proposal, now: float, vehicles: tuple[AgvId, ...]) -> Resolution:
    """The history entry for carrying out ``proposal``."""
    target = proposal.route.destination if isinstance(proposal, Replan) else proposal.node_id
    return Resolution(now, _KINDS[type(proposal)], proposal.agv, target, vehicles, proposal.reason)


@dataclass(frozen=True, slots=True)
class VehicleSnapshot:
    """One vehicle's traffic situation."""

    agv: AgvId
    node_id: str | None
    #: Held resources as ``node:<id>`` / ``edge:<id>``, sorted.
    held: tuple[str, ...]
    #: Nodes of its route beyond the released end, still waiting for release.
    pending_node_ids: tuple[str, ...]
    waiting_for: tuple[AgvId, ...]
    #: The first resource of the refused step, while waiting.
    waiting_at: str | None
    since: float | None
    waited_s: float | None
    #: Set when the vehicle stands where another vehicle holds a conflicting resource (it
    #: appeared or was moved there by hand): the position it could not reserve, and why.
    conflict: str | None = None

    def as_json(self) -> dict[str, JsonValue]:
        """camelCase JSON for the API."""
        return {
            "manufacturer": self.agv.manufacturer,
            "serialNumber": self.agv.serial_number,
            "nodeId": self.node_id,
            "holds": list(self.held),
            "pendingNodeIds": list(self.pending_node_ids),
            "waitingFor": [str(a) for a in self.waiting_for],
            "waitingAt": self.waiting_at,
            "waitingSince": self.since,
            "waitedS": self.waited_s,
            "conflict": self.conflict,
        }


@dataclass(frozen=True, slots=True)
class TrafficSnapshot:
    """The whole fleet's traffic situation."""

    safety_distance_m: float
    vehicles: tuple[VehicleSnapshot, ...]
    deadlocks_resolved: int
    resolutions: tuple[Resolution, ...]

    def as_json(self) -> dict[str, JsonValue]:
        """camelCase JSON for ``GET /traffic``."""
        return {
            "safetyDistanceM": self.safety_distance_m,
            "vehicles": [v.as_json() for v in self.vehicles],
            "deadlocksResolved": self.deadlocks_resolved,
            "resolutions": [r.as_json() for r in self.resolutions],
        }
