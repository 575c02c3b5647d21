"""Who holds which resource: the immutable reservation table (issue 9 §2).

THE invariant: no two different vehicles ever hold conflicting resources. Every operation that
adds holdings (:meth:`ReservationTable.claim`, :meth:`ReservationTable.replace`) first checks
that the new resources are *free for* the vehicle: no other vehicle holds any resource that
conflicts with them (a resource conflicts with itself, so this also rules out sharing one). An
operation that would break the invariant returns :class:`Refused` and changes nothing. Releasing
can never break it.

Each operation costs O(resources touched × conflict-set size), independent of the fleet size.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass

from vda5050.topics import AgvId
from vda_master.traffic.conflicts import ConflictMap, Resource
from vda_master.traffic.pmap import PMap


@dataclass(frozen=True, slots=True)
class Refused:
    """Why resources are not free: ``wanted`` conflicts with ``held``, held by ``holder``."""

    wanted: Resource
    held: Resource
    holder: AgvId


class ReservationTable:
    """Resource → holding vehicle and vehicle → held resources, always consistent."""

    __slots__ = ("_by_vehicle", "_holder", "conflicts")

    def __init__(
        self,
        conflicts: ConflictMap,
        holder: PMap[Resource, AgvId] | None = None,
        by_vehicle: PMap[AgvId, frozenset[Resource]] | None = None,
    ) -> None:
        self.conflicts = conflicts
        self._holder: PMap[Resource, AgvId] = holder if holder is not None else PMap()
        self._by_vehicle: PMap[AgvId, frozenset[Resource]] = (
            by_vehicle if by_vehicle is not None else PMap()
        )

    def held_by(self, agv: AgvId) -> frozenset[Resource]:
        """What ``agv`` holds (empty if nothing)."""
        return self._by_vehicle.get(agv) or frozenset()

    def holder(self, resource: Resource) -> AgvId | None:
        """The vehicle holding ``resource``, if any."""
        return self._holder.get(resource)

    def vehicles(self) -> Iterator[tuple[AgvId, frozenset[Resource]]]:
        """Every vehicle that holds something, with its holdings (O(fleet): snapshots only)."""
        return self._by_vehicle.items()

    def refusal(self, agv: AgvId, resources: Iterable[Resource]) -> Refused | None:
        """The first resource (in iteration order) that is not free for ``agv``, or None."""
        holder_of = self._holder.get
        for wanted in resources:
            for other in self.conflicts.ordered[wanted]:
                holder = holder_of(other)
                if holder is not None and holder != agv:
                    return Refused(wanted, other, holder)
        return None

    def blockers(self, agv: AgvId, resources: Iterable[Resource]) -> frozenset[AgvId]:
        """Every other vehicle holding something that conflicts with ``resources``."""
        holder_of = self._holder.get
        found = {
            holder
            for wanted in resources
            for other in self.conflicts[wanted]
            if (holder := holder_of(other)) is not None and holder != agv
        }
        return frozenset(found)

    def is_free(self, agv: AgvId, resources: Iterable[Resource]) -> bool:
        """Whether ``agv`` may hold all of ``resources`` without breaking the invariant."""
        return self.refusal(agv, resources) is None

    def claim(self, agv: AgvId, resources: Iterable[Resource]) -> ReservationTable | Refused:
        """``agv`` additionally holds ``resources``, if all are free for it."""
        wanted = frozenset(resources)
        refused = self.refusal(agv, wanted)
        if refused is not None:
            return refused
        return self._with(agv, self.held_by(agv) | wanted)

    def release(self, agv: AgvId, resources: Iterable[Resource]) -> ReservationTable:
        """``agv`` no longer holds ``resources`` (those it does not hold are ignored)."""
        held = self.held_by(agv)
        kept = held.difference(resources)
        return self if len(kept) == len(held) else self._with(agv, kept)

    def replace(self, agv: AgvId, resources: Iterable[Resource]) -> ReservationTable | Refused:
        """``agv`` holds exactly ``resources`` from now on, if all are free for it."""
        wanted = frozenset(resources)
        refused = self.refusal(agv, wanted - self.held_by(agv))
        if refused is not None:
            return refused
        return self._with(agv, wanted)

    def _with(self, agv: AgvId, holdings: frozenset[Resource]) -> ReservationTable:
        """Set ``agv``'s holdings; callers have checked they are free for it."""
        old = self.held_by(agv)
        holder = self._holder.update(put=((r, agv) for r in holdings - old), remove=old - holdings)
        by_vehicle = (
            self._by_vehicle.set(agv, holdings) if holdings else self._by_vehicle.remove(agv)
        )
        return ReservationTable(self.conflicts, holder, by_vehicle)
