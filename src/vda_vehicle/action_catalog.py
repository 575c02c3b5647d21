"""The actions this vehicle performs: scopes, parameters, durations and effects (§6.8, §6.8.2).

The factsheet's ``agvActions`` is built from this table, and orders are checked against it, so
what the vehicle declares and what it does cannot drift apart (R31, R111).

Triggering ``waitForTrigger``: master control sends the vendor instant action ``trigger`` with
parameter ``actionId`` = the id of the waiting ``waitForTrigger`` action; that action then
finishes. ``trigger`` is declared in the factsheet like every other action.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Final

from vda5050.models import ActionScope, ActionStatus, Load
from vda5050.models.factsheet import ValueDataType
from vda_vehicle.actions import (
    ActionSpec,
    Effect,
    EffectResult,
    ParameterSpec,
    moved,
    pause_all,
    record_of,
    replace_record,
    resume_all,
)
from vda_vehicle.faults import action_error
from vda_vehicle.maps import DELETE_MAP, DOWNLOAD_MAP, ENABLE_MAP, delete_map, enable_map
from vda_vehicle.model import ActionRecord, Pose, VehicleState

INSTANT, NODE, EDGE = ActionScope.INSTANT, ActionScope.NODE, ActionScope.EDGE
ONLY_INSTANT = frozenset({INSTANT})
STR, NUM = ValueDataType.STRING, ValueDataType.NUMBER
#: The vendor-specific instant action that releases a ``waitForTrigger`` (module docstring).
TRIGGER: Final = "trigger"


def _text(record: ActionRecord, key: str) -> str | None:
    value = record.action.parameter(key)
    return value if isinstance(value, str) else None


def _number(record: ActionRecord, key: str) -> float | None:
    value = record.action.parameter(key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


def start_pause(state: VehicleState, record: ActionRecord) -> EffectResult:
    """R76: motion stops and running actions pause; ``paused`` becomes true."""
    return EffectResult(pause_all(state, keep=record.action_id))


def stop_pause(state: VehicleState, _record: ActionRecord) -> EffectResult:
    """R76: paused actions resume and ``paused`` becomes false."""
    return EffectResult(resume_all(state))


def start_charging(state: VehicleState, _record: ActionRecord) -> EffectResult:
    """R77: ``batteryState.charging`` becomes true."""
    return EffectResult(replace(state, charging=True))


def stop_charging(state: VehicleState, _record: ActionRecord) -> EffectResult:
    """R77: ``batteryState.charging`` becomes false."""
    return EffectResult(replace(state, charging=False))


def init_position(state: VehicleState, record: ActionRecord) -> EffectResult:
    """R78: pose, mapId and lastNodeId become the parameters; refused while an order runs."""
    x, y, theta = (_number(record, key) for key in ("x", "y", "theta"))
    map_id, last_node = _text(record, "mapId"), _text(record, "lastNodeId")
    if x is None or y is None or theta is None or map_id is None or last_node is None:
        return _failed(state, record, "initPosition needs x, y, theta, mapId and lastNodeId")
    if not -math.pi <= theta <= math.pi:
        return _failed(state, record, "initPosition theta must lie in [-pi, pi]")
    if record.scope is INSTANT and state.nodes:
        return _failed(state, record, "initPosition conflicts with the running order (§6.9)")
    pose = Pose(x, y, theta, map_id)
    changes = {"pose": pose, "last_node_id": last_node, "position_initialized": True}
    return EffectResult(replace(state, distance_since_last_node=0.0, **changes))  # type: ignore[arg-type]


def pick(state: VehicleState, record: ActionRecord) -> EffectResult:
    """R81: the picked load appears in ``loads``; a handling device already loaded fails."""
    lhd = _text(record, "lhd")
    if any(load.load_position == lhd for load in state.loads):
        return _failed(state, record, f"load handling device {lhd or 'default'} is occupied")
    load = Load(
        load_id=_text(record, "loadId"), load_type=_text(record, "loadType"), load_position=lhd
    )
    return EffectResult(replace(state, loads=(*state.loads, load)))


def drop(state: VehicleState, record: ActionRecord) -> EffectResult:
    """R81: the dropped load leaves ``loads``: the first on the ``lhd`` asked for, with the
    ``loadId`` and ``loadType`` asked for; dropping with no such load fails."""
    lhd, load_id = _text(record, "lhd"), _text(record, "loadId")
    load_type = _text(record, "loadType")
    for load in state.loads:
        if (
            (lhd is None or load.load_position == lhd)
            and load_id in (None, load.load_id)
            and load_type in (None, load.load_type)
        ):
            remaining = tuple(held for held in state.loads if held is not load)
            return EffectResult(replace(state, loads=remaining))
    return _failed(state, record, "there is no matching load to drop")


def state_request(state: VehicleState, _record: ActionRecord) -> EffectResult:
    """R79: the FINISHED stateRequest goes out in the state it triggers."""
    return EffectResult(state.bumped())


def factsheet_request(state: VehicleState, _record: ActionRecord) -> EffectResult:
    """R80: the shell publishes the factsheet when it sees the request flag."""
    return EffectResult(replace(state, factsheet_requested=True))


def log_report(state: VehicleState, record: ActionRecord) -> EffectResult:
    """§6.8.2: the log's name is reported as the action's resultDescription."""
    count = state.log_count + 1
    reason = _text(record, "reason") or "unspecified"
    return EffectResult(replace(state, log_count=count), result=f"log-{count:04d} ({reason})")


def trigger(state: VehicleState, record: ActionRecord) -> EffectResult:
    """Finish the RUNNING waitForTrigger named by parameter ``actionId``."""
    target_id = _text(record, "actionId") or ""
    target = record_of(state, target_id)
    if (
        target is None
        or target.action_type != "waitForTrigger"
        or target.status is not ActionStatus.RUNNING
    ):
        return _failed(state, record, f"no running waitForTrigger {target_id!r}")
    result = f"triggered by {record.action_id}"
    done = moved(target, ActionStatus.FINISHED, remaining_s=0.0, result=result)
    return EffectResult(replace_record(state, done))


def _failed(state: VehicleState, record: ActionRecord, description: str) -> EffectResult:
    return EffectResult(state, error=action_error(record.action, description))


def _result(text: str) -> Effect:
    def effect(state: VehicleState, _record: ActionRecord) -> EffectResult:
        return EffectResult(state, result=text)

    return effect


def _params(*items: tuple[str, ValueDataType, str, bool]) -> tuple[ParameterSpec, ...]:
    return tuple(ParameterSpec(key, kind, text, optional) for key, kind, text, optional in items)


_PICK_DROP = (
    ("lhd", STR, "load handling device (loadSpecification.loadPositions)", True),
    ("stationType", STR, "type of the station", False),
    ("stationName", STR, "name of the station", True),
    ("loadType", STR, "type of the load", False),
    ("loadId", STR, "id of the load", True),
    ("height", NUM, "height of the load bottom above the floor, m", True),
)


_MAP_PAIR = (("mapId", STR, "map", False), ("mapVersion", STR, "version of the map", False))


def default_catalog() -> dict[str, ActionSpec]:
    """Every action this vehicle performs, with default durations in (simulated) seconds."""
    specs = [
        ActionSpec(
            "startPause", "stop driving and pause actions", ONLY_INSTANT, effect=start_pause
        ),
        ActionSpec("stopPause", "resume driving and actions", ONLY_INSTANT, effect=stop_pause),
        ActionSpec(
            "startCharging",
            "connect the charger",
            frozenset({INSTANT, NODE}),
            run_s=2.0,
            effect=start_charging,
        ),
        ActionSpec(
            "stopCharging",
            "disconnect the charger",
            frozenset({INSTANT, NODE}),
            run_s=1.0,
            effect=stop_charging,
        ),
        ActionSpec(
            "initPosition",
            "set pose and lastNodeId",
            frozenset({INSTANT, NODE}),
            _params(
                ("x", NUM, "m", False),
                ("y", NUM, "m", False),
                ("theta", NUM, "rad", False),
                ("mapId", STR, "map", False),
                ("lastNodeId", STR, "node", False),
            ),
            effect=init_position,
        ),
        ActionSpec("stateRequest", "publish a state", ONLY_INSTANT, effect=state_request),
        ActionSpec(
            "factsheetRequest", "publish the factsheet", ONLY_INSTANT, effect=factsheet_request
        ),
        ActionSpec(
            "logReport",
            "write a log",
            ONLY_INSTANT,
            _params(("reason", STR, "why the log is wanted", False)),
            run_s=1.0,
            effect=log_report,
            result_description="name of the log",
        ),
        # Runs until instant.finish_cancel sees the vehicle stopped and the order actions ended.
        ActionSpec("cancelOrder", "cancel the running order", frozenset({INSTANT}), run_s=math.inf),
        ActionSpec(
            "pick",
            "pick up a load",
            frozenset({NODE, EDGE}),
            _params(*_PICK_DROP),
            init_s=1.0,
            run_s=3.0,
            interruptible=False,
            effect=pick,
        ),
        ActionSpec(
            "drop",
            "put down a load",
            frozenset({NODE, EDGE}),
            tuple(replace(p, optional=True) for p in _params(*_PICK_DROP)),
            init_s=1.0,
            run_s=3.0,
            interruptible=False,
            effect=drop,
        ),
        ActionSpec(
            "detectObject",
            "look for an object",
            frozenset({NODE, EDGE}),
            _params(("objectType", STR, "kind of object", True)),
            run_s=1.0,
            effect=_result("detected"),
        ),
        ActionSpec(
            "finePositioning",
            "align precisely at a station",
            frozenset({NODE, EDGE}),
            _params(
                ("stationType", STR, "type of the station", True),
                ("stationName", STR, "name of the station", True),
            ),
            run_s=2.0,
        ),
        ActionSpec(
            "waitForTrigger",
            "wait until the trigger instant action arrives",
            frozenset({NODE}),
            _params(("triggerType", STR, "what is awaited", False)),
            run_s=math.inf,
        ),
        # Map distribution (§6.7; vda_vehicle.maps), declared by 2.1 and 3.0 vehicles only.
        ActionSpec(
            DOWNLOAD_MAP,
            "fetch a map from mapDownloadLink and hold it DISABLED",
            ONLY_INSTANT,
            _params(
                *_MAP_PAIR,
                ("mapDownloadLink", STR, "http:// or https:// address of the map file", False),
                ("mapHash", STR, "SHA-256 (or SHA-1, MD5) of the file, hex", True),
            ),
            # Ends when the shell's download does (maps.download_finished).
            run_s=math.inf,
            result_description="map ready, or why not",
        ),
        ActionSpec(
            ENABLE_MAP,
            "enable a held map version, disabling the mapId's others",
            frozenset({INSTANT, NODE}),
            _params(*_MAP_PAIR),
            effect=enable_map,
        ),
        ActionSpec(
            DELETE_MAP,
            "delete a held map version that is not in use",
            ONLY_INSTANT,
            _params(*_MAP_PAIR),
            effect=delete_map,
        ),
        ActionSpec(
            TRIGGER,
            "release the waitForTrigger given by actionId",
            ONLY_INSTANT,
            _params(("actionId", STR, "id of the waitForTrigger action", False)),
            effect=trigger,
        ),
    ]
    return {spec.action_type: spec for spec in specs}


#: The map distribution actions (§6.7), which a 2.0 vehicle does not offer (2.0 has no maps).
MAP_ACTIONS: Final = frozenset({DOWNLOAD_MAP, ENABLE_MAP, DELETE_MAP})


def for_version(catalog: Mapping[str, ActionSpec], vda_version: str) -> dict[str, ActionSpec]:
    """``catalog`` as a vehicle of ``vda_version`` offers it: no map actions in 2.0.0."""
    if vda_version != "2.0.0":
        return dict(catalog)
    return {key: spec for key, spec in catalog.items() if key not in MAP_ACTIONS}


def with_durations(
    catalog: Mapping[str, ActionSpec], durations_s: Mapping[str, float]
) -> dict[str, ActionSpec]:
    """``catalog`` with the run durations of ``durations_s`` (configurable, issue item 5)."""
    unknown = set(durations_s) - set(catalog)
    if unknown:
        msg = f"durations given for unknown actions: {sorted(unknown)}"
        raise ValueError(msg)
    return {
        key: replace(spec, run_s=durations_s[key]) if key in durations_s else spec
        for key, spec in catalog.items()
    }
