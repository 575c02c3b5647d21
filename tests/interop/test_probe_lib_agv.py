"""``vda-probe`` against a vda-5050-lib 1.4.0 virtual AGV (VDA 5050 2.0.0): every step it
is given is answered (none is left undecided for want of a state or an error), the one step
it fails is the one docs/inspect.md records, and the whole outcome is recorded as
``probe_peer_results``. Our side here is master control: what the prober sends must be
schema-exact and break nothing ``vda-inspect`` judges on master control's side (the ``wire``
fixture) but what it breaks on purpose."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tests.interop.node_lib import NodeRuntime
from tests.interop.peers import running_agvs
from tests.interop.services import pose_at
from tests.interop.wire import Side
from tests.mosquitto import Mosquitto
from tests.system.stack import Captured
from vda_inspect.probe_cli import ProbeConfig, Prober

pytestmark = pytest.mark.interop
OUR_SIDE = Side.MASTER
#: What the prober breaks on purpose to see the AGV reject it: a lower orderUpdateId (R57) and
#: an update that does not stitch (R56).
DELIBERATE = frozenset({"R56", "R57"})


async def test_every_step_is_judged_on_the_library_agv(
    node_runtime: NodeRuntime,
    mosquitto: Mosquitto,
    unique_interface_name: str,
    wire: Captured,
    record_property: Callable[[str, object], None],
) -> None:
    async with running_agvs(
        node_runtime,
        broker_url=mosquitto.address.url,
        interface_name=unique_interface_name,
        manufacturer="vdalib",
        poses={"agv_1": pose_at("n1")},
        timeLapse=10,
        tickRate=10,
    ):
        config = ProbeConfig.model_validate(
            {
                "broker_url": mosquitto.address.url,
                "interface_name": unique_interface_name,
                "manufacturer": "vdalib",
                "serial_number": "agv_1",
                "wait_s": 10,
            }
        )
        report = await Prober(config).probe()
    assert "unprobed" not in report, report
    steps = report["steps"]
    assert isinstance(steps, list)
    record_property(
        "probe_peer_results",
        [f"{s['outcome']} {','.join(s['rules'])}: {s['text']}" for s in steps],
    )
    assert len(steps) == 18
    judged = [s for s in steps if s["outcome"] != "skipped"]
    silent = [s for s in judged if "no state came" in str(s["text"])]
    assert silent == [], silent  # the AGV answered every step it was given
    outcomes = {",".join(s["rules"]): s["outcome"] for s in judged}
    # everything but R40: vda-5050-lib 1.4.0 counts an order whose base is done as ended,
    # horizon or not, and takes a new orderId then, against 2.1's definition of a busy
    # vehicle, as docs/inspect.md says
    failed = sorted(rules for rules, outcome in outcomes.items() if outcome != "pass")
    assert failed == ["R40,R30"], steps
    # its factsheet is only a header: it came (R80), and is said not to be valid
    undecodable = report["undecodable"]
    assert isinstance(undecodable, list)
    assert any("factsheet" in problem for problem in undecodable), undecodable
