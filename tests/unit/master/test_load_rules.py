"""Who may pick and who may drop: master control reads the loads a vehicle reports
(vda_master.load_rules, docs/master.md *Loads*)."""

from __future__ import annotations

from typing import Any

import pytest

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import Connection, ConnectionState, Factsheet, Load
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.capabilities import ActionSpec
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderTrack
from vda_master.load_rules import Fit, LoadNeed, load_fit, load_need
from vda_master.planner import Target
from vda_master.queue_rules import QueuedOrder
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.testing import LOAD_ACTIONS, RecordingPublisher, demo_graph, make_factsheet

A, B, C = (AgvId("acme", s) for s in ("a", "b", "c"))
PICK = (ActionSpec("pick"),)
DROP = (ActionSpec("drop"),)

ID_PARAMETERS = [
    {"key": key, "valueDataType": "STRING", "isOptional": True} for key in ("lhd", "loadId")
]
#: pick and drop that also take the predefined ``lhd`` and ``loadId`` parameters (§6.8.2).
ACTIONS_WITH_IDS = [
    {**action, "actionParameters": [*action["actionParameters"], *ID_PARAMETERS]}  # type: ignore[misc]
    if action["actionType"] in ("pick", "drop")
    else action
    for action in LOAD_ACTIONS
]


def _load(load_id: str | None = None, position: str | None = None) -> Load:
    return Load(load_id=load_id, load_position=position)


def _factsheet(*positions: str) -> Factsheet:
    factsheet = make_factsheet()
    spec = factsheet.load_specification.model_copy(update={"load_positions": list(positions)})
    return factsheet.model_copy(update={"load_specification": spec})


# -- the rule --------------------------------------------------------------------------------


def test_the_first_load_action_decides_what_the_order_needs() -> None:
    assert load_need(()) == LoadNeed()
    assert load_need((ActionSpec("beep"),)) == LoadNeed()
    specs = (ActionSpec("drop", parameters={"loadId": "L7", "lhd": "fork"}), ActionSpec("pick"))
    assert load_need(specs) == LoadNeed("drop", "fork", "L7")
    assert load_need((ActionSpec("pick", parameters={"loadId": ""}),)) == LoadNeed("pick")


def test_a_pick_needs_a_free_load_position() -> None:
    need = LoadNeed("pick")
    one = _factsheet("front")
    assert load_fit([], one, need).fit is Fit.FITS
    full = load_fit([_load("L1", "front")], one, need)
    assert full.fit is Fit.REFUSED
    assert full.reason == "it carries load 'L1' on its 1 load position: a pick needs a free one"
    assert load_fit([_load("L1", "front")], _factsheet("front", "rear"), need).fit is Fit.FITS
    occupied = load_fit(
        [_load(None, "rear")], _factsheet("front", "rear"), LoadNeed("pick", "rear")
    )
    assert occupied.fit is Fit.REFUSED
    assert "load handling device 'rear' holds a load" in occupied.reason


def test_a_drop_needs_the_load_it_names() -> None:
    empty = load_fit([], None, LoadNeed("drop"))
    assert (empty.fit, empty.reason) == (Fit.REFUSED, "it carries no load to drop")
    carrying = [_load("L1", "front")]
    assert load_fit(carrying, None, LoadNeed("drop")).fit is Fit.FITS
    assert load_fit(carrying, None, LoadNeed("drop", "front", "L1")).fit is Fit.FITS
    other = load_fit(carrying, None, LoadNeed("drop", load_id="L7"))
    assert other.fit is Fit.REFUSED
    assert other.reason == "it carries no load 'L7' to drop (it carries load 'L1')"
    wrong_side = load_fit(carrying, None, LoadNeed("drop", lhd="rear"))
    assert "no load on load handling device 'rear'" in wrong_side.reason


def test_a_vehicle_that_says_too_little_may_still_fit() -> None:
    """No loads reported, no load positions listed, loads without ids: unknown, not refused."""
    assert load_fit(None, None, LoadNeed("pick")).fit is Fit.UNKNOWN
    assert load_fit(None, None, LoadNeed("drop")).fit is Fit.UNKNOWN
    assert load_fit([_load("L1")], None, LoadNeed("pick")).fit is Fit.UNKNOWN
    assert load_fit([_load()], None, LoadNeed("drop", load_id="L7")).fit is Fit.UNKNOWN
    assert load_fit(None, None, LoadNeed()).fit is Fit.FITS


# -- master control ----------------------------------------------------------------------------


def _topic(agv: AgvId, kind: Topic) -> str:
    return build_topic("uagv", 2, agv, kind)


def _report(
    service: MasterService, agv: AgvId, node: str, loads: list[Load] | None, **factsheet: Any
) -> None:
    header = {"manufacturer": agv.manufacturer, "serial_number": agv.serial_number}
    online = Connection.model_validate({**HEADER, "connection_state": ConnectionState.ONLINE})
    service.ingest(_topic(agv, Topic.CONNECTION), encode(online.model_copy(update=header)))
    sheet = factsheet.get("sheet") or make_factsheet(actions=ACTIONS_WITH_IDS)
    service.ingest(_topic(agv, Topic.FACTSHEET), encode(sheet.model_copy(update=header)))
    state = make_state(last_node_id=node, loads=loads, **header)
    service.ingest(_topic(agv, Topic.STATE), encode(state))


def _service() -> MasterService:
    config = MasterConfig.model_validate({"traffic_control": False, "charge_below_pct": 0})
    return MasterService(config, demo_graph(), RecordingPublisher(), FakeClock())


def _sent_to(outcome: OrderTrack | QueuedOrder) -> AgvId:
    assert isinstance(outcome, OrderTrack)
    return outcome.plan.agv


def test_master_control_sends_a_pick_to_an_empty_vehicle_and_a_drop_to_a_loaded_one() -> None:
    service = _service()
    _report(service, A, "10", [_load("L1")], sheet=_factsheet("front"))  # next to 12, full
    _report(service, B, "1", [])  # far away, empty
    pick = service.create_order(OrderRequest(Target(destination="12"), None, PICK))
    assert _sent_to(pick) == B
    drop = service.create_order(OrderRequest(Target(destination="12"), None, DROP))
    assert _sent_to(drop) == A


def test_a_drop_of_a_named_load_goes_to_the_vehicle_that_carries_it() -> None:
    service = _service()
    _report(service, A, "10", [_load("L1")])
    _report(service, B, "1", [_load("L7")])
    named = (ActionSpec("drop", parameters={"loadId": "L7"}),)
    assert _sent_to(service.create_order(OrderRequest(Target(destination="12"), None, named))) == B


def test_a_vehicle_that_reports_no_loads_is_chosen_only_when_none_known_to_fit_can_go() -> None:
    service = _service()
    _report(service, A, "10", None)  # nearer, but does not say what it carries
    _report(service, B, "1", [])
    assert _sent_to(service.create_order(OrderRequest(Target(destination="12"), None, PICK))) == B
    assert _sent_to(service.create_order(OrderRequest(Target(destination="13"), None, PICK))) == A


def test_a_named_vehicle_that_cannot_pick_or_drop_is_refused_saying_why() -> None:
    service = _service()
    _report(service, A, "10", [])
    with pytest.raises(
        RequestError, match="vehicle acme/a cannot drop now: it carries no load"
    ) as e:
        service.create_order(OrderRequest(Target(destination="12"), A, DROP))
    assert e.value.status == 409
    _report(service, B, "1", None)  # unknown: it is sent what it is asked
    assert _sent_to(service.create_order(OrderRequest(Target(destination="12"), B, DROP))) == B


def test_no_vehicle_that_can_drop_answers_409_with_each_one_s_reason() -> None:
    service = _service()
    _report(service, A, "10", [])
    _report(service, C, "1", [_load("L1")])
    named = (ActionSpec("drop", parameters={"loadId": "L7"}),)
    with pytest.raises(RequestError) as refused:
        service.create_order(OrderRequest(Target(destination="12"), None, named))
    assert refused.value.status == 409
    assert "acme/a: cannot drop now: it carries no load 'L7' to drop" in refused.value.message
    assert "acme/c: cannot drop now: it carries no load 'L7' to drop (it carries load 'L1')" in (
        refused.value.message
    )


def test_a_queued_drop_waits_for_a_vehicle_that_carries_a_load() -> None:
    service = _service()
    _report(service, A, "10", [])
    waiting = service.place_order(OrderRequest(Target(destination="12"), None, DROP, queue=True))
    assert isinstance(waiting, QueuedOrder)
    assert "cannot drop now: it carries no load to drop" in waiting.reason
    header = {"manufacturer": A.manufacturer, "serial_number": A.serial_number}
    service.ingest(
        _topic(A, Topic.STATE), encode(make_state(last_node_id="10", loads=[_load()], **header))
    )
    service.clock.advance(11.0)  # type: ignore[attr-defined]
    service.tick()
    assert service.queue == {}
    assert service.active.get(A) == waiting.order_id
