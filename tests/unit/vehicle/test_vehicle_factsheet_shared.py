"""The vehicles of one process build their factsheet once (SharedFactsheets): a memo of the
pure builder, per capabilities object, timing and version."""

from __future__ import annotations

from dataclasses import replace

from vda_vehicle.capabilities import Capabilities
from vda_vehicle.factsheet import FactsheetTiming, SharedFactsheets, build_factsheet

TIMING = FactsheetTiming(min_state_interval_s=0.1, state_interval_s=30, visualization_interval_s=1)


def test_one_build_per_capabilities_timing_and_version() -> None:
    """Alike requests share one factsheet; another capabilities object, timing or version
    builds its own, equal to what the builder returns."""
    shared, builds = SharedFactsheets(), []
    caps = Capabilities(map_ids=frozenset({"m"}))

    def get(caps: Capabilities, timing: FactsheetTiming, version: str) -> object:
        def build() -> object:
            builds.append(version)
            return build_factsheet(caps, timing, version=version)

        return shared.get(caps, timing, version, build)

    first = get(caps, TIMING, "2.1.0")
    assert get(caps, replace(TIMING), "2.1.0") is first
    assert len(builds) == 1
    other_caps = replace(caps, speed_max_mps=3.0)
    assert get(other_caps, TIMING, "2.1.0") == build_factsheet(other_caps, TIMING, version="2.1.0")
    assert get(caps, replace(TIMING, state_interval_s=10), "2.1.0") is not first
    assert get(caps, TIMING, "2.0.0") == build_factsheet(caps, TIMING, version="2.0.0")
    assert len(builds) == 4
