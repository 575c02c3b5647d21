"""The map files master control serves to its vehicles (VDA 5050 §6.7.3: the vehicle pulls a
map from the ``mapDownloadLink`` that ``downloadMap`` names; master control is that map server).

Each map version (mapId, mapVersion) is one file under ``<data_dir>/maps``, named by a digest of
the pair (any mapId is a safe file name then), with a JSON sidecar holding the pair, its SHA-256
(sent as ``mapHash``), its size and when it was uploaded. A version never changes its content:
vehicles refuse a second download of a pair they hold (R87), so a different file needs a new
mapVersion. Files are written to a temporary name and renamed, so a crash never leaves half a
map under a pair; the library is read from the folder at start, so maps outlive restarts.

Download links carry a token, an HMAC of the pair under a secret kept in the folder
(``.link-secret``, created on first use): a vehicle presents no API key, and the link works for
the pair it was made for only.

The downloads waiting to be enabled (``POST …/distribute`` with ``enable``) are kept in the
folder too (``.pending-enables``), so a restart of master control between a vehicle's download
and its enable does not leave the new version disabled.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import json
import secrets
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Final

import structlog

from vda_master.files import write_atomically
from vda_master.map_rules import MapKey, describe

log = structlog.get_logger()

#: Longest mapId or mapVersion accepted (the schemas set no limit; this keeps names sane).
MAX_ID_LENGTH: Final = 200
SECRET_FILE: Final = ".link-secret"  # noqa: S105 - a file name
#: The downloads to enable once done (no ``.json`` suffix: the sidecars are every ``*.json``).
PENDING_FILE: Final = ".pending-enables"
_SIDECAR: Final = ".json"
_CONTENT: Final = ".map"


class MapConflictError(Exception):
    """The pair is stored with other content (a map version never changes)."""


@dataclass(frozen=True, slots=True)
class StoredMap:
    """One map version the library holds."""

    map_id: str
    map_version: str
    sha256: str
    size_bytes: int
    uploaded: str

    @property
    def key(self) -> MapKey:
        return (self.map_id, self.map_version)


def id_problem(value: str, what: str) -> str | None:
    """Why ``value`` cannot be a mapId or mapVersion (``what``), or None."""
    if not value.strip():
        return f"{what} must not be empty"
    if len(value) > MAX_ID_LENGTH:
        return f"{what} is longer than {MAX_ID_LENGTH} characters"
    if any(ord(c) < 0x20 or ord(c) == 0x7F for c in value):  # noqa: PLR2004 - control chars
        return f"{what} contains a control character"
    return None


class MapLibrary:
    """Map files in one folder (created on the first upload)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self._maps: dict[MapKey, StoredMap] = {}
        self._secret: bytes | None = None
        if folder.is_dir():
            self._load()

    def _load(self) -> None:
        for sidecar in sorted(self.folder.glob(f"*{_SIDECAR}")):
            try:
                stored = StoredMap(**json.loads(sidecar.read_text("utf-8")))
            except (OSError, ValueError, TypeError) as exc:
                log.warning("maps.unreadable", file=str(sidecar), error=str(exc))
                continue
            if self._content(stored.key).is_file():
                self._maps[stored.key] = stored
            else:
                log.warning("maps.content_missing", file=str(sidecar), map=describe(stored.key))

    def all(self) -> list[StoredMap]:
        """Every stored version, by mapId and mapVersion."""
        return [self._maps[k] for k in sorted(self._maps)]

    def get(self, key: MapKey) -> StoredMap | None:
        return self._maps.get(key)

    def content_path(self, stored: StoredMap) -> Path:
        """The file holding ``stored``'s bytes."""
        return self._content(stored.key)

    def put(self, key: MapKey, content: bytes, uploaded: str) -> tuple[StoredMap, bool]:
        """Store ``content`` as ``key``; (the stored map, whether it is new). The same content
        again is no change; other content raises :class:`MapConflictError`. Blocking file I/O:
        run it in a worker thread."""
        digest = hashlib.sha256(content).hexdigest()
        known = self._maps.get(key)
        if known is not None:
            if known.sha256 == digest:
                return known, False
            msg = (
                f"{describe(key)} is stored with other content (sha256 {known.sha256}); a map "
                "version never changes (vehicles refuse a version they hold, §6.7.3): upload "
                "it as a new mapVersion"
            )
            raise MapConflictError(msg)
        stored = StoredMap(key[0], key[1], digest, len(content), uploaded)
        write_atomically(self._content(key), content)
        write_atomically(self._sidecar(key), json.dumps(asdict(stored)).encode())
        self._maps[key] = stored
        return stored, True

    def delete(self, key: MapKey) -> bool:
        """Remove ``key``'s file; False when it is not stored."""
        if self._maps.pop(key, None) is None:
            return False
        for path in (self._sidecar(key), self._content(key)):
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
        return True

    def pending_enables(self) -> list[dict[str, str]]:
        """The downloads to enable as :meth:`keep_pending_enables` last wrote them; none when
        there is no such file, or an unreadable one (logged)."""
        path = self.folder / PENDING_FILE
        try:
            entries = json.loads(path.read_text("utf-8"))
        except FileNotFoundError:
            return []
        except (OSError, ValueError) as exc:
            log.warning("maps.pending_unreadable", file=str(path), error=str(exc))
            return []
        fields = ("manufacturer", "serialNumber", "mapId", "mapVersion", "actionId")
        if not isinstance(entries, list) or not all(
            isinstance(e, dict) and all(isinstance(e.get(f), str) for f in fields) for e in entries
        ):
            log.warning("maps.pending_unreadable", file=str(path), error="not a list of enables")
            return []
        return [{f: e[f] for f in fields} for e in entries]

    def keep_pending_enables(self, entries: list[dict[str, str]]) -> None:
        """Write the downloads to enable (blocking, but a few hundred bytes and rare: when a
        distribution starts and when a download is enabled or fails)."""
        write_atomically(self.folder / PENDING_FILE, json.dumps(entries).encode())

    def token(self, key: MapKey) -> str:
        """The download token of ``key`` (stable across restarts)."""
        message = f"{key[0]}\0{key[1]}".encode()
        return hmac.new(self._link_secret(), message, hashlib.sha256).hexdigest()[:32]

    def token_matches(self, key: MapKey, token: str | None) -> bool:
        return token is not None and hmac.compare_digest(self.token(key), token)

    def _link_secret(self) -> bytes:
        if self._secret is None:
            path = self.folder / SECRET_FILE
            if not path.is_file():
                write_atomically(path, secrets.token_hex(32).encode(), mode=0o600)
            self._secret = path.read_bytes().strip()
        return self._secret

    def _name(self, key: MapKey) -> str:
        return hashlib.sha256(f"{key[0]}\0{key[1]}".encode()).hexdigest()

    def _content(self, key: MapKey) -> Path:
        return self.folder / f"{self._name(key)}{_CONTENT}"

    def _sidecar(self, key: MapKey) -> Path:
        return self.folder / f"{self._name(key)}{_SIDECAR}"
