"""The demo run: broker, master and robots up, missions dispatched through the HTTP API, live
progress in the terminal, a summary at the end."""

from __future__ import annotations

import asyncio
import contextlib
import json
import random
import re
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import httpx

from vda5050.broker import EmbeddedBroker
from vda5050.mqtt import BrokerEndpoint, MqttSession, MqttSettings
from vda_demo.display import summary_lines, vehicle_line
from vda_demo.missions import (
    MANUFACTURER,
    ROBOT_STARTS,
    Mission,
    demo_missions,
    next_mission,
    stations_of,
)
from vda_demo.separation import Separation
from vda_demo.stack import (
    PortTakenError,
    Service,
    check_port_free,
    first_exited,
    python_module,
    running,
)

ROBOTS = tuple(ROBOT_STARTS)
TERMINAL_FAILURES = frozenset({"FAILED", "REJECTED", "CANCELLED"})


class DemoError(Exception):
    """The demo cannot go on; the message says why."""


@dataclass(frozen=True, slots=True)
class DemoOptions:
    """What the command line chose. Times in seconds."""

    broker_host: str = "127.0.0.1"
    broker_port: int = 0
    broker_url: str | None = None
    api_port: int = 8050
    time_lapse: float = 3.0
    forever: bool = False
    timeout_s: float = 55.0
    config_dir: Path = Path("config")
    interface_name: str = "uagv"

    @property
    def graph(self) -> Path:
        """The demo's floor: the warehouse with one-lane aisles."""
        return self.config_dir / "graphs" / "warehouse.json"


@dataclass
class Progress:
    """What the display shows and the summary reports."""

    missions: list[Mission]
    started: dict[str, float] = field(default_factory=dict)
    finished: list[tuple[str, str, float]] = field(default_factory=list)
    orders: dict[str, dict[str, object]] = field(default_factory=dict)
    #: Per order: the seconds from its start to the expectedFinishAt first seen.
    expected: dict[str, float] = field(default_factory=dict)


def service_commands(options: DemoOptions, broker_url: str, logs: Path) -> list[Service]:
    """master control and one vehicle process per robot, each from its YAML file."""
    common = ["--broker-url", broker_url, "--interface-name", options.interface_name]
    common += ["--graph", str(options.graph)]
    fleet = json.dumps([{"manufacturer": MANUFACTURER, "serial_number": r} for r in ROBOTS])
    master = Service(
        "master",
        python_module(
            "vda_master",
            "--config",
            str(options.config_dir / "master.yaml"),
            *common,
            "--api-port",
            str(options.api_port),
            "--data-dir",
            str(logs / "master-data"),
            "--robots",
            fleet,
            # traffic control's waits and margins in the robots' simulated time
            "--time-lapse",
            str(options.time_lapse),
        ),
        logs / "master.log",
    )
    robots = [
        Service(
            robot,
            python_module(
                "vda_vehicle",
                "--config",
                str(options.config_dir / f"{robot}.yaml"),
                *common,
                "--start-node",
                ROBOT_STARTS[robot],
                "--time-lapse",
                str(options.time_lapse),
                "--visualization-interval-s",
                "0.1",
            ),
            logs / f"{robot}.log",
        )
        for robot in ROBOTS
    ]
    return [master, *robots]


@contextlib.asynccontextmanager
async def broker_for(options: DemoOptions) -> AsyncIterator[str]:
    """The broker URL: the given one, or an embedded broker started for the demo."""
    if options.broker_url is not None:
        BrokerEndpoint.from_url(options.broker_url)  # fails early on a malformed URL
        yield options.broker_url
        return
    if options.broker_port:
        check_port_free(options.broker_host, options.broker_port, "MQTT broker", "--broker-port")
    async with EmbeddedBroker(options.broker_host, options.broker_port) as address:
        yield address.url


def banner(broker_url: str, options: DemoOptions, logs: Path) -> str:
    endpoint = BrokerEndpoint.from_url(broker_url)
    return "\n".join(
        [
            f"MQTT broker   {endpoint.display}",
            (
                f"watch traffic mosquitto_sub -h {endpoint.host} -p {endpoint.port} "
                f"-t '{options.interface_name}/#' -v"
            ),
            f"master API    http://127.0.0.1:{options.api_port}/docs",
            f"live map      open http://127.0.0.1:{options.api_port}/ to watch the fleet",
            f"service logs  {logs}",
            "",
        ]
    )


async def wait_ready(
    http: httpx.AsyncClient, services: Sequence[Service], timeout_s: float
) -> None:
    """Until the API answers and every robot is available (ONLINE, AUTOMATIC, idle)."""
    async with asyncio.timeout(timeout_s):
        while True:
            check_alive(services)
            with contextlib.suppress(httpx.TransportError):
                answer = await http.get("/vehicles")
                ready = {v["serialNumber"] for v in answer.json() if v.get("available")}
                if answer.status_code == 200 and ready >= set(ROBOTS):  # noqa: PLR2004
                    return
            await asyncio.sleep(0.2)


def check_alive(services: Sequence[Service]) -> None:
    dead = first_exited(services)
    if dead is not None:
        msg = (
            f"{dead.name} exited with status {dead.exited()}; the end of its log "
            f"({dead.log_path}):\n{dead.log_tail()}"
        )
        raise DemoError(msg)


async def send_step(http: httpx.AsyncClient, mission: Mission, progress: Progress) -> None:
    """POST the mission's current order and remember its id. A robot that is busy (409: e.g.
    traffic control is moving it out of another robot's way) gets the order on a later round."""
    answer = await http.post("/orders", json=mission.next_body())
    if answer.status_code == 409:  # noqa: PLR2004
        return
    if answer.status_code != 201:  # noqa: PLR2004
        msg = f"{mission.serial_number}: POST /orders answered {answer.status_code}: {answer.text}"
        raise DemoError(msg)
    order_id = str(answer.json()["orderId"])
    mission.order_ids.append(order_id)
    progress.started[order_id] = time.monotonic()


async def advance_missions(http: httpx.AsyncClient, progress: Progress) -> None:
    """Poll each mission's current order; send the next step when it finished."""
    for mission in progress.missions:
        if mission.done:
            continue
        if len(mission.order_ids) <= mission.step:
            await send_step(http, mission, progress)
            continue
        order_id = mission.order_ids[mission.step]
        info = (await http.get(f"/orders/{order_id}")).json()
        progress.orders[mission.serial_number] = info
        note_expected(progress, order_id, info.get("expectedFinishAt"))
        status = info.get("status")
        if status in TERMINAL_FAILURES:
            msg = f"{mission.serial_number}: order {order_id} ended {status}: {info.get('reason')}"
            raise DemoError(msg)
        if status == "FINISHED":
            progress.finished.append(
                (mission.serial_number, order_id, time.monotonic() - progress.started[order_id])
            )
            mission.step += 1


def note_expected(progress: Progress, order_id: str, at: object) -> None:
    """The first ``expectedFinishAt`` of an order, as seconds from its start (the summary)."""
    if order_id in progress.expected or not isinstance(at, str) or order_id not in progress.started:
        return
    left = (datetime.fromisoformat(at) - datetime.now(UTC)).total_seconds()
    progress.expected[order_id] = time.monotonic() - progress.started[order_id] + left


async def render(http: httpx.AsyncClient, progress: Progress, previous: list[str]) -> list[str]:
    """Show one line per robot; rewrite in place on a terminal, else print on change."""
    lines = []
    for robot in ROBOTS:
        vehicle = (await http.get(f"/vehicles/{MANUFACTURER}/{robot}")).json()
        mission = next((m for m in progress.missions if m.serial_number == robot), None)
        title = "" if mission is None else mission.title
        order = progress.orders.get(robot)
        own = vehicle.get("orderId")
        if own and own not in progress.started:
            # an order of master control's own: to a charger, or out of another's way
            order = (await http.get(f"/orders/{own}")).json()
            title = str(order.get("note") or f"order {own}")
        lines.append(vehicle_line(vehicle, order, title))  # type: ignore[arg-type]
    if sys.stdout.isatty():
        if previous:
            sys.stdout.write(f"\x1b[{len(previous)}F")
        sys.stdout.write("".join(f"\x1b[2K{line}\n" for line in lines))
        sys.stdout.flush()
    else:  # a log: print a robot's line when more than its battery or wait time changed
        before = {line.split()[0]: _gist(line) for line in previous}
        changed = [line for line in lines if before.get(line.split()[0]) != _gist(line)]
        if changed:
            print("\n".join(changed), flush=True)  # noqa: T201 - the demo's output
    return lines


def _gist(line: str) -> str:
    """What of a robot's line matters for a log: not its battery, not how long it waited, not
    when its order is expected done (the estimate moves with every state)."""
    without_battery = line.split("battery", maxsplit=1)[0] + line.split("%", 1)[-1]
    return re.sub(r"\([0-9.?]+ s\)|  done by \S+ UTC", "", without_battery)


def refill(
    progress: Progress,
    vehicles: list[dict[str, object]],
    rng: random.Random,
    graph: dict[str, object],
) -> None:
    """``--forever``: give each robot whose mission is done and that is available a new
    transport. One that is not (master control sends it to charge, or it charges) gets its
    next transport once it is available again."""
    stations = stations_of(graph)  # type: ignore[arg-type]
    available = {str(v["serialNumber"]) for v in vehicles if v.get("available")}
    for index, mission in enumerate(progress.missions):
        if mission.done and mission.serial_number in available:
            progress.missions[index] = next_mission(mission.serial_number, stations, rng)


async def drive(
    http: httpx.AsyncClient,
    services: Sequence[Service],
    options: DemoOptions,
    progress: Progress,
    stop: asyncio.Event,
) -> None:
    """Run the missions until all finished (with ``--forever`` until ``stop``), showing progress."""
    graph = json.loads(options.graph.read_text())
    rng = random.Random(5050)  # noqa: S311 - mission choice, not security
    deadline = time.monotonic() + options.timeout_s
    lines: list[str] = []
    while not stop.is_set() and (options.forever or not all(m.done for m in progress.missions)):
        check_alive(services)
        if not options.forever and time.monotonic() > deadline:
            msg = f"the missions did not finish within {options.timeout_s:.0f} s"
            raise DemoError(msg)
        await advance_missions(http, progress)
        lines = await render(http, progress, lines)
        if options.forever:
            refill(progress, (await http.get("/vehicles")).json(), rng, graph)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(0.25):
                await stop.wait()
    await render(http, progress, lines)


async def run_demo(options: DemoOptions, stop: asyncio.Event) -> int:
    """The whole demo; returns the exit status (0 done, 1 a mission failed, 2 set-up problem)."""
    progress = Progress(missions=demo_missions())
    separation = Separation()
    safety_m: float | None = None
    try:
        check_port_free("127.0.0.1", options.api_port, "master HTTP API", "--api-port")
        logs = Path(tempfile.mkdtemp(prefix="vda-demo-"))
        async with broker_for(options) as broker_url:
            print(banner(broker_url, options, logs), flush=True)  # noqa: T201
            services = service_commands(options, broker_url, logs)
            async with (
                running(services),
                observing(broker_url, options.interface_name, separation),
                httpx.AsyncClient(
                    base_url=f"http://127.0.0.1:{options.api_port}", timeout=5.0
                ) as http,
            ):
                await wait_ready(http, services, timeout_s=30.0)
                await drive(http, services, options, progress, stop)
                traffic = (await http.get("/traffic")).json()
                safety_m = traffic.get("safetyDistanceM")
    except PortTakenError as exc:
        print(f"error: {exc}", file=sys.stderr)  # noqa: T201
        return 2
    except (DemoError, TimeoutError) as exc:
        reason = str(exc) or "the services did not become ready within 30 s"
        print(f"\ndemo failed: {reason}", file=sys.stderr)  # noqa: T201
        return 1
    print("\nFinished orders:" if options.forever else "\nAll orders finished:")  # noqa: T201
    print("\n".join(summary_lines(progress.finished, progress.expected)))  # noqa: T201
    print(separation.summary(safety_m))  # noqa: T201
    return 0


@contextlib.asynccontextmanager
async def observing(broker_url: str, interface: str, separation: Separation) -> AsyncIterator[None]:
    """The demo's own subscription to every robot's visualization, for the closest approach."""
    session = MqttSession(MqttSettings(url=broker_url, client_id=None), name="demo.observer")
    session.subscribe(f"{interface}/v2/+/+/visualization", separation.on_message)
    async with asyncio.TaskGroup() as group:
        group.create_task(session.run(), name="demo.observer")
        try:
            yield
        finally:
            await session.stop()
