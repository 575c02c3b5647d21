"""The map files master control serves (:mod:`vda_master.map_library`): kept across restarts,
never changed under a version, safe for any mapId, links that work for their version only."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
from structlog.testing import capture_logs

from vda_master.map_library import PENDING_FILE, MapConflictError, MapLibrary, id_problem

HALL_2 = ("hall", "2")
NOW = "2026-12-02T10:00:00.000Z"


def test_a_stored_map_outlives_the_library(tmp_path: Path) -> None:
    folder = tmp_path / "maps"
    library = MapLibrary(folder)
    assert library.all() == []
    assert not folder.exists()  # created on the first upload only
    stored, created = library.put(HALL_2, b"grid" * 100, NOW)
    assert created
    assert (stored.sha256, stored.size_bytes, stored.uploaded) == (
        hashlib.sha256(b"grid" * 100).hexdigest(),
        400,
        NOW,
    )
    reopened = MapLibrary(folder)
    assert reopened.all() == [stored]
    assert reopened.content_path(stored).read_bytes() == b"grid" * 100
    assert [p.name for p in folder.iterdir() if p.name.endswith(".tmp")] == []


def test_a_version_never_changes_its_content(tmp_path: Path) -> None:
    library = MapLibrary(tmp_path)
    first, _ = library.put(HALL_2, b"one", NOW)
    again, created = library.put(HALL_2, b"one", "later")
    assert (again, created) == (first, False)
    with pytest.raises(MapConflictError, match="upload it as a new mapVersion"):
        library.put(HALL_2, b"two", NOW)
    assert library.content_path(first).read_bytes() == b"one"


def test_any_map_id_stays_inside_the_folder(tmp_path: Path) -> None:
    folder = tmp_path / "maps"
    library = MapLibrary(folder)
    for key in [("../../etc", "passwd"), ("a/b", ".."), (".", "\\x")]:
        stored, _ = library.put(key, b"x", NOW)
        assert library.content_path(stored).parent == folder
    assert len(MapLibrary(folder).all()) == 3
    assert list(tmp_path.iterdir()) == [folder]


def test_delete_removes_the_file(tmp_path: Path) -> None:
    library = MapLibrary(tmp_path)
    stored, _ = library.put(HALL_2, b"x", NOW)
    assert library.delete(HALL_2)
    assert not library.delete(HALL_2)
    assert not library.content_path(stored).exists()
    assert MapLibrary(tmp_path).all() == []


def test_links_work_for_their_version_only_and_across_restarts(tmp_path: Path) -> None:
    library = MapLibrary(tmp_path)
    token = library.token(HALL_2)
    assert library.token_matches(HALL_2, token)
    assert not library.token_matches(("hall", "3"), token)
    assert not library.token_matches(HALL_2, None)
    assert not library.token_matches(HALL_2, token[:-1] + ("0" if token[-1] != "0" else "1"))
    assert MapLibrary(tmp_path).token(HALL_2) == token  # the secret is kept
    assert MapLibrary(tmp_path / "other").token(HALL_2) != token  # and is this master's own
    assert (tmp_path / ".link-secret").stat().st_mode & 0o077 == 0


def test_an_unreadable_sidecar_is_logged_and_left_out(tmp_path: Path) -> None:
    library = MapLibrary(tmp_path)
    library.put(HALL_2, b"x", NOW)
    (tmp_path / "broken.json").write_text("{not json")
    with capture_logs() as logs:
        again = MapLibrary(tmp_path)
    assert [m.key for m in again.all()] == [HALL_2]
    assert [entry["event"] for entry in logs] == ["maps.unreadable"]


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        ("", "mapId must not be empty"),
        ("  ", "mapId must not be empty"),
        ("a\nb", "mapId contains a control character"),
        ("x" * 201, "mapId is longer than 200 characters"),
    ],
)
def test_ids_that_cannot_name_a_map(value: str, problem: str) -> None:
    assert id_problem(value, "mapId") == problem
    assert id_problem("hall-3.b", "mapId") is None


def test_downloads_to_enable_are_kept_and_an_unreadable_file_is_none(tmp_path: Path) -> None:
    library = MapLibrary(tmp_path / "maps")
    assert library.pending_enables() == []
    entry = {
        "manufacturer": "acme",
        "serialNumber": "r1",
        "mapId": "hall",
        "mapVersion": "2",
        "actionId": "a1",
    }
    library.keep_pending_enables([entry])
    assert MapLibrary(tmp_path / "maps").pending_enables() == [entry]
    assert MapLibrary(tmp_path / "maps").all() == []  # not taken for a map's sidecar
    (tmp_path / "maps" / PENDING_FILE).write_text('[{"mapId": 7}]')
    with capture_logs() as logs:
        assert library.pending_enables() == []
    assert [e["event"] for e in logs] == ["maps.pending_unreadable"]
