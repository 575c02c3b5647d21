"""The maps a vehicle holds and their distribution by master control (§6.7, 2.1 and 3.0; R87-R91).

A vehicle starts with one map per mapId of its graph, version ``1``, ENABLED. Master control
changes that with three instant actions (``enableMap`` also as a node action), declared in the
factsheet of 2.1 and 3.0 vehicles (2.0 has no maps):

- ``downloadMap`` (mapId, mapVersion, mapDownloadLink, mapHash optional) runs while the shell
  fetches the map (:mod:`vda_vehicle.map_download`) and then :func:`download_finished` ends
  it: the map is added DISABLED and the action FINISHED (R88), or the action FAILED with a
  WARNING saying why. A mapId and mapVersion already held fail at once with a
  ``duplicateMap`` WARNING (3.0 DUPLICATE_MAP) and leave every map as it was (R87); maps are
  reported only once they are ready.
- ``enableMap`` (mapId, mapVersion) enables that version and disables every other version of
  the mapId, so no two versions of one mapId are ever ENABLED (R89); an unknown pair FAILS (R90).
- ``deleteMap`` (mapId, mapVersion) removes the map (R91); an unknown pair, or the ENABLED map
  the vehicle stands on (in use), FAILS (R90). The vehicle never deletes a map on its own.

Orders may only use ENABLED maps (R35: an order naming another mapId is rejected).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Final

from vda5050.models import ActionStatus
from vda_vehicle.actions import EffectResult, moved, record_of, replace_record
from vda_vehicle.faults import action_error, duplicate_map, with_errors
from vda_vehicle.model import ActionRecord, HeldMap, VehicleState

#: The version of the maps a vehicle starts with (one per mapId of its graph).
FIRST_VERSION: Final = "1"
DOWNLOAD_MAP: Final = "downloadMap"
ENABLE_MAP: Final = "enableMap"
DELETE_MAP: Final = "deleteMap"
#: What a map download link may be (the vehicle fetches nothing else).
_SCHEMES: Final = ("http://", "https://")


def initial_maps(map_ids: Iterable[str]) -> tuple[HeldMap, ...]:
    """One ENABLED map per mapId, version :data:`FIRST_VERSION`, sorted by mapId."""
    return tuple(HeldMap(map_id, FIRST_VERSION, enabled=True) for map_id in sorted(map_ids))


def enabled_map_ids(state: VehicleState) -> frozenset[str]:
    """The mapIds an order may use: those with an ENABLED version."""
    return frozenset(held.map_id for held in state.maps if held.enabled)


def _pair(record: ActionRecord) -> tuple[str, str] | None:
    map_id = record.action.parameter("mapId")
    version = record.action.parameter("mapVersion")
    if isinstance(map_id, str) and isinstance(version, str):
        return map_id, version
    return None


def _held(state: VehicleState, map_id: str, version: str) -> HeldMap | None:
    return next((m for m in state.maps if (m.map_id, m.map_version) == (map_id, version)), None)


def _failed(state: VehicleState, record: ActionRecord, description: str) -> EffectResult:
    return EffectResult(state, error=action_error(record.action, description))


def enable_map(state: VehicleState, record: ActionRecord) -> EffectResult:
    """R89, R90: the requested version ENABLED, every other version of its mapId DISABLED."""
    pair = _pair(record)
    if pair is None:
        return _failed(state, record, "enableMap needs mapId and mapVersion")
    if _held(state, *pair) is None:
        return _failed(state, record, f"map {pair[0]!r} version {pair[1]!r} is not on the vehicle")
    map_id, version = pair
    maps = tuple(
        replace(m, enabled=m.map_version == version) if m.map_id == map_id else m
        for m in state.maps
    )
    return EffectResult(replace(state, maps=maps))


def delete_map(state: VehicleState, record: ActionRecord) -> EffectResult:
    """R90, R91: the map leaves ``maps``; not one the vehicle does not hold (any more), nor
    the ENABLED map it stands on."""
    pair = _pair(record)
    if pair is None:
        return _failed(state, record, "deleteMap needs mapId and mapVersion")
    held = _held(state, *pair)
    if held is None:
        return _failed(state, record, f"map {pair[0]!r} version {pair[1]!r} is not on the vehicle")
    if held.enabled and state.pose.map_id == held.map_id:
        return _failed(
            state, record, f"map {pair[0]!r} version {pair[1]!r} is in use (the vehicle is on it)"
        )
    return EffectResult(replace(state, maps=tuple(m for m in state.maps if m is not held)))


@dataclass(frozen=True, slots=True)
class DownloadRequest:
    """What the shell fetches for one ``downloadMap`` action."""

    action_id: str
    map_id: str
    map_version: str
    link: str
    map_hash: str | None


def download_request(state: VehicleState, action_id: str) -> DownloadRequest | str:
    """The download ``action_id`` asks for, or why it cannot start (then end it with
    :func:`download_finished`): R87, a pair already held, or missing or bad parameters."""
    record = record_of(state, action_id)
    if record is None:
        return f"no action {action_id!r}"
    pair = _pair(record)
    link = record.action.parameter("mapDownloadLink")
    if pair is None or not isinstance(link, str):
        return "downloadMap needs mapId, mapVersion and mapDownloadLink"
    if not link.startswith(_SCHEMES):
        return f"mapDownloadLink must be an http:// or https:// address, not {link!r}"
    if _held(state, *pair) is not None:
        return f"map {pair[0]!r} version {pair[1]!r} is already on the vehicle"
    map_hash = record.action.parameter("mapHash")
    return DownloadRequest(
        action_id, pair[0], pair[1], link, map_hash if isinstance(map_hash, str) else None
    )


def download_finished(state: VehicleState, action_id: str, problem: str | None) -> VehicleState:
    """End ``downloadMap`` ``action_id``: with no ``problem`` the map is added DISABLED and the
    action FINISHED (R88), else it FAILS with a WARNING naming ``problem``; every other map
    stays as it was (R87). An action that already ended (or is gone) is left alone."""
    record = record_of(state, action_id)
    if record is None or record.terminal:
        return state
    if record.status is not ActionStatus.RUNNING:  # fetched before its tick started it
        record = moved(record, ActionStatus.RUNNING)
    pair = _pair(record)
    if pair is None:
        error = action_error(record.action, "downloadMap needs mapId and mapVersion")
    elif _held(state, *pair) is not None:
        error = duplicate_map(record.action, *pair)
    elif problem is not None:
        error = action_error(record.action, problem)
    else:
        done = moved(record, ActionStatus.FINISHED, remaining_s=0.0, result="map ready")
        maps = (*state.maps, HeldMap(pair[0], pair[1], enabled=False))
        return replace_record(state, done).bumped(maps=maps)
    failed = moved(record, ActionStatus.FAILED, remaining_s=0.0, result=error.error_description)
    return replace_record(state, failed).bumped(errors=with_errors(state.errors, error))
