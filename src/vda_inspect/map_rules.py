"""What a vehicle's ``maps`` must show when a map action ends (pure; 2.1 §6.7, 3.0 alike;
R87-R91; docs/inspect.md). :mod:`vda_inspect.progress` records each ``downloadMap``,
``enableMap`` and ``deleteMap`` the listener sees sent, with what the vehicle's last state
said of that map then, and calls :func:`ended_problems` where the action first ends:

- R87: a ``downloadMap`` of a map version the vehicle held already ends FAILED;
- R88: a ``downloadMap`` that ends FINISHED has put the version into ``maps``;
- R89: an ``enableMap`` that ends FINISHED has made that version ENABLED (and, checked in every
  state, no other version of the mapId is ENABLED beside it);
- R90: an ``enableMap`` or ``deleteMap`` of a version the vehicle did not hold ends FAILED;
- R91: a ``deleteMap`` that ends FINISHED has taken the version out of ``maps``, and (checked in
  every state, :func:`map_problems`) no map leaves ``maps`` without one.

Whether a map is "in use" (a ``deleteMap`` of it must fail) is the vehicle's to say: not judged.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from vda5050.models import State, v3
from vda_inspect.action_rules import FINISHED, Listed
from vda_inspect.severity import Problem, Severity

MAP_ACTIONS: Final = frozenset({"downloadMap", "enableMap", "deleteMap"})
#: Map id and version → mapStatus, as a state lists them.
Maps = dict[tuple[str, str], str]


def maps_of(state: State | v3.State) -> Maps:
    """The maps ``state`` lists (none when it has no ``maps``)."""
    return {(m.map_id, m.map_version): m.map_status.value for m in state.maps or ()}


@dataclass(frozen=True, slots=True)
class MapRequest:
    """A map action as sent, and the version's status in the vehicle's last state then."""

    action_type: str
    map_id: str
    map_version: str
    #: None: the vehicle did not list that version when the action was sent
    status_before: str | None

    def describe(self) -> str:
        return f"{self.action_type} of map {self.map_id!r} version {self.map_version!r}"


def map_request(
    action_type: str,
    parameters: Mapping[str, object],
    maps: Mapping[tuple[str, str], str],
) -> MapRequest | None:
    """The request an action is, if it is a map action with both ids (else None)."""
    map_id, version = parameters.get("mapId"), parameters.get("mapVersion")
    if action_type not in MAP_ACTIONS or not isinstance(map_id, str):
        return None
    if not isinstance(version, str):
        return None
    return MapRequest(action_type, map_id, version, maps.get((map_id, version)))


def ended_problems(request: MapRequest, status: str, state: State | v3.State) -> list[Problem]:
    """R87-R91 in the state where the action first shows ``status`` (FINISHED or FAILED)."""
    if status != FINISHED:
        return []
    found = _finished_problem(request, state)
    return [] if found is None else [(found[0], found[1], Severity.VIOLATION)]


def _finished_problem(request: MapRequest, state: State | v3.State) -> tuple[str, str] | None:
    maps = maps_of(state)
    now = maps.get((request.map_id, request.map_version))
    held = request.status_before is not None
    what = f"{request.describe()} FINISHED"
    if request.action_type == "downloadMap":
        return _downloaded(what, now, held=held, listed=state.maps is not None)
    if not held:
        return "R90", f"{what}, though the vehicle did not hold it"
    if request.action_type == "enableMap" and now != "ENABLED":
        return "R89", f"{what}, but the map is {now or 'gone'}"
    if request.action_type == "deleteMap" and now is not None:
        return "R91", f"{what}, but the map is still listed"
    return None


def _downloaded(what: str, now: str | None, *, held: bool, listed: bool) -> tuple[str, str] | None:
    if held:
        return "R87", f"{what}, though the vehicle held it already"
    if listed and now is None:
        return "R88", f"{what}, but the map is not in maps"
    return None


def map_problems(
    state: State | v3.State, before: Mapping[tuple[str, str], str], shown: Listed
) -> list[Problem]:
    """R89: no two versions of one mapId ENABLED; R91: a map leaves ``maps`` only by a
    ``deleteMap`` that the state shows FINISHED. ``before`` are the maps of the vehicle's
    previous state (map id and version → status)."""
    maps = maps_of(state)
    enabled: dict[str, list[str]] = {}
    for (map_id, version), status in maps.items():
        if status == "ENABLED":
            enabled.setdefault(map_id, []).append(version)
    for map_id, versions in sorted(enabled.items()):
        if len(versions) > 1:
            text = f"map {map_id!r} ENABLED in versions {', '.join(sorted(versions))} at once"
            return [("R89", text, Severity.VIOLATION)]
    gone = sorted(set(before) - set(maps))
    deleted = any(s == FINISHED and t == "deleteMap" for s, t in shown.values())
    if gone and state.maps is not None and not deleted:
        map_id, version = gone[0]
        text = f"map {map_id!r} version {version!r} left maps without a deleteMap FINISHED"
        return [("R91", text, Severity.VIOLATION)]
    return []
