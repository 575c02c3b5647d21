"""Fetching a map for ``downloadMap`` (§6.7.3): the shell's side of :mod:`vda_vehicle.maps`.

The file at ``mapDownloadLink`` (http or https) is streamed, bounded in size and time, and
checked against ``mapHash`` when one is given. VDA 5050 does not name the hash function; a hex
digest of 64, 40 or 32 characters is taken as SHA-256, SHA-1 or MD5. The simulated vehicle
keeps no map contents: a map it fetched whole is ready.
"""

from __future__ import annotations

import hashlib
from typing import Final

import httpx

from vda_vehicle.maps import DownloadRequest

#: A larger map file is refused (the download stops there).
MAX_MAP_BYTES: Final = 64 * 1024 * 1024
#: Connect, read and write timeouts of one download, seconds.
TIMEOUT_S: Final = 30.0
_HASHES: Final = {64: "sha256", 40: "sha1", 32: "md5"}


async def fetch_map(request: DownloadRequest, *, max_bytes: int = MAX_MAP_BYTES) -> str | None:
    """None once the map file was fetched whole (and matches ``mapHash``), else why not."""
    expected = request.map_hash.strip().lower() if request.map_hash else None
    if expected is not None and len(expected) not in _HASHES:
        return f"mapHash {request.map_hash!r} is not a hex SHA-256, SHA-1 or MD5 digest"
    digest = hashlib.new(_HASHES[len(expected)] if expected else "sha256")
    problem = await _stream_into(digest, request.link, max_bytes)
    if problem is None and expected is not None and digest.hexdigest() != expected:
        problem = f"the map file does not match mapHash (its {digest.name} is {digest.hexdigest()})"
    return problem


async def _stream_into(digest: hashlib._Hash, link: str, max_bytes: int) -> str | None:
    """Stream the file at ``link`` into ``digest``; why that failed, if it did."""
    size = 0
    try:
        async with (
            httpx.AsyncClient(timeout=TIMEOUT_S, follow_redirects=True) as client,
            client.stream("GET", link) as response,
        ):
            if response.status_code != httpx.codes.OK:
                return f"the map server answered {response.status_code} for {link}"
            async for chunk in response.aiter_bytes():
                size += len(chunk)
                if size > max_bytes:
                    return f"the map file is larger than {max_bytes} bytes"
                digest.update(chunk)
    except httpx.HTTPError as exc:
        return f"cannot download {link}: {exc or type(exc).__name__}"
    return None if size else f"the map file at {link} is empty"
