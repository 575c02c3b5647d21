"""The demo's mission driver: a busy robot gets its next order later, a real refusal stops."""

from __future__ import annotations

import time
from datetime import UTC, datetime, timedelta

import httpx
import pytest

from vda_demo.missions import Mission
from vda_demo.runner import DemoError, Progress, _gist, advance_missions, note_expected


def _progress() -> Progress:
    mission = Mission("robot_1", "transport", [{"destination": "A2"}, {"destination": "DR1"}])
    return Progress([mission])


def _client(answers: list[httpx.Response]) -> httpx.AsyncClient:
    def handle(request: httpx.Request) -> httpx.Response:
        assert request.method == "POST"
        assert request.url.path == "/orders"
        return answers.pop(0)

    return httpx.AsyncClient(transport=httpx.MockTransport(handle), base_url="http://master")


async def test_a_busy_robot_gets_its_order_on_a_later_round() -> None:
    """409 (the robot runs master control's own order, e.g. a move out of another robot's way)
    is no failure: the same step is sent again on the next round."""
    busy = httpx.Response(409, json={"detail": "vehicle vda-sim/robot_1 is not available"})
    created = httpx.Response(201, json={"orderId": "o1"})
    progress = _progress()
    async with _client([busy, created]) as http:
        await advance_missions(http, progress)
        assert progress.missions[0].order_ids == []
        await advance_missions(http, progress)
    assert progress.missions[0].order_ids == ["o1"]
    assert "o1" in progress.started


async def test_a_refused_order_stops_the_demo_with_the_reason() -> None:
    """Any other refusal is a demo failure that names the robot and the answer."""
    refused = httpx.Response(422, json={"detail": "no route to A2"})
    async with _client([refused]) as http:
        with pytest.raises(DemoError, match=r"robot_1: POST /orders answered 422: .*no route"):
            await advance_missions(http, _progress())


def test_a_log_line_is_not_repeated_for_a_new_estimate_alone() -> None:
    """Written to a log, a robot's line is printed again when what it does changes, not when
    only its battery, its wait time or its order's expected finish moved."""
    line = "robot_1   node A3 (1.0, 2.0)  RUNNING driving  battery 80.0%  pick{}{}"
    first = line.format("  done by 14:03:45 UTC", "  waits for robot_0 (1.2 s)")
    later = line.format("  done by 14:03:51 UTC", "  waits for robot_0 (7.9 s)")
    assert _gist(first) == _gist(later)
    assert _gist(first) != _gist(line.format("", "  waits for robot_2 (0.1 s)"))


def test_the_first_expected_finish_is_kept_as_seconds_from_the_start() -> None:
    progress = _progress()
    progress.started["o1"] = time.monotonic() - 5.0
    at = datetime.now(UTC) + timedelta(seconds=20)
    note_expected(progress, "o1", at.isoformat())
    assert progress.expected["o1"] == pytest.approx(25.0, abs=0.5)
    note_expected(progress, "o1", (at + timedelta(seconds=60)).isoformat())
    assert progress.expected["o1"] == pytest.approx(25.0, abs=0.5)  # the first one stays
