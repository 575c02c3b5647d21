"""Fixtures of the interoperability tests: vda-5050-lib, a private Mosquitto, the wire check."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Iterator

import pytest

from tests.interop.node_lib import NodeRuntime, install_vda_lib
from tests.interop.wire import (
    LIB_DEVIATIONS,
    Side,
    inspect_side,
    inspected,
    judge,
    schema_problems,
)
from tests.mosquitto import Mosquitto, run_mosquitto
from tests.system.stack import Captured, capturing
from vda_inspect.severity import Severity


@pytest.fixture(scope="session")
def node_runtime() -> NodeRuntime:
    """Node.js with vda-5050-lib 1.4.0, installed into .cache/interop/ on first use."""
    return install_vda_lib()


@pytest.fixture(scope="module")
def mosquitto(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Mosquitto]:
    """One private Mosquitto per test module; every test uses its own interface name."""
    with run_mosquitto(tmp_path_factory.mktemp("mosquitto")) as broker:
        yield broker


@pytest.fixture
async def wire(
    mosquitto: Mosquitto,
    unique_interface_name: str,
    request: pytest.FixtureRequest,
    record_property: Callable[[str, object], None],
) -> AsyncIterator[Captured]:
    """Every message on the test's interface; at the end, what OUR side sent must be
    schema-exact (official 2.0.0) and every peer deviation must be a known one; and
    ``vda-inspect`` must find no violation on our side (what it finds on the peer's is
    recorded as ``inspect_peer_findings``), but for the rules a test module breaks on purpose
    (its ``DELIBERATE``)."""
    our_side: Side = request.module.OUR_SIDE
    async with capturing(mosquitto.address, unique_interface_name) as captured:
        yield captured
    verdict = judge(schema_problems(captured), our_side, LIB_DEVIATIONS)
    record_property("known_peer_deviations", sorted({str(p) for p in verdict.known_peer}))
    failures = verdict.failures()
    assert not failures, "\n".join(failures[:15])
    findings = [f for f in inspected(captured) if f.severity is Severity.VIOLATION]
    deliberate: frozenset[str] = getattr(request.module, "DELIBERATE", frozenset())
    ours = [f for f in findings if inspect_side(f) is our_side and f.rule not in deliberate]
    peer = sorted({f"{f.rule} {f.vehicle} {f.topic}: {f.text}" for f in findings if f not in ours})
    record_property("inspect_peer_findings", peer)
    assert not ours, "vda-inspect: " + "\n".join(f"{f.rule} {f.vehicle}: {f.text}" for f in ours)
