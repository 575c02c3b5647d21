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
from vda_master.api_models import CreateOrder
from vda_master.capabilities import ActionSpec
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderTrack
from vda_master.load_rules import Fit, LoadFit, LoadNeed, load_fit, load_need
from vda_master.planner import Target
from vda_master.queue_rules import QueuedOrder
from vda_master.requests import OrderRequest, RequestError
from vda_master.service import MasterService
from vda_master.testing import LOAD_ACTIONS, RecordingPublisher, demo_graph, make_factsheet
from vda_master.web.payloads import load_types_payload

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


def _handling(*load_sets: tuple[str, list[str] | None]) -> Factsheet:
    """A factsheet whose load sets take (loadType, loadPositions) each."""
    sets = [
        {"setName": f"set-{i}", "loadType": load_type, "loadPositions": positions}
        for i, (load_type, positions) in enumerate(load_sets)
    ]
    return Factsheet.model_validate(
        {
            **make_factsheet(actions=ACTIONS_WITH_IDS).model_dump(by_alias=True, mode="json"),
            "loadSpecification": {"loadPositions": ["front"], "loadSets": sets},
        }
    )


def _typed(action: str, load_type: str, **more: str) -> tuple[ActionSpec, ...]:
    return (ActionSpec(action, parameters={"loadType": load_type, **more}),)


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


def test_a_load_type_needs_a_load_set_of_the_factsheet_for_good() -> None:
    """loadSpecification.loadSets narrow what a vehicle is sent: a pick or drop naming a
    loadType that no set takes (at the lhd asked for, when the set lists positions) is
    UNSUITED, which no change of load cures; a factsheet without load sets says nothing."""
    need = load_need(_typed("pick", "KLT"))
    assert need == LoadNeed("pick", load_type="KLT")
    pallets = _handling(("EPAL", None), ("EPAL", ["front"]))
    unsuited = load_fit([], pallets, need)
    assert unsuited == LoadFit(
        Fit.UNSUITED, "its factsheet's load sets take 'EPAL', not load type 'KLT'"
    )
    assert load_fit([], _handling(("EPAL", None), ("KLT", None)), need).fit is Fit.FITS
    assert load_fit([], make_factsheet(), need).fit is Fit.FITS  # no load sets listed
    assert load_fit([], None, need).fit is Fit.FITS
    rear = LoadNeed("pick", lhd="rear", load_type="KLT")
    front_only = load_fit([], _handling(("KLT", ["front"])), rear)
    assert front_only.fit is Fit.UNSUITED
    assert front_only.reason == (
        "its factsheet's load sets take load type 'KLT' on 'front' only, not on load handling "
        "device 'rear'"
    )
    assert load_fit([], _handling(("KLT", None)), rear).fit is Fit.FITS  # anywhere
    # a drop's loadType is also compared with what the vehicle carries (not now, not never)
    drop = LoadNeed("drop", load_type="KLT")
    both = _handling(("EPAL", None), ("KLT", None))
    pallet = [Load(load_id="L1", load_type="EPAL")]
    carried = load_fit(pallet, both, drop)
    assert carried == LoadFit(
        Fit.REFUSED, "it carries no load of type 'KLT' to drop (it carries load 'L1')"
    )
    assert load_fit([Load(load_type="KLT")], both, drop).fit is Fit.FITS
    assert load_fit([Load(load_id="L1")], both, drop).fit is Fit.UNKNOWN  # type not reported


def test_the_load_types_a_vehicle_takes_are_listed_from_its_load_sets() -> None:
    """GET /vehicles and the map's panel: each type once, in the factsheet's order; null when
    it lists no load sets (no type is refused then) or no factsheet is known."""
    assert load_types_payload(_handling(("KLT", None), ("EPAL", ["front"]), ("KLT", ["rear"]))) == [
        "KLT",
        "EPAL",
    ]
    assert load_types_payload(make_factsheet()) is None
    assert load_types_payload(None) is None


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


def test_a_load_type_goes_to_a_vehicle_whose_load_sets_take_it() -> None:
    """Mixed fleet: a forklift for pallets, an AMR for small load carriers. Without a vehicle
    named, a KLT pick goes to the AMR though the forklift is nearer; named, the forklift is
    refused for good (422, a queued order is not kept for it); a later stop counts too."""
    service = _service()
    _report(service, A, "10", [], sheet=_handling(("EPAL", None)))  # next to 12
    _report(service, B, "1", [], sheet=_handling(("KLT", None)))  # far away
    klt = _typed("pick", "KLT")
    assert _sent_to(service.create_order(OrderRequest(Target(destination="12"), None, klt))) == B
    service = _service()
    _report(service, A, "10", [], sheet=_handling(("EPAL", None)))
    for queue in (False, True):
        with pytest.raises(RequestError) as refused:
            service.place_order(OrderRequest(Target(destination="12"), A, klt, queue=queue))
        assert refused.value.status == 422
        assert refused.value.message == (
            "vehicle acme/a cannot take this order: pick: its factsheet's load sets take "
            "'EPAL', not load type 'KLT'"
        )
    with pytest.raises(RequestError) as nobody:
        service.create_order(OrderRequest(Target(destination="12"), None, klt))
    assert nobody.value.status == 409  # a vehicle that takes KLT may come: queue: true waits
    assert "acme/a: cannot take this order: pick: its factsheet's load sets take 'EPAL'" in (
        nobody.value.message
    )
    stops = CreateOrder.model_validate(
        {
            "manufacturer": "acme",
            "serialNumber": "a",
            "stops": [
                {"destination": "12", "actions": [{"actionType": "pick"}]},
                {"destination": "14", "actions": [
                    {"actionType": "drop", "actionParameters": [
                        {"key": "loadType", "value": "KLT"}]}]},
            ],
        }
    ).to_request()  # fmt: skip
    with pytest.raises(RequestError) as later:
        service.create_order(stops)
    assert later.value.status == 422
    assert "drop at stop 2: its factsheet's load sets take 'EPAL', not load type 'KLT'" in (
        later.value.message
    )
