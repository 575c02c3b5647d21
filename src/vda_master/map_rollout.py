"""Master control as the fleet's map server, and map versions rolled out to the fleet (VDA 5050
§6.7; docs/master.md, *Maps*).

Mixed into :class:`vda_master.service.MasterService`:

- ``PUT /maps/{mapId}/{mapVersion}`` stores a map file (:mod:`vda_master.map_library`);
  ``GET …/file`` serves it to the vehicles (the link carries a token, vehicles present no key);
- ``POST …/distribute`` sends ``downloadMap`` (the link, the file's SHA-256 as ``mapHash``)
  to every vehicle chosen that does not hold the version; with ``enable``, each is sent
  ``enableMap`` as soon as its state lists the version (R88: DISABLED, once downloaded), and
  one that holds it DISABLED already is sent it at once;
- ``POST …/enable`` sends ``enableMap`` to every vehicle chosen that holds the version
  DISABLED (a map switch at a time of the operator's choosing, after a distribution).

Each vehicle is checked and sent its action as by its own ``instantActions`` endpoint, and the
answer lists every vehicle: 202 with the actionId, 200 when it needs nothing, or the status and
reason it was not sent one (offline, a 2.0 vehicle, a factsheet without the action). A
download to enable waits in memory (a restart forgets it: distribute again, the vehicles that
hold the version are then only enabled). Logged: ``maps.uploaded``, ``maps.deleted``,
``maps.distributed``, ``maps.enabling``, ``maps.download_failed``.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING
from urllib.parse import quote

import structlog

from vda5050.clock import Clock, format_timestamp
from vda5050.models import MapStatus, State
from vda5050.topics import AgvId
from vda_master.capabilities import ActionSpec
from vda_master.config import MasterConfig
from vda_master.fleet import FleetView, VehicleView
from vda_master.map_library import MapConflictError, MapLibrary, StoredMap, id_problem
from vda_master.map_rules import (
    Follow,
    MapKey,
    MapStep,
    PendingEnable,
    Send,
    describe,
    distribution_step,
    enabling_step,
    follow_download,
    held_maps,
)
from vda_master.requests import RequestError

log = structlog.get_logger()

#: Hosts that are no address a vehicle can reach (the API listens on every interface).
WILDCARD_HOSTS = frozenset({"", "0.0.0.0", "::", "[::]"})  # noqa: S104 - compared, not bound


@dataclass(frozen=True, slots=True)
class MapOutcome:
    """What one vehicle was sent for a map version: ``status`` 202 with ``action_ids``, 200
    (nothing needed) or the refusal's status, with ``detail``."""

    agv: AgvId
    status: int
    action_ids: tuple[str, ...] = ()
    detail: str | None = None


def key_of(map_id: str, map_version: str) -> MapKey:
    """The pair as an API path names it; 422 for a mapId or mapVersion that cannot be one."""
    problem = id_problem(map_id, "mapId") or id_problem(map_version, "mapVersion")
    if problem is not None:
        raise RequestError(422, problem)
    return (map_id, map_version)


class MapRollout:
    """The map files, and the downloads waiting to be enabled."""

    config: MasterConfig
    clock: Clock
    fleet: FleetView

    if TYPE_CHECKING:

        def send_instant_actions(self, agv: AgvId, specs: list[ActionSpec]) -> list[str]: ...
        def known_vehicle(self, agv: AgvId) -> VehicleView: ...

    def _init_map_rollout(self) -> None:
        self.map_library = MapLibrary(self.config.data_dir / "maps")
        #: Downloads to enable once the vehicle lists the version (kept in the map folder).
        self._map_enables: dict[AgvId, PendingEnable] = {}
        for entry in self.map_library.pending_enables():
            key = (entry["mapId"], entry["mapVersion"])
            if self.map_library.get(key) is not None:  # a deleted version is enabled by no one
                agv = AgvId(entry["manufacturer"], entry["serialNumber"])
                self._map_enables[agv] = PendingEnable(key, entry["actionId"])
        if self._map_enables:
            log.info("maps.enables_resumed", vehicles=len(self._map_enables))
        #: The port the API really listens on, once it does (the runtime sets this: with
        #: ``api_port: 0`` only the server knows it).
        self.listening_port: Callable[[], int | None] = lambda: None

    def api_base(self) -> str | None:
        """The API's address as vehicles reach it: ``public_url``, else the address it
        listens on, unless that is a wildcard (every interface) or not known yet."""
        config = self.config
        if config.public_url:
            return config.public_url.rstrip("/")
        port = self.listening_port() or config.api_port
        if config.api_host in WILDCARD_HOSTS or not port:
            return None
        host = f"[{config.api_host}]" if ":" in config.api_host else config.api_host
        return f"http://{host}:{port}"

    # -- files ---------------------------------------------------------------------------------

    async def upload_map(self, key: MapKey, content: bytes) -> tuple[StoredMap, bool]:
        """Store a map file; (it, whether it is new). 422 empty, 409 other content under the
        pair, 503 the folder cannot be written."""
        if not content:
            raise RequestError(422, "the map file is empty: send its bytes as the request body")
        uploaded = format_timestamp(self.clock.now())
        try:
            stored, created = await asyncio.to_thread(self.map_library.put, key, content, uploaded)
        except MapConflictError as exc:
            raise RequestError(409, str(exc)) from None
        except OSError as exc:
            folder = self.map_library.folder
            raise RequestError(503, f"cannot write the map file under {folder}: {exc}") from None
        if created:
            log.info("maps.uploaded", map=describe(key), size_bytes=stored.size_bytes)
        return stored, created

    def stored_map(self, key: MapKey) -> StoredMap:
        """The stored version; 404 when there is none."""
        stored = self.map_library.get(key)
        if stored is None:
            raise RequestError(404, f"{describe(key)} is not stored on master control")
        return stored

    def remove_map(self, key: MapKey) -> None:
        """Delete the stored file (vehicles keep what they downloaded: deleteMap); 404."""
        if not self.map_library.delete(key):
            raise RequestError(404, f"{describe(key)} is not stored on master control")
        for agv in [a for a, p in self._map_enables.items() if p.key == key]:
            del self._map_enables[agv]
        self._keep_enables()
        log.info("maps.deleted", map=describe(key))

    def download_link(self, key: MapKey) -> str:
        """The ``mapDownloadLink`` of a stored version; 409 when master control does not know
        the address vehicles reach it at."""
        base = self.api_base()
        if base is None:
            raise RequestError(
                409,
                "master control does not know the address vehicles reach its HTTP API at "
                f"(api_host {self.config.api_host!r}): set public_url (VDA_PUBLIC_URL)",
            )
        path = "/".join(quote(part, safe="") for part in key)
        return f"{base}/maps/{path}/file?token={self.map_library.token(key)}"

    # -- the fleet -----------------------------------------------------------------------------

    def distribute_map(
        self,
        key: MapKey,
        *,
        manufacturer: str | None = None,
        serial_numbers: Iterable[str] | None = None,
        enable: bool = False,
    ) -> list[MapOutcome]:
        """``downloadMap`` (and with ``enable``, ``enableMap`` once downloaded) to the chosen
        vehicles (module docstring). 404 for a version not stored or no vehicle chosen."""
        stored = self.stored_map(key)
        link = self.download_link(key)
        outcomes = []
        for vehicle in self._chosen(manufacturer, serial_numbers):
            step = distribution_step(vehicle.state, vehicle.version, key, enable=enable)
            outcome = self._send_map_step(vehicle, step, key, link=link, sha256=stored.sha256)
            if enable and step.send is Send.DOWNLOAD and outcome.status == 202:  # noqa: PLR2004
                self._map_enables[vehicle.agv] = PendingEnable(key, outcome.action_ids[0])
            outcomes.append(outcome)
        if enable:
            self._keep_enables()
        _log_outcomes("maps.distributed", key, outcomes, enable=enable)
        return outcomes

    def enable_map(
        self,
        key: MapKey,
        *,
        manufacturer: str | None = None,
        serial_numbers: Iterable[str] | None = None,
    ) -> list[MapOutcome]:
        """``enableMap`` to the chosen vehicles that hold ``key`` DISABLED (the version need not
        be stored here: a vehicle may have it from elsewhere)."""
        outcomes = []
        for vehicle in self._chosen(manufacturer, serial_numbers):
            step = enabling_step(vehicle.state, vehicle.version, key)
            outcomes.append(self._send_map_step(vehicle, step, key))
        _log_outcomes("maps.enabling", key, outcomes)
        return outcomes

    def follow_map_downloads(self, agv: AgvId, state: State) -> None:
        """A state of a vehicle with a download to enable: enable it once it is listed."""
        pending = self._map_enables.get(agv)
        if pending is None:
            return
        follow, why = follow_download(state, pending)
        if follow is Follow.WAIT:
            return
        del self._map_enables[agv]
        self._keep_enables()
        if follow is Follow.FAILED:
            log.warning("maps.download_failed", agv=str(agv), map=describe(pending.key), why=why)
        elif follow is Follow.ENABLE:
            outcome = self._send_map_step(
                self.known_vehicle(agv), MapStep(Send.ENABLE), pending.key
            )
            _log_outcomes("maps.enabling", pending.key, [outcome])

    def _keep_enables(self) -> None:
        """Write the downloads to enable to the map folder; a failure is logged (they are
        still enabled while master control runs)."""
        entries = [
            {
                "manufacturer": agv.manufacturer,
                "serialNumber": agv.serial_number,
                "mapId": pending.key[0],
                "mapVersion": pending.key[1],
                "actionId": pending.action_id,
            }
            for agv, pending in self._map_enables.items()
        ]
        try:
            self.map_library.keep_pending_enables(entries)
        except OSError as exc:
            log.warning(
                "maps.pending_not_kept", folder=str(self.map_library.folder), error=str(exc)
            )

    def map_overview(self) -> list[dict[str, object]]:
        """``GET /maps``: every version stored here or held by a vehicle, with the vehicles
        that hold it and its status on each."""
        holders: dict[MapKey, list[dict[str, object]]] = {}
        for vehicle in self.fleet:
            for key, status in held_maps(vehicle.state).items():
                holders.setdefault(key, []).append(_holder(vehicle.agv, status))
        keys = sorted({*holders, *(m.key for m in self.map_library.all())})
        return [self._map_document(key, holders.get(key, [])) for key in keys]

    def map_document(self, key: MapKey) -> dict[str, object]:
        """``GET /maps/{mapId}/{mapVersion}``; 404 when neither stored nor held."""
        holders = [
            _holder(v.agv, status)
            for v in self.fleet
            if (status := held_maps(v.state).get(key)) is not None
        ]
        if not holders and self.map_library.get(key) is None:
            raise RequestError(404, f"{describe(key)} is neither stored nor held by a vehicle")
        return self._map_document(key, holders)

    def _map_document(self, key: MapKey, holders: list[dict[str, object]]) -> dict[str, object]:
        stored = self.map_library.get(key)
        return {
            "mapId": key[0],
            "mapVersion": key[1],
            "stored": stored is not None,
            "sizeBytes": stored.size_bytes if stored else None,
            "sha256": stored.sha256 if stored else None,
            "uploaded": stored.uploaded if stored else None,
            "vehicles": holders,
            "enablingAfterDownload": sorted(
                f"{a.manufacturer}/{a.serial_number}"
                for a, p in self._map_enables.items()
                if p.key == key
            ),
        }

    def _chosen(
        self, manufacturer: str | None, serial_numbers: Iterable[str] | None
    ) -> list[VehicleView]:
        """The vehicles of ``manufacturer`` (any) and ``serial_numbers`` (any); 404 for a
        serialNumber or manufacturer no known vehicle has."""
        wanted = None if serial_numbers is None else set(serial_numbers)
        chosen = [
            v
            for v in self.fleet
            if (manufacturer is None or v.agv.manufacturer == manufacturer)
            and (wanted is None or v.agv.serial_number in wanted)
        ]
        of = "" if manufacturer is None else f" of manufacturer {manufacturer!r}"
        missing = sorted((wanted or set()) - {v.agv.serial_number for v in chosen})
        if missing:
            raise RequestError(404, f"no vehicle{of} with serialNumber {missing[0]!r} is known")
        if not chosen:
            raise RequestError(404, f"no vehicle{of} is known")
        return chosen

    def _send_map_step(
        self,
        vehicle: VehicleView,
        step: MapStep,
        key: MapKey,
        *,
        link: str | None = None,
        sha256: str | None = None,
    ) -> MapOutcome:
        agv = vehicle.agv
        if step.refused is not None:
            detail = f"vehicle {agv} cannot take {describe(key)}: {step.detail}"
            return MapOutcome(agv, step.refused, detail=detail)
        if step.send is Send.NOTHING:
            return MapOutcome(agv, 200, detail=step.detail)
        parameters: dict[str, str] = {"mapId": key[0], "mapVersion": key[1]}
        if step.send is Send.DOWNLOAD and link is not None:
            parameters["mapDownloadLink"] = link
            if sha256 is not None and _takes_hash(vehicle):
                parameters["mapHash"] = sha256
        try:
            ids = self.send_instant_actions(agv, [ActionSpec(step.send.value, None, parameters)])
        except RequestError as exc:
            return MapOutcome(agv, exc.status, detail=exc.message)
        return MapOutcome(agv, 202, tuple(ids))


def _takes_hash(vehicle: VehicleView) -> bool:
    """Whether ``mapHash`` may go with ``downloadMap``: unless the factsheet declares the
    action's parameters without it (an undeclared parameter is refused, R112)."""
    declared = None if vehicle.factsheet is None else vehicle.factsheet.action(Send.DOWNLOAD.value)
    if declared is None or not declared.action_parameters:
        return True
    return any(p.key == "mapHash" for p in declared.action_parameters)


def _holder(agv: AgvId, status: MapStatus) -> dict[str, object]:
    return {
        "manufacturer": agv.manufacturer,
        "serialNumber": agv.serial_number,
        "mapStatus": status.value,
    }


def _log_outcomes(
    event: str, key: MapKey, outcomes: list[MapOutcome], *, enable: bool | None = None
) -> None:
    sent = [str(o.agv) for o in outcomes if o.status == 202]  # noqa: PLR2004 - HTTP status
    refused = [o.detail for o in outcomes if o.status >= 400]  # noqa: PLR2004 - HTTP status
    extra = {} if enable is None else {"enable": enable}
    log.info(event, map=describe(key), sent=sent, refused=refused, **extra)
