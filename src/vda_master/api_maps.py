"""``/maps``: master control as the fleet's map server (:mod:`vda_master.map_rollout`).

The handlers translate between HTTP and the service. A map file is the raw request body of
``PUT /maps/{mapId}/{mapVersion}`` (any content type, up to ``max_map_bytes``); ``GET
…/file`` serves it to whoever presents the link's token (the vehicles) or a viewer key.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import FastAPI, Query, Request
from fastapi.responses import FileResponse, Response

from vda_master.api_auth import Role, api_keys
from vda_master.api_errors import error_responses
from vda_master.api_models import (
    FleetActionOutcome,
    FleetActionOutcomes,
    MapDistribution,
    MapInfo,
    MapSelection,
)
from vda_master.map_rollout import MapOutcome, key_of
from vda_master.service import MasterService

#: Where map routes start; ``PUT`` bodies under it may be up to ``max_map_bytes``.
MAPS_PREFIX = "/maps/"


def add_map_routes(app: FastAPI, service: MasterService, reads: list[Any], acts: list[Any]) -> None:
    """The ``/maps`` routes; ``reads``/``acts``: the viewer and operator key dependencies."""
    keys = api_keys(service.config)

    @app.get("/maps", dependencies=reads, responses=error_responses(401))
    async def maps() -> list[MapInfo]:
        """Every map version stored here or held by a vehicle, with the vehicles that hold
        it."""
        return [MapInfo.model_validate(d) for d in service.map_overview()]

    @app.get(
        "/maps/{map_id}/{map_version}", dependencies=reads, responses=error_responses(401, 404)
    )
    async def map_version(map_id: str, map_version: str) -> MapInfo:
        return MapInfo.model_validate(service.map_document(key_of(map_id, map_version)))

    @app.put(
        "/maps/{map_id}/{map_version}",
        dependencies=acts,
        status_code=201,
        responses={
            200: {"description": "the same file was stored already"},
            **error_responses(401, 403, 409, 413, 422, 503),
        },
    )
    async def upload(map_id: str, map_version: str, request: Request) -> Response:
        """Store a map file (the request body, any content type) as this map version. A
        version never changes: the same bytes again answer 200, other bytes 409."""
        key = key_of(map_id, map_version)
        _, created = await service.upload_map(key, await request.body())
        document = MapInfo.model_validate(service.map_document(key))
        return Response(
            document.model_dump_json(by_alias=True),
            status_code=201 if created else 200,
            media_type="application/json",
        )

    @app.delete(
        "/maps/{map_id}/{map_version}",
        dependencies=acts,
        status_code=204,
        responses=error_responses(401, 403, 404, 422),
    )
    async def delete(map_id: str, map_version: str) -> Response:
        """Delete the stored file; vehicles keep what they downloaded (``deleteMap``)."""
        service.remove_map(key_of(map_id, map_version))
        return Response(status_code=204)

    @app.get(
        "/maps/{map_id}/{map_version}/file",
        response_class=FileResponse,
        responses=error_responses(401, 403, 404, 422),
    )
    async def map_file(
        map_id: str,
        map_version: str,
        request: Request,
        token: Annotated[str | None, Query(description="the download link's token")] = None,
    ) -> FileResponse:
        """The map file, for the ``mapDownloadLink`` of ``downloadMap``: with the link's token,
        or a viewer key."""
        key = key_of(map_id, map_version)
        if not service.map_library.token_matches(key, token):
            keys.require(request, Role.VIEWER)
        stored = service.stored_map(key)
        return FileResponse(
            service.map_library.content_path(stored),
            media_type="application/octet-stream",
            headers={"ETag": f'"{stored.sha256}"'},
        )

    @app.post(
        "/maps/{map_id}/{map_version}/distribute",
        dependencies=acts,
        responses=error_responses(401, 403, 404, 409, 413, 415, 422),
    )
    async def distribute(
        map_id: str, map_version: str, body: MapDistribution
    ) -> FleetActionOutcomes:
        """``downloadMap`` to every vehicle chosen that does not hold the version (the link to
        its file here, its SHA-256 as ``mapHash``); with ``enable``, ``enableMap`` once each
        holds it. Per vehicle: 202 sent, 200 nothing needed, or why it was not sent one."""
        outcomes = service.distribute_map(
            key_of(map_id, map_version),
            manufacturer=body.manufacturer,
            serial_numbers=body.serial_numbers,
            enable=body.enable,
        )
        return _outcomes(outcomes)

    @app.post(
        "/maps/{map_id}/{map_version}/enable",
        dependencies=acts,
        responses=error_responses(401, 403, 404, 413, 415, 422),
    )
    async def enable(map_id: str, map_version: str, body: MapSelection) -> FleetActionOutcomes:
        """``enableMap`` to every vehicle chosen that holds the version DISABLED (the other
        versions of its mapId are disabled by the vehicle, §6.7.4)."""
        outcomes = service.enable_map(
            key_of(map_id, map_version),
            manufacturer=body.manufacturer,
            serial_numbers=body.serial_numbers,
        )
        return _outcomes(outcomes)


def _outcomes(outcomes: list[MapOutcome]) -> FleetActionOutcomes:
    results = [
        FleetActionOutcome(
            manufacturer=o.agv.manufacturer,
            serial_number=o.agv.serial_number,
            status=o.status,
            action_ids=list(o.action_ids) or None,
            detail=o.detail,
        )
        for o in outcomes
    ]
    sent = sum(r.status == 202 for r in results)  # noqa: PLR2004 - HTTP status
    return FleetActionOutcomes(sent=sent, results=results)
