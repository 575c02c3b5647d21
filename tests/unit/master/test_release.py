"""Base release windows and extension decisions (§6.6.2; R56, R66, R107)."""

from __future__ import annotations

import pytest

from vda5050.topics import AgvId
from vda_master.order_builder import OrderPlan, PlanRequest, plan_order
from vda_master.release import ReleasePolicy, decide_release, progress_index, release_end
from vda_master.routing import Route, shortest_route
from vda_master.testing import id_source, line_graph, plan_state


def _plan(count: int = 10) -> OrderPlan:
    graph = line_graph(count)
    route = shortest_route(graph, "n0", f"n{count - 1}")
    assert isinstance(route, Route)
    plan = plan_order(
        graph,
        PlanRequest(route, "o1", {}, {}),
        agv=AgvId("acme", "r1"),
        version="2.1.0",
        factsheet=None,
        action_ids=id_source(),
    )
    assert isinstance(plan, OrderPlan)
    return plan


def test_window_releases_n_nodes_ahead() -> None:
    """The default policy releases three nodes beyond the vehicle's last node."""
    assert release_end(ReleasePolicy(), last_index=9, progress=0) == 3
    assert release_end(ReleasePolicy(window_nodes=2), last_index=9, progress=4) == 6


def test_window_stops_at_the_destination() -> None:
    """The window never reaches past the last node of the route."""
    assert release_end(ReleasePolicy(window_nodes=5), last_index=3, progress=1) == 3


def test_window_zero_releases_everything() -> None:
    """A window of 0 releases the whole route at once (no horizon)."""
    assert release_end(ReleasePolicy(window_nodes=0), last_index=9, progress=0) == 9


def test_negative_window_is_refused() -> None:
    """A negative window is a configuration error."""
    with pytest.raises(ValueError, match="must not be negative"):
        ReleasePolicy(window_nodes=-1)


def test_progress_extends_the_base() -> None:
    """Passing a node slides the window forward by one (R56: the base only grows)."""
    policy = ReleasePolicy(window_nodes=3)
    new_end = decide_release(
        policy, last_index=9, released_end=3, progress=1, new_base_request=False
    )
    assert new_end == 4


def test_no_extension_while_window_is_full() -> None:
    """No update is made while the released window ahead is still full."""
    policy = ReleasePolicy(window_nodes=3)
    assert (
        decide_release(policy, last_index=9, released_end=3, progress=0, new_base_request=False)
        is None
    )


def test_new_base_request_extends_even_with_full_window() -> None:
    """newBaseRequest asks for more base and gets at least one node more (§6.10.3, R107)."""
    policy = ReleasePolicy(window_nodes=3)
    assert (
        decide_release(policy, last_index=9, released_end=3, progress=0, new_base_request=True) == 6
    )


def test_fully_released_route_is_never_extended() -> None:
    """Once the destination is released there is nothing left to extend."""
    policy = ReleasePolicy(window_nodes=3)
    assert (
        decide_release(policy, last_index=9, released_end=9, progress=8, new_base_request=True)
        is None
    )


def test_progress_index_from_last_node_sequence_id() -> None:
    """The vehicle's position in the order comes from lastNodeId and lastNodeSequenceId."""
    plan = _plan()
    assert progress_index(plan, plan_state(plan, passed=4)) == 4


def test_progress_index_ignores_other_orders() -> None:
    """A state of another order says nothing about this one."""
    plan = _plan()
    assert progress_index(plan, plan_state(plan, passed=4, order_id="other")) is None


def test_progress_index_needs_matching_node_id() -> None:
    """A sequenceId that does not belong to the reported node is not progress."""
    plan = _plan()
    assert progress_index(plan, plan_state(plan, passed=4, last_node_id="n7")) is None
