"""What a vehicle's maps allow, and what master control sends it for a map version (pure).

VDA 5050 2.1 and 3.0 (§6.7): a vehicle lists the maps it holds in its state's ``maps``, each
map version ENABLED or DISABLED; it drives only on ENABLED ones and rejects an order on a map it
does not hold (§6.7.1, R35). Master control "must make sure the right maps are enabled for the
mapIds used in its orders". Here:

- :func:`map_problem`: why a vehicle cannot take an order that starts on ``map_id`` now (it lists
  maps, and no version of that mapId is ENABLED). Tolerant where the vehicle says nothing: a
  state without ``maps`` (2.0, or a 2.1 vehicle that leaves the optional field out) or with an
  empty list is not narrowed: many vehicles drive on one fixed map and report none.
- :func:`distribution_step` / :func:`enabling_step`: per vehicle, what ``POST
  /maps/{mapId}/{mapVersion}/distribute`` and ``…/enable`` do: send ``downloadMap``, send
  ``enableMap``, nothing (it holds the version already), or why not.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from vda5050.models import ActionStatus, MapStatus, State

#: A map version: (mapId, mapVersion).
MapKey = tuple[str, str]
#: The first VDA 5050 version with map distribution (§6.7 is new in 2.1).
FIRST_MAP_VERSION = "2.1"


def describe(key: MapKey) -> str:
    """``map 'hall' version '2'``."""
    return f"map {key[0]!r} version {key[1]!r}"


def held_maps(state: State | None) -> dict[MapKey, MapStatus]:
    """The map versions ``state`` lists, with their status (empty when it lists none)."""
    if state is None or not state.maps:
        return {}
    return {(m.map_id, m.map_version): m.map_status for m in state.maps}


def map_problem(state: State | None, map_id: str) -> str | None:
    """Why the vehicle cannot drive an order on ``map_id`` now, or None: it lists maps and
    none of ``map_id``'s versions is ENABLED (§6.7.1). A vehicle that lists no maps passes."""
    if state is None or not state.maps:
        return None
    versions = [m for m in state.maps if m.map_id == map_id]
    if any(m.map_status is MapStatus.ENABLED for m in versions):
        return None
    if versions:
        listed = ", ".join(f"{m.map_version!r} ({m.map_status.value})" for m in versions)
        held = f"it holds version {listed} and none ENABLED"
    else:
        held = f"it holds none ({', '.join(sorted({m.map_id for m in state.maps}))} only)"
    return f"no version of map {map_id!r} is ENABLED on it: {held} (enableMap, §6.7.1)"


class Send(Enum):
    """What master control sends a vehicle for a map version."""

    DOWNLOAD = "downloadMap"
    ENABLE = "enableMap"
    NOTHING = "nothing"


@dataclass(frozen=True, slots=True)
class MapStep:
    """``send`` (with ``detail`` saying why when it is NOTHING), or ``refused``: an HTTP status
    and why the vehicle cannot be given the map."""

    send: Send = Send.NOTHING
    detail: str = ""
    refused: int | None = None


def _speaks_maps(version: str | None) -> bool:
    """Whether a vehicle speaking ``version`` knows map distribution (unknown: assumed so)."""
    return version is None or not version.startswith("2.0")


def distribution_step(
    state: State | None, version: str | None, key: MapKey, *, enable: bool
) -> MapStep:
    """For ``POST …/distribute``: download the version unless the vehicle holds it; with
    ``enable``, enable it where it is held DISABLED (a download is enabled once it is done)."""
    if not _speaks_maps(version):
        return MapStep(
            refused=422,
            detail=f"it speaks VDA 5050 {version}, which has no map distribution (new in "
            f"{FIRST_MAP_VERSION}, §6.7)",
        )
    status = held_maps(state).get(key)
    if status is None:
        return MapStep(Send.DOWNLOAD)
    if status is MapStatus.DISABLED and enable:
        return MapStep(Send.ENABLE)
    return MapStep(detail=f"it holds {describe(key)} already ({status.value})")


def enabling_step(state: State | None, version: str | None, key: MapKey) -> MapStep:
    """For ``POST …/enable``: enable the version where it is held DISABLED."""
    if not _speaks_maps(version):
        return distribution_step(state, version, key, enable=True)
    status = held_maps(state).get(key)
    if status is None:
        return MapStep(
            refused=409,
            detail=f"it does not hold {describe(key)}: distribute it first "
            "(POST /maps/{mapId}/{mapVersion}/distribute)",
        )
    if status is MapStatus.ENABLED:
        return MapStep(detail=f"{describe(key)} is ENABLED on it already")
    return MapStep(Send.ENABLE)


@dataclass(frozen=True, slots=True)
class PendingEnable:
    """A download to enable once it is done: the version and the ``downloadMap`` actionId."""

    key: MapKey
    action_id: str


class Follow(Enum):
    """What a state says of a :class:`PendingEnable`."""

    WAIT = "wait"
    ENABLE = "enable"
    DONE = "done"
    FAILED = "failed"


def follow_download(state: State, pending: PendingEnable) -> tuple[Follow, str]:
    """ENABLE once the state lists the version DISABLED (R88), DONE when it is ENABLED already
    (enabled by hand), FAILED when the download ended FAILED (with its description), else
    WAIT."""
    status = held_maps(state).get(pending.key)
    if status is MapStatus.DISABLED:
        return Follow.ENABLE, ""
    if status is MapStatus.ENABLED:
        return Follow.DONE, ""
    for action in state.action_states:
        if action.action_id == pending.action_id and action.action_status is ActionStatus.FAILED:
            return Follow.FAILED, action.result_description or "no resultDescription"
    return Follow.WAIT, ""
