"""The warehouse without its aisles' passing places, for tests of one-lane stretches: each aisle
is then one lane from the south corridor to the north one (the shipped floor's aisles are two
shorter one-lane stretches joined by a passing place)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

from vda_master.graph import Graph, build_graph

SCRIPT = Path(__file__).resolve().parents[4] / "scripts" / "make_warehouse_graph.py"


def warehouse_generator() -> ModuleType:
    """``scripts/make_warehouse_graph.py`` as a module."""
    spec = importlib.util.spec_from_file_location("make_warehouse_graph", SCRIPT)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def one_lane_aisles_warehouse() -> Graph:
    """The warehouse with every aisle one lane end to end (no passing place)."""
    return build_graph(warehouse_generator().build(passing_aisles=""), source="one-lane aisles")
