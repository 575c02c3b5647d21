"""The live map's seams: traffic control's snapshot and the API key."""

from __future__ import annotations

from collections.abc import Mapping

import pytest
from playwright.async_api import Browser, Dialog, Page, Request, expect

from tests.browser.harness import Fleet, open_map
from vda5050.graph_file import GraphZone
from vda5050.models import EStop
from vda_master.testing import demo_graph_with_zones, zone
from vda_vehicle.model import RobotMode
from vda_vehicle.vehicle_status import StackStatus

pytestmark = [pytest.mark.browser, pytest.mark.integration]


def _traffic() -> Mapping[str, object]:
    """What GET /traffic answers (issue 9): robot-1 holds node 7 and waits for robot-2."""
    return {
        "safetyDistanceM": 1.0,
        "vehicles": [
            {
                "manufacturer": "acme",
                "serialNumber": "robot-1",
                "nodeId": "7",
                "holds": ["node:7", "edge:17"],
                "pendingNodeIds": ["1"],
                "waitingFor": ["acme/robot-2"],
                "waitingAt": "node:1",
                "waitingSince": 1.0,
                "waitedS": 2.5,
                "conflict": "node 1 is held by acme/robot-2",
            },
            {
                "manufacturer": "acme",
                "serialNumber": "robot-2",
                "nodeId": "1",
                "holds": ["node:1"],
                "pendingNodeIds": [],
                "waitingFor": [],
                "waitingAt": None,
                "waitingSince": None,
                "waitedS": None,
                "conflict": None,
            },
        ],
        "deadlocksResolved": 0,
        "history": [],
    }


@pytest.mark.parametrize("snapshot", [None, {"enabled": False, "vehicles": []}])
async def test_without_traffic_control_the_page_says_so(
    browser: Browser, fleet: Fleet, monkeypatch: pytest.MonkeyPatch, snapshot: object
) -> None:
    """No snapshot, or one that says traffic control is off: the selected vehicle's panel
    says it is not active."""
    monkeypatch.setattr(fleet.master.service, "traffic_snapshot", lambda: snapshot)
    page, watch = await open_map(browser, fleet.url)
    await page.locator('tr[data-row-vehicle="acme/robot-1"]').click()
    await expect(page.locator("#selected .traffic")).to_have_text("traffic control is not active")
    watch.clean()


async def test_traffic_snapshot_colours_waiting_vehicles_and_draws_what_they_hold(
    browser: Browser, fleet: Fleet, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A vehicle that traffic control makes wait turns 'waiting'; selected, its reservations,
    the vehicle it waits for and why are shown."""
    page, watch = await open_map(browser, fleet.url)
    service = fleet.master.service
    monkeypatch.setattr(service, "traffic_snapshot", _traffic)
    service.live.traffic_changed()
    waiting = page.locator('[data-vehicle="acme/robot-1"]')
    await expect(waiting).to_have_attribute("data-status", "waiting")
    await expect(page.locator('[data-vehicle="acme/robot-2"]')).to_have_attribute(
        "data-status", "idle"
    )
    await waiting.locator(".body").click()
    await expect(page.locator('#holds [data-hold="node:7"]')).to_be_attached()
    await expect(page.locator('#holds [data-hold="edge:17"]')).to_be_attached()
    await expect(page.locator('#waits [data-waits-for="acme/robot-2"]')).to_be_attached()
    details = page.locator("#selected .traffic")
    await expect(details).to_contain_text("node:7, edge:17")
    await expect(details).to_contain_text("node:1 for 2.5 s")
    await expect(details).to_contain_text("node 1 is held by acme/robot-2")
    await details.locator('[data-select="acme/robot-2"]').click()
    await expect(page.locator("#selected")).to_have_attribute(
        "data-vehicle-selected", "acme/robot-2"
    )
    watch.clean()


async def test_an_api_key_from_the_url_goes_with_every_request(
    browser: Browser, fleet: Fleet
) -> None:
    """``?key=`` is taken out of the address and sent as X-API-Key and Bearer token with the
    stream and with every action."""
    seen: list[Request] = []
    page, watch = await open_map(browser, f"{fleet.url}?key=s3cret")
    assert "key=" not in page.url
    # A bound builtin cannot be a Playwright listener (it wraps the callable it is given).
    page.on("request", lambda request: seen.append(request))  # noqa: PLW0108
    await page.reload()
    await page.wait_for_function("() => window.vdaMap && window.vdaMap.ready")
    await page.locator('tr[data-row-vehicle="acme/robot-2"]').click()
    await page.locator('#selected button[data-action="pause"]').click()
    await expect(page.locator('[data-vehicle="acme/robot-2"]')).to_have_attribute(
        "data-status", "paused"
    )
    calls = [r for r in seen if "/events" in r.url or "/instantActions" in r.url]
    assert {("/events" in r.url) for r in calls} == {True, False}
    for request in calls:
        headers = await request.all_headers()
        assert headers.get("x-api-key") == "s3cret"
        assert headers.get("authorization") == "Bearer s3cret"
    watch.clean()


STATUS_CASES = """async () => {
  const { vehicleStatus } = await import("/map-assets/js/status.js");
  const base = { connection: "ONLINE", hasState: true, lastStateWall: 1000,
    unreachableAfterS: 90, errors: [], paused: false, driving: false, nodeStates: [],
    edgeStates: [], actionStates: [] };
  const at = (over, traffic = null, now = 1001) =>
    vehicleStatus({ ...base, ...over }, traffic, now);
  const fatal = [{ errorLevel: "FATAL" }];
  return {
    idle: at({}),
    broken: at({ connection: "CONNECTIONBROKEN" }),
    never: at({ connection: null, hasState: false }),
    silent: at({}, null, 1091),
    error: at({ errors: fatal, paused: true }),
    warning: at({ errors: [{ errorLevel: "WARNING" }] }),
    paused: at({ paused: true, driving: true }),
    estop: at({ eStop: "REMOTE", operatingMode: "MANUAL", paused: true }),
    manual: at({ operatingMode: "MANUAL", paused: true, driving: true }),
    service: at({ operatingMode: "SERVICE" }),
    semi: at({ operatingMode: "SEMIAUTOMATIC", driving: true }),
    noStop: at({ eStop: "NONE", operatingMode: "AUTOMATIC" }),
    waiting: at({ driving: true }, { waitingFor: ["acme/x"] }),
    notWaiting: at({ driving: true }, { waitingFor: [] }),
    driving: at({ driving: true }),
    busyNodes: at({ nodeStates: [{}] }),
    busyAction: at({ actionStates: [{ actionStatus: "RUNNING" }] }),
    doneAction: at({ actionStates: [{ actionStatus: "FINISHED" }] }),
  };
}"""


async def test_status_mapping_in_the_browser(browser: Browser, fleet: Fleet) -> None:
    """The one status function: offline beats error beats estop beats manual beats paused
    beats waiting beats driving beats busy beats idle; WARNING errors, ended actions,
    SEMIAUTOMATIC and eStop NONE do not change the colour."""
    page, watch = await open_map(browser, fleet.url)
    statuses = await page.evaluate(STATUS_CASES)
    assert statuses == {
        "idle": "idle",
        "broken": "offline",
        "never": "offline",
        "silent": "offline",
        "error": "error",
        "warning": "idle",
        "paused": "paused",
        "estop": "estop",
        "manual": "manual",
        "service": "manual",
        "semi": "driving",
        "noStop": "idle",
        "waiting": "waiting",
        "notWaiting": "driving",
        "driving": "driving",
        "busyNodes": "busy",
        "busyAction": "busy",
        "doneAction": "idle",
    }
    watch.clean()


async def test_an_e_stop_and_manual_mode_show_on_the_marker(browser: Browser, fleet: Fleet) -> None:
    """The vehicle's stack reports an emergency stop, then MANUAL (R104, R105): the marker turns
    'estop', then 'manual', then back to 'idle' in AUTOMATIC."""
    page, watch = await open_map(browser, fleet.url)
    runtime = fleet.vehicles.runtimes[0]
    marker = page.locator(f'[data-vehicle="acme/{runtime.agv.serial_number}"]')
    await expect(marker).to_have_attribute("data-status", "idle")
    runtime.on_stack_status(StackStatus(e_stop=EStop.REMOTE))
    await expect(marker).to_have_attribute("data-status", "estop")
    runtime.on_stack_status(StackStatus(RobotMode.MANUAL))
    await expect(marker).to_have_attribute("data-status", "manual")
    runtime.on_stack_status(StackStatus())
    await expect(marker).to_have_attribute("data-status", "idle")
    watch.clean()


async def test_the_graphs_zones_are_drawn_with_the_edges_they_close(
    browser: Browser, fleet: Fleet, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A BLOCKED zone and a SPEED_LIMIT zone of the graph file show as shaded areas named in
    the legend; the edges the BLOCKED one closes are still drawn, marked closed."""
    zoned = demo_graph_with_zones(
        zone("maintenance", "BLOCKED", [[13.0, -1.5], [17.0, -1.5], [17.0, 1.5], [13.0, 1.5]]),
        zone("slow", "SPEED_LIMIT", [[-1.0, 7.0], [6.0, 7.0], [6.0, 9.0]], maximumSpeed=0.4),
    )
    monkeypatch.setattr(fleet.master.service, "graph", zoned)
    page, watch = await open_map(browser, fleet.url)
    blocked = page.locator('polygon.zone[data-zone-id="maintenance"]')
    await expect(blocked).to_have_attribute("data-zone-type", "BLOCKED")
    await expect(page.locator('polygon[data-zone-id][data-zone-type="SPEED_LIMIT"]')).to_have_count(
        1
    )
    assert await blocked.locator("title").text_content() == "BLOCKED maintenance"
    closed = page.locator("line.edge.blocked")
    await expect(closed).to_have_count(len(zoned.blocked_edges))
    ids = {await line.get_attribute("data-edge-id") for line in await closed.all()}
    assert ids == set(zoned.blocked_edges)
    await expect(page.locator("#legend")).to_contain_text("speed limit")
    watch.clean()


async def test_a_zone_added_and_lifted_while_the_map_is_open_is_drawn_and_removed(
    browser: Browser, fleet: Fleet
) -> None:
    """POST /zones while the page is open: the zone and the edges it closes appear without a
    reload; DELETE takes them away again; the vehicles stay on the map throughout."""
    page, watch = await open_map(browser, fleet.url)
    markers = page.locator("g.vehicle")
    await expect(markers).not_to_have_count(0)
    shown = await markers.count()
    spill = zone("spill", "BLOCKED", [[13.0, -1.5], [17.0, -1.5], [17.0, 1.5], [13.0, 1.5]])
    await fleet.master.service.add_zone(GraphZone.model_validate(spill))
    await expect(page.locator('polygon.zone[data-zone-id="spill"]')).to_have_count(1)
    await expect(page.locator("line.edge.blocked")).to_have_count(
        len(fleet.master.service.graph.blocked_edges)
    )
    await expect(markers).to_have_count(shown)
    await fleet.master.service.remove_zone("spill")
    await expect(page.locator("polygon.zone")).to_have_count(0)
    await expect(page.locator("line.edge.blocked")).to_have_count(0)
    await expect(markers).to_have_count(shown)
    watch.clean()


async def _click_at(page: Page, x: float, y: float) -> None:
    """A click on the map at map coordinates (x, y) metres."""
    point = await page.evaluate(
        """([x, y]) => {
          const screen = document.querySelector("#map").getScreenCTM();
          const p = new DOMPoint(x, -y).matrixTransform(screen);
          return [p.x, p.y];
        }""",
        [x, y],
    )
    await page.mouse.click(point[0], point[1])


async def test_an_area_blocked_on_the_map_keeps_orders_out_until_lifted_there(
    browser: Browser, fleet: Fleet
) -> None:
    """An operator draws an area round node 10 (Block an area, four corners, Enter, a name):
    master control holds it as a BLOCKED zone added through the API, and the map shows it.
    A crossing polygon is refused with the master's own reason. Clicking the zone lifts it.
    Slow an area asks for the speed as well and gives a SPEED_LIMIT zone."""
    page, watch = await open_map(browser, fleet.url)
    answers = iter(["bow", "spill", "crossing", "0.4"])

    async def answer(dialog: Dialog) -> None:
        await dialog.accept("" if dialog.type == "confirm" else next(answers))

    page.on("dialog", answer)
    await page.click("#block-area")
    for x, y in ((13.0, -1.5), (17.0, 1.5), (17.0, -1.5), (13.0, 1.5)):  # sides cross
        await _click_at(page, x, y)
    await page.keyboard.press("Enter")
    await expect(page.locator("#toast")).to_contain_text("its sides 1 and 3 cross")
    await page.keyboard.press("Escape")

    await page.click("#block-area")
    for x, y in ((13.0, -1.5), (17.0, -1.5), (17.0, 1.5), (13.0, 1.5)):
        await _click_at(page, x, y)
    await page.keyboard.press("Enter")
    await expect(page.locator('polygon.zone[data-zone-id="spill"]')).to_have_count(1)
    await expect(page.locator("#toast")).to_contain_text("zone spill blocks 3 edges")
    service = fleet.master.service
    assert [z.zone_id for z in service.runtime_zones()] == ["spill"]
    assert service.graph.blocked_nodes == {"10": "spill"}
    assert await page.locator("#draft *").count() == 0

    await _click_at(page, 14.0, 1.0)  # inside the zone, clear of nodes and edges
    await expect(page.locator("polygon.zone")).to_have_count(0)
    assert service.runtime_zones() == ()

    await page.click("#slow-area")  # a speed limit round node 5: asks for the speed too
    for x, y in ((3.5, 6.5), (6.5, 6.5), (6.5, 9.5), (3.5, 9.5)):
        await _click_at(page, x, y)
    await page.keyboard.press("Enter")
    slow = page.locator('polygon.zone[data-zone-id="crossing"]')
    await expect(slow).to_have_attribute("data-zone-type", "SPEED_LIMIT")
    await expect(page.locator("#toast")).to_contain_text("zone crossing slows")
    assert {service.graph.edges[e].max_speed for e in service.graph.limited_edges} == {0.4}
    assert watch.foreign_requests == []
    assert len(watch.console_errors) == 1  # the browser's own line for the refused polygon
    assert "422" in watch.console_errors[0]
