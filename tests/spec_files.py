"""Locations of the shared VDA 5050 material beside the repository (examples, official schemas)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import cast

import pytest

REPO = Path(__file__).resolve().parents[1]
SPEC = REPO.parent / "shared" / "spec"
EXAMPLES = SPEC / "examples"
OFFICIAL_SCHEMAS = SPEC / "official-schemas"
VERSIONS = ("2.0.0", "2.1.0")

needs_examples = pytest.mark.skipif(
    not EXAMPLES.is_dir(), reason=f"shared examples not present at {EXAMPLES}"
)
needs_official_schemas = pytest.mark.skipif(
    not OFFICIAL_SCHEMAS.is_dir(), reason=f"official schemas not present at {OFFICIAL_SCHEMAS}"
)


def topic_of_example(path: Path) -> str:
    """``order_initial.json`` -> ``order``; ``factsheet.json`` -> ``factsheet``."""
    return path.stem.split("_")[0]


def example_files(version: str, folder: str = "") -> list[Path]:
    """Example messages of ``version`` (top level, or a sub-folder), without ``_rules.json``."""
    base = EXAMPLES / version / folder if folder else EXAMPLES / version
    if not base.is_dir():
        return []
    return sorted(p for p in base.glob("*.json") if not p.name.startswith("_"))


def official_schema(version: str, topic: str) -> dict[str, object]:
    """The official schema of ``topic``, preferring the patched copy (SOURCE.md)."""
    patched = OFFICIAL_SCHEMAS / "_patched" / version / f"{topic}.schema"
    path = patched if patched.is_file() else OFFICIAL_SCHEMAS / version / f"{topic}.schema"
    return cast("dict[str, object]", json.loads(path.read_text()))


#: Hand-written 3.0.0 examples of this repository (valid ones at the top, ``schema_invalid/``
#: with ``_rules.json`` naming the path, rule id and reason of each invalid one).
V3_EXAMPLES = REPO / "tests" / "examples" / "3.0.0"


def v3_example_files(folder: str = "") -> list[Path]:
    """The 3.0.0 example messages (top level, or a sub-folder), without ``_rules.json``."""
    base = V3_EXAMPLES / folder if folder else V3_EXAMPLES
    return sorted(p for p in base.glob("*.json") if not p.name.startswith("_"))


def v3_invalid_rules() -> dict[str, dict[str, str]]:
    """``schema_invalid/_rules.json``: file name -> {path, rule, why}."""
    path = V3_EXAMPLES / "schema_invalid" / "_rules.json"
    return cast("dict[str, dict[str, str]]", json.loads(path.read_text()))
