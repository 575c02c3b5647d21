"""Command-line flags generated from a settings model, so flags and config keys cannot drift
(architecture §3.2: every config key is also a flag and an environment variable).

``settings_parser(model, ...)`` adds one flag per field: ``release_window_nodes`` becomes
``--release-window-nodes``, booleans get ``--x``/``--no-x``, literals get their choices, and
structured values (lists, mappings) are given as JSON or YAML text, e.g.
``--action-durations-s '{pick: 2.0}'``. Unset flags stay None, so lower layers (environment,
config file, defaults) fill them (:func:`vda5050.config.load_settings`).
"""

from __future__ import annotations

import argparse
import types
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin

import yaml
from pydantic import BaseModel
from pydantic.fields import FieldInfo


def flag_name(field: str) -> str:
    """``release_window_nodes`` → ``--release-window-nodes``."""
    return "--" + field.replace("_", "-")


def add_settings_flags(
    parser: argparse.ArgumentParser,
    model: type[BaseModel],
    *,
    overrides: dict[str, dict[str, Any]] | None = None,
) -> None:
    """One flag per field of ``model``; ``overrides`` replaces argparse options per field."""
    for name, info in model.model_fields.items():
        options = _options(name, info)
        options.update((overrides or {}).get(name, {}))
        parser.add_argument(flag_name(name), dest=name, default=None, **options)


def structured_fields(model: type[BaseModel]) -> frozenset[str]:
    """Fields whose values are lists or mappings (given as JSON/YAML text on the command line
    and in the environment)."""
    return frozenset(
        name for name, info in model.model_fields.items() if _is_structured(info.annotation)
    )


def parse_structured(text: str) -> object:
    """A JSON or YAML value given as text; the text itself when it does not parse."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def _options(name: str, info: FieldInfo) -> dict[str, Any]:
    annotation = _without_none(info.annotation)
    help_text = _help(info)
    if annotation is bool:
        return {"action": argparse.BooleanOptionalAction, "help": help_text}
    if get_origin(annotation) is Literal:
        choices = [str(choice) for choice in get_args(annotation)]
        return {"choices": choices, "help": help_text, "metavar": "|".join(choices)}
    if _is_structured(annotation):
        return {"type": parse_structured, "help": f"{help_text} (JSON or YAML)"}
    converter: Callable[[str], object] = annotation if annotation in (int, float, Path) else str
    return {"type": converter, "help": help_text, "metavar": name.upper()}


def _help(info: FieldInfo) -> str:
    text = info.description or ""
    default = info.get_default(call_default_factory=True)
    if default not in (None, [], {}):
        text = f"{text} (default {default})" if text else f"default {default}"
    return text.replace("%", "%%")


def _without_none(annotation: Any) -> Any:  # noqa: ANN401 - typing objects are untyped
    origin = get_origin(annotation)
    if origin in (Union, types.UnionType):
        rest = [arg for arg in get_args(annotation) if arg is not type(None)]
        if len(rest) == 1:
            return rest[0]
    return annotation


def _is_structured(annotation: Any) -> bool:  # noqa: ANN401 - typing objects are untyped
    annotation = _without_none(annotation)
    origin = get_origin(annotation) or annotation
    return isinstance(origin, type) and issubclass(origin, list | dict | tuple | set | BaseModel)


def known_flags(parser: argparse.ArgumentParser) -> Iterable[str]:
    """Every long option of ``parser`` (for tests and help texts)."""
    for action in parser._actions:  # noqa: SLF001 - argparse exposes no public list
        yield from (option for option in action.option_strings if option.startswith("--"))
