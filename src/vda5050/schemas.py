"""JSON Schemas of the wire messages and of the graph file, generated from the models.

The models are the single source of truth. ``python -m vda5050.schemas`` writes the files under
``schemas/``; a unit test fails when the committed files are stale. 2.0.0 schemas leave out the
fields that exist only from 2.1.0 on (marked ``x-vda5050-since`` in the models); 3.0.0 schemas
are generated from :mod:`vda5050.models.v3` and cover its eight topics.

At run time the schemas serve cold paths (graph files, tooling, tests); the hot path validates
with the pydantic models directly, which is over an order of magnitude faster than jsonschema.
"""

from __future__ import annotations

import argparse
import json
from functools import cache
from importlib import resources
from pathlib import Path
from typing import cast

from jsonschema import Draft202012Validator, FormatChecker

from vda5050.codec import SUPPORTED_VERSIONS, major_of, model_for
from vda5050.graph_file import GraphFile
from vda5050.models.base import SINCE_2_1
from vda5050.topics import Topic, topics_of

JsonObject = dict[str, object]
DRAFT = "https://json-schema.org/draft/2020-12/schema"
GRAPH_SCHEMA = "graph.schema.json"
_SINCE_KEY = next(iter(SINCE_2_1))


def schema_file_name(topic: Topic, version: str) -> str:
    """Relative path of a message schema, e.g. ``2.1.0/order.schema.json``."""
    return f"{version}/{topic.value}.schema.json"


def build_message_schema(topic: Topic, version: str) -> JsonObject:
    """Generate the JSON Schema of ``topic`` for protocol ``version``."""
    model = model_for(topic, major_of(version))
    schema = cast("JsonObject", model.model_json_schema(by_alias=True))
    if version == "2.0.0":
        schema = _without_newer_fields(schema)
    return {
        "$schema": DRAFT,
        "$id": f"vda5050-stack/{schema_file_name(topic, version)}",
        "title": f"VDA 5050 {version} {topic.value}",
        **{key: value for key, value in schema.items() if key != "title"},
    }


def build_graph_schema() -> JsonObject:
    """Generate the JSON Schema of the graph file (architecture §3.3)."""
    schema = cast("JsonObject", GraphFile.model_json_schema(by_alias=True))
    return {"$schema": DRAFT, "$id": f"vda5050-stack/{GRAPH_SCHEMA}", **schema}


def build_all() -> dict[str, JsonObject]:
    """Every schema file, keyed by its path relative to ``schemas/``."""
    files = {
        schema_file_name(topic, version): build_message_schema(topic, version)
        for version in SUPPORTED_VERSIONS
        for topic in sorted(topics_of(major_of(version)), key=list(Topic).index)
    }
    files[GRAPH_SCHEMA] = build_graph_schema()
    return files


def render(schema: JsonObject) -> str:
    """The exact text a schema file holds."""
    return json.dumps(schema, indent=2, ensure_ascii=False, sort_keys=False) + "\n"


def _without_newer_fields(node: object) -> JsonObject:
    """Copy of a schema tree without properties marked as 2.1-only."""

    def strip(value: object) -> object:
        if isinstance(value, dict):
            properties = value.get("properties")
            result = {key: strip(item) for key, item in value.items() if key != "properties"}
            if isinstance(properties, dict):
                result["properties"] = {
                    name: strip(prop)
                    for name, prop in properties.items()
                    if not (isinstance(prop, dict) and _SINCE_KEY in prop)
                }
            return result
        if isinstance(value, list):
            return [strip(item) for item in value]
        return value

    return cast("JsonObject", strip(node))


def repository_schema_dir() -> Path:
    """``schemas/`` of a source checkout (the generator writes there)."""
    return Path(__file__).resolve().parents[2] / "schemas"


@cache
def load_schema(name: str) -> JsonObject:
    """Load a committed schema by relative path: from the installed package, else the checkout."""
    packaged = resources.files("vda5050").joinpath("_schemas", name)
    if packaged.is_file():
        return cast("JsonObject", json.loads(packaged.read_text(encoding="utf-8")))
    return cast(
        "JsonObject", json.loads((repository_schema_dir() / name).read_text(encoding="utf-8"))
    )


@cache
def validator(name: str) -> Draft202012Validator:
    """A Draft 2020-12 validator (with format checks) for a committed schema, built once."""
    return Draft202012Validator(load_schema(name), format_checker=FormatChecker())


def main(argv: list[str] | None = None) -> int:
    """Write (or with ``--check``, compare) every schema under ``schemas/``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--check", action="store_true", help="exit 1 if a file is stale")
    parser.add_argument("--out", type=Path, default=repository_schema_dir())
    args = parser.parse_args(argv)
    stale = []
    for name, schema in build_all().items():
        path: Path = args.out / name
        text = render(schema)
        if path.is_file() and path.read_text(encoding="utf-8") == text:
            continue
        stale.append(name)
        if not args.check:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
    for name in stale:
        print(f"{'stale' if args.check else 'wrote'} {name}")  # noqa: T201 - a CLI
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    raise SystemExit(main())
