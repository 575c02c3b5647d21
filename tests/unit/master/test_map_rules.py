"""What a vehicle's listed maps allow and what master control sends it for a map version
(:mod:`vda_master.map_rules`; VDA 5050 §6.7)."""

from __future__ import annotations

from vda5050.models import ActionState, ActionStatus, State
from vda5050.testing import make_state
from vda_master.map_rules import (
    Follow,
    PendingEnable,
    Send,
    distribution_step,
    enabling_step,
    follow_download,
    map_problem,
)

HALL_2 = ("hall", "2")


def _with_maps(*maps: tuple[str, str, str], **fields: object) -> State:
    listed = [{"mapId": i, "mapVersion": v, "mapStatus": s} for i, v, s in maps]
    return make_state(maps=listed, **fields)


def test_a_vehicle_that_lists_no_maps_is_never_narrowed() -> None:
    """2.0 states have no ``maps``; an empty list is tolerated as "nothing said" too."""
    assert map_problem(make_state(), "hall") is None
    assert map_problem(make_state(maps=[]), "hall") is None
    assert map_problem(None, "hall") is None


def test_an_order_needs_an_enabled_version_of_its_map() -> None:
    """R35: a vehicle rejects an order on a map it does not hold ENABLED, so master control
    does not send one (§6.7.1)."""
    assert (
        map_problem(_with_maps(("hall", "1", "DISABLED"), ("hall", "2", "ENABLED")), "hall") is None
    )
    disabled = map_problem(_with_maps(("hall", "1", "DISABLED")), "hall")
    assert disabled == (
        "no version of map 'hall' is ENABLED on it: it holds version '1' (DISABLED) and none "
        "ENABLED (enableMap, §6.7.1)"
    )
    other = map_problem(_with_maps(("yard", "1", "ENABLED"), ("dock", "3", "ENABLED")), "hall")
    assert other == (
        "no version of map 'hall' is ENABLED on it: it holds none (dock, yard only) "
        "(enableMap, §6.7.1)"
    )


def test_distribution_downloads_what_is_not_held_and_enables_what_is_held_disabled() -> None:
    """R87: a version the vehicle holds is never downloaded again; R89: enableMap for one
    held DISABLED."""
    missing = _with_maps(("hall", "1", "ENABLED"))
    assert distribution_step(missing, "2.1.0", HALL_2, enable=True).send is Send.DOWNLOAD
    held = _with_maps(("hall", "2", "DISABLED"))
    assert distribution_step(held, "2.1.0", HALL_2, enable=True).send is Send.ENABLE
    kept = distribution_step(held, "2.1.0", HALL_2, enable=False)
    assert (kept.send, kept.detail) == (
        Send.NOTHING,
        "it holds map 'hall' version '2' already (DISABLED)",
    )
    enabled = distribution_step(_with_maps(("hall", "2", "ENABLED")), "3.0.0", HALL_2, enable=True)
    assert (enabled.send, enabled.refused) == (Send.NOTHING, None)
    # no state yet, version unknown: the download is still sent (tolerant)
    assert distribution_step(None, None, HALL_2, enable=False).send is Send.DOWNLOAD


def test_a_2_0_vehicle_is_refused_map_distribution() -> None:
    step = distribution_step(make_state(), "2.0.0", HALL_2, enable=False)
    assert step.refused == 422
    assert "2.0.0, which has no map distribution" in step.detail
    assert enabling_step(make_state(), "2.0.0", HALL_2).refused == 422


def test_enabling_needs_the_version_on_the_vehicle() -> None:
    absent = enabling_step(_with_maps(("hall", "1", "ENABLED")), "2.1.0", HALL_2)
    assert absent.refused == 409
    assert absent.detail.startswith("it does not hold map 'hall' version '2': distribute it")
    assert enabling_step(_with_maps(("hall", "2", "DISABLED")), "2.1.0", HALL_2).send is Send.ENABLE
    done = enabling_step(_with_maps(("hall", "2", "ENABLED")), "2.1.0", HALL_2)
    assert (done.send, done.detail) == (
        Send.NOTHING,
        "map 'hall' version '2' is ENABLED on it already",
    )


def test_a_pending_download_is_followed_to_its_end() -> None:
    """R88: a downloaded version is listed DISABLED, which is when it is enabled; a FAILED
    download ends the wait."""
    pending = PendingEnable(HALL_2, "dl-1")
    running = ActionState(action_id="dl-1", action_status=ActionStatus.RUNNING)
    assert follow_download(make_state(action_states=[running]), pending) == (Follow.WAIT, "")
    ready = _with_maps(("hall", "1", "ENABLED"), ("hall", "2", "DISABLED"))
    assert follow_download(ready, pending) == (Follow.ENABLE, "")
    by_hand = _with_maps(("hall", "2", "ENABLED"))
    assert follow_download(by_hand, pending) == (Follow.DONE, "")
    failed = ActionState(
        action_id="dl-1", action_status=ActionStatus.FAILED, result_description="404 at the server"
    )
    assert follow_download(make_state(action_states=[failed]), pending) == (
        Follow.FAILED,
        "404 at the server",
    )
