"""Fleet benchmark (issue 12): our stack side by side with vda-5050-lib 1.4.0, N vehicles.

Every vehicle drives one 16 m order: two 8 m edges along its own lane (lanes 3 m apart), 2 m/s,
time lapse 1, visualization at 1 Hz, VDA 2.0.0, the whole order released. Both stacks run in the
same invocation, one after the other, each on its own fresh Mosquitto:

- peer: vda-5050-lib's MasterController and N virtual AGVs in one Node process
  (``benchmarks/peer/fleet.js``; the library comes from the npm registry into
  ``.cache/interop`` as for the interop tests);
- ours: one ``vda-master`` process and one ``vda-vehicle --count N`` process, the orders sent
  through ``POST /orders`` (traffic control off unless ``--traffic-control``: the peer has none);
  ``--batch 50`` sends them through ``POST /orders/batch``, 50 to a request, instead, and
  ``--batch 1 50`` runs ours once each way (one column each).

An observer in its own process (``--observe``), independent of both stacks, subscribes to every
``state`` and ``order`` topic and counts state messages per vehicle, lost states (gaps in a
vehicle's headerIds), resends (an order message with an orderId/orderUpdateId seen before),
the time from an order message to the vehicle's first state carrying that order, and when each
vehicle has finished (a state of the order with no node or edge left and not driving).

Figures per stack: time from starting the vehicles' process until every vehicle is available
(ours: ``GET /health`` counts every vehicle available, as ``GET /vehicles`` says each,
polled at 10 Hz; peer: its master has a state of every AGV);
completion time of the burst (first order sent until the last vehicle finished) and its ratio
to the ideal 8 s; CPU-seconds of each process during the drive (and of it while the orders were
being sent) and during start-up; peak RSS;
state messages; lost states; order-to-first-accepting-state p50/p99; resends; the order call's
p99 (ours: ``POST /orders`` or ``POST /orders/batch`` answered; peer: ``assignOrder`` resolved).

``--idle``: N vehicles connected, no orders, ``--idle-seconds`` (60): CPU % of each process.

The machine is shared and small: run it more than once before trusting a difference.
``--rounds K`` does: both stacks K times, alternating which goes first, each round's table,
then median [min-max] per stack and issue 12's targets met per round
(``benchmarks/fleet_rounds.py``).

Run: .venv/bin/python benchmarks/fleet.py [--vehicles 100] [--idle] [--only ours|peer]
     [--rounds K]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for tests.* and benchmarks.*

import aiomqtt  # noqa: TID251 - the observer is nobody's MQTT session, just a listener
import httpx
import orjson

from benchmarks.fleet_rounds import observed_figure, percentile, stack_total, summary
from benchmarks.lean_http import LeanConnection
from tests.interop.node_lib import install_vda_lib
from tests.mosquitto import free_port, run_mosquitto
from tests.system.stack import ServiceProcess, process_env

REPO = Path(__file__).resolve().parents[1]
PEER_SCRIPT = Path(__file__).resolve().parent / "peer" / "fleet.js"
INTERFACE = "fleet"
EDGE_M = 8.0
LANE_M = 3.0
SPEED_MPS = 2.0
IDEAL_S = 2 * EDGE_M / SPEED_MPS
TICKS = os.sysconf("SC_CLK_TCK")
_Stream = TypeVar("_Stream")
POST_CONCURRENCY = 32
#: Batch requests in flight at once (``--batch`` over 1): enough to overlap one request's
#: write-ahead with the next one's planning.
BATCH_CONCURRENCY = 4
#: GET /health counts the available vehicles, ~7 ms of the master's time for 1000 (GET
#: /vehicles, polled until 2026-11-24 at 4 Hz, took 20-150 ms): the figure is known to 0.1 s.
AVAILABLE_POLL_S = 0.1


def cpu_s(pid: int) -> float:
    """User + system CPU-seconds of a process so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def peak_rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


# --- the observer (its own process) -------------------------------------------------------------


@dataclass
class VehicleRecord:
    states: int = 0
    last_header: int | None = None
    lost: int = 0
    orders: dict[tuple[str, int], float] = field(default_factory=dict)  # first seen, unix s
    accepted: set[tuple[str, int]] = field(default_factory=set)
    finished_at: float | None = None


@dataclass
class Observation:
    vehicles: dict[str, VehicleRecord] = field(default_factory=dict)
    accept_latency_s: list[float] = field(default_factory=list)
    #: Per finished vehicle: its order message seen → the state showing it done (the vehicle's
    #: share of the completion time; the ideal drive is IDEAL_S).
    drive_s: list[float] = field(default_factory=list)
    resends: int = 0
    order_messages: int = 0

    def record(self, serial: str) -> VehicleRecord:
        found = self.vehicles.get(serial)
        if found is None:
            found = self.vehicles[serial] = VehicleRecord()
        return found

    def see(self, topic: str, payload: bytes, now: float) -> bool:
        """Fold in one message; True when it finished a vehicle's order."""
        parts = topic.split("/")
        if len(parts) != 5:
            return False
        vehicle = self.record(parts[3])
        message = orjson.loads(payload)
        if parts[4] == "order":
            key = (message["orderId"], message["orderUpdateId"])
            self.order_messages += 1
            if key in vehicle.orders:
                self.resends += 1
            else:
                vehicle.orders[key] = now
            return False
        vehicle.states += 1
        header = message.get("headerId")
        if isinstance(header, int):
            if vehicle.last_header is not None and header > vehicle.last_header + 1:
                vehicle.lost += header - vehicle.last_header - 1
            vehicle.last_header = header
        key = (message.get("orderId", ""), message.get("orderUpdateId", 0))
        sent = vehicle.orders.get(key)
        if sent is None:
            return False
        if key not in vehicle.accepted:
            vehicle.accepted.add(key)
            self.accept_latency_s.append(now - sent)
        done = not message.get("nodeStates") and not message.get("edgeStates")
        if done and not message.get("driving") and vehicle.finished_at is None:
            vehicle.finished_at = now
            self.drive_s.append(now - sent)
            return True
        return False

    def report(self) -> dict[str, object]:
        finished = [v.finished_at for v in self.vehicles.values() if v.finished_at is not None]
        return {
            "event": "report",
            "vehicles_seen": len(self.vehicles),
            "states": sum(v.states for v in self.vehicles.values()),
            "lost_states": sum(v.lost for v in self.vehicles.values()),
            "order_messages": self.order_messages,
            "resends": self.resends,
            "accept_p50_s": percentile(self.accept_latency_s, 0.5),
            "accept_p99_s": percentile(self.accept_latency_s, 0.99),
            "drive_min_s": min(self.drive_s, default=float("nan")),
            "drive_p50_s": percentile(self.drive_s, 0.5),
            "drive_max_s": max(self.drive_s, default=float("nan")),
            "finished": len(finished),
            "last_finished_t": max(finished, default=None),
        }


async def observe(port: int, vehicles: int) -> None:
    """Listen until stdin closes or says "report"; print "subscribed", "complete", "report"."""
    observation = Observation()
    finished = 0

    def say(line: dict[str, object]) -> None:
        sys.stdout.write(json.dumps({"t": time.time(), **line}) + "\n")
        sys.stdout.flush()

    async with aiomqtt.Client("127.0.0.1", port, identifier="fleet-observer") as client:
        await client.subscribe(f"{INTERFACE}/+/+/+/state")
        await client.subscribe(f"{INTERFACE}/+/+/+/order")
        say({"event": "subscribed"})

        async def listen() -> None:
            nonlocal finished
            async for message in client.messages:
                payload = message.payload
                if isinstance(payload, bytes) and observation.see(
                    str(message.topic), payload, time.time()
                ):
                    finished += 1
                    if finished == vehicles:
                        say({"event": "complete"})

        listener = asyncio.create_task(listen())
        loop = asyncio.get_running_loop()
        reader = asyncio.StreamReader()
        await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
        await reader.readline()
        listener.cancel()
    say(observation.report())


@dataclass
class Observer:
    """The observer process seen from the benchmark."""

    process: asyncio.subprocess.Process
    lines: asyncio.Queue[dict[str, object]] = field(default_factory=asyncio.Queue)

    async def pump(self) -> None:
        stdout = _pipe(self.process.stdout)
        while line := await stdout.readline():
            await self.lines.put(json.loads(line))

    async def wait(self, event: str, limit_s: float) -> dict[str, object]:
        async with asyncio.timeout(limit_s):
            while True:
                line = await self.lines.get()
                if line.get("event") == event:
                    return line

    async def report(self) -> dict[str, object]:
        stdin = _pipe(self.process.stdin)
        stdin.write(b"report\n")
        await stdin.drain()
        return await self.wait("report", 30)


@asynccontextmanager
async def observer(port: int, vehicles: int) -> AsyncIterator[Observer]:
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        __file__,
        "--observe",
        str(port),
        "--vehicles",
        str(vehicles),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        limit=2**22,
    )
    watcher = Observer(process)
    pump = asyncio.create_task(watcher.pump())
    try:
        await watcher.wait("subscribed", 20)
        yield watcher
    finally:
        if process.returncode is None:
            process.kill()
        await process.wait()
        pump.cancel()


# --- the two stacks -------------------------------------------------------------------------------


@dataclass
class Result:
    """One stack's figures; processes maps a name to its pid."""

    name: str
    processes: dict[str, int] = field(default_factory=dict)
    available_s: float = float("nan")
    completion_s: float = float("nan")
    cpu_start: dict[str, float] = field(default_factory=dict)
    cpu_drive: dict[str, float] = field(default_factory=dict)
    #: CPU-seconds of each process while the orders were being sent (part of ``cpu_drive``).
    cpu_sending: dict[str, float] = field(default_factory=dict)
    idle_cpu_pct: dict[str, float] = field(default_factory=dict)
    rss_mib: dict[str, float] = field(default_factory=dict)
    call_s: list[float] = field(default_factory=list)
    orders_sent_s: float = float("nan")
    #: CPU-seconds the benchmark itself spent sending the orders (HTTP client).
    client_cpu_s: float = float("nan")
    observed: dict[str, object] = field(default_factory=dict)


def cpu_all(result: Result) -> dict[str, float]:
    return {name: cpu_s(pid) for name, pid in result.processes.items()}


def cpu_delta(before: dict[str, float], after: dict[str, float]) -> dict[str, float]:
    return {name: after[name] - before[name] for name in before}


async def drive_or_idle(
    result: Result,
    watcher: Observer,
    vehicles: int,
    idle_s: float | None,
    send_orders: Callable[[], Awaitable[None]],
) -> None:
    """After all vehicles are available: idle for ``idle_s`` or send the burst and wait."""
    if idle_s is not None:
        await asyncio.sleep(2)
        before, begin = cpu_all(result), time.monotonic()
        await asyncio.sleep(idle_s)
        used = cpu_delta(before, cpu_all(result))
        result.idle_cpu_pct = {k: 100 * v / (time.monotonic() - begin) for k, v in used.items()}
        return
    before = cpu_all(result)
    burst = time.time()
    sending = asyncio.ensure_future(send_orders())
    try:
        await watcher.wait("complete", 60 + vehicles / 10)
    except TimeoutError:
        print(f"  {result.name}: not every vehicle finished in time", file=sys.stderr)
    await sending
    result.cpu_drive = cpu_delta(before, cpu_all(result))
    result.observed = await watcher.report()
    last = result.observed.get("last_finished_t")
    if isinstance(last, float):
        result.completion_s = last - burst


def _profiles(
    result: Result, phase: str, folder: Path | None, rate: int
) -> list[subprocess.Popen[bytes]]:
    """py-spy sampling each of our Python processes at ``rate`` Hz into
    ``folder/<name>-<phase>.txt`` (collapsed stacks) until :func:`_stop_profiles`; none without
    a folder."""
    if folder is None:
        return []
    folder.mkdir(parents=True, exist_ok=True)
    spy = Path(sys.executable).parent / "py-spy"
    if not spy.exists():
        msg = f"--profile needs py-spy next to this Python ({spy}): pip install py-spy"
        raise SystemExit(msg)
    started = []
    for name, pid in result.processes.items():
        if name.startswith("vda-"):
            command = [str(spy), "record", "--pid", str(pid), "--rate", str(rate), "--nonblocking"]
            command += ["--format", "raw", "--output", str(folder / f"{name}-{phase}.txt")]
            started.append(
                subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # noqa: S603
            )
    return started


async def _stop_profiles(profilers: list[subprocess.Popen[bytes]]) -> None:
    for profiler in profilers:
        profiler.send_signal(signal.SIGINT)
        await asyncio.to_thread(profiler.wait, 30)
    profilers.clear()


async def run_peer(folder: Path, vehicles: int, idle_s: float | None) -> Result:
    runtime = install_vda_lib()
    result = Result("vda-5050-lib 1.4.0")
    with run_mosquitto(folder / "peer-broker") as broker:
        result.processes["mosquitto"] = broker.process.pid
        async with observer(broker.address.port, vehicles) as watcher:
            config = {
                "brokerUrl": broker.address.url,
                "interfaceName": INTERFACE,
                "manufacturer": "peer",
                "vehicles": vehicles,
                "laneSpacing": LANE_M,
                "edgeLength": EDGE_M,
                "speed": SPEED_MPS,
                "timeLapse": 1,
                "visualizationIntervalS": 1,
                "orders": idle_s is None,
            }
            start = time.time()
            node = await asyncio.create_subprocess_exec(
                runtime.node,
                str(PEER_SCRIPT),
                json.dumps(config),
                env=runtime.env(),
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                limit=2**22,
            )
            stdout, stdin = _pipe(node.stdout), _pipe(node.stdin)
            result.processes = {"node": node.pid, **result.processes}
            events: asyncio.Queue[dict[str, object]] = asyncio.Queue()

            async def pump() -> None:
                while line := await stdout.readline():
                    event = json.loads(line)
                    if event["event"] == "peer_error":
                        print(f"  peer: {event['message']}"[:300], file=sys.stderr)
                    await events.put(event)

            async def next_event(name: str, limit_s: float) -> dict[str, object]:
                async with asyncio.timeout(limit_s):
                    while (event := await events.get())["event"] != name:
                        if event["event"] == "order_sent":
                            result.call_s.append(float(event["callS"]))  # type: ignore[arg-type]
                    return event

            pumping = asyncio.create_task(pump())
            try:
                available = await next_event("available", 30 + vehicles / 20)
                result.available_s = float(available["t"]) - start  # type: ignore[arg-type]
                result.cpu_start = cpu_all(result)

                async def go() -> None:
                    stdin.write(b"go\n")
                    await stdin.drain()
                    begin = await next_event("orders_start", 30)
                    done = await next_event("orders_sent", 60 + vehicles / 10)
                    result.orders_sent_s = float(done["t"]) - float(begin["t"])  # type: ignore[arg-type]

                await drive_or_idle(result, watcher, vehicles, idle_s, go)
                result.rss_mib = {k: peak_rss_mib(p) for k, p in result.processes.items()}
            finally:
                if node.returncode is None:
                    node.terminate()
                    try:
                        await asyncio.wait_for(node.wait(), 10)
                    except TimeoutError:
                        node.kill()
                        await node.wait()
                pumping.cancel()
    return result


def lane_orders(vehicles: int, batch: int) -> list[list[dict[str, object]]]:
    """The ``POST /orders`` body of every vehicle (its two-edge lane of :func:`lanes_graph`),
    ``batch`` to a group (the last one may be shorter)."""
    bodies: list[dict[str, object]] = [
        {"manufacturer": "ours", "serialNumber": f"ours-{i + 1}", "route": [f"e1_{i}", f"e2_{i}"]}
        for i in range(vehicles)
    ]
    return [bodies[i : i + batch] for i in range(0, vehicles, batch)]


def lanes_graph(path: Path, vehicles: int) -> None:
    """Start nodes a0..a(N-1) first (vehicles stand on the first N nodes in file order), then the
    middle and end nodes; edges e1_i a_i->b_i and e2_i b_i->c_i, 8 m each."""
    hops = (("a", "b"), ("b", "c"))
    nodes = [
        {"nodeId": f"{name}{i}", "x": k * EDGE_M, "y": i * LANE_M, "theta": 0.0}
        for k, name in enumerate("abc")
        for i in range(vehicles)
    ]
    edges = [
        {
            "edgeId": f"e{k + 1}_{i}",
            "startNodeId": f"{start}{i}",
            "endNodeId": f"{end}{i}",
            "maxSpeed": SPEED_MPS,
        }
        for k, (start, end) in enumerate(hops)
        for i in range(vehicles)
    ]
    path.write_text(json.dumps({"mapId": "fleet", "nodes": nodes, "edges": edges}))


def vehicles_process(common: list[str], vehicles: int, folder: Path) -> ServiceProcess:
    """The scenario's ``vda-vehicle --count N`` (not started): serials ours_0 …, on a0 …, VDA
    2.0.0, 2 m/s, time-lapse 1, visualization at 1 Hz."""
    return ServiceProcess(
        "vehicles",
        [
            "vda_vehicle",
            *common,
            *("--start-node", "a0", "--count", str(vehicles)),
            *("--serial-number", "ours", "--manufacturer", "ours"),
            *("--vda-version", "2.0.0", "--speed-max-mps", str(SPEED_MPS)),
            *("--time-lapse", "1", "--visualization-interval-s", "1"),
        ],
        folder / "vehicles.log",
        env=process_env(),
    )


async def run_ours(
    folder: Path,
    vehicles: int,
    idle_s: float | None,
    *,
    traffic: bool,
    master_args: list[str],
    profile: Path | None = None,
    profile_rate: int = 50,
    batch: int = 1,
) -> Result:
    result = Result("ours" if batch == 1 else f"ours, batches of {batch}")
    profilers: list[subprocess.Popen[bytes]] = []
    graph = folder / "lanes.json"
    lanes_graph(graph, vehicles)
    api_port = free_port()
    api = f"http://127.0.0.1:{api_port}"
    with run_mosquitto(folder / "ours-broker") as broker:
        async with observer(broker.address.port, vehicles) as watcher:
            common = ["--broker-url", broker.address.url, "--interface-name", INTERFACE]
            common += ["--graph", str(graph), "--log-level", "WARNING"]
            master = ServiceProcess(
                "master",
                [
                    "vda_master",
                    *common,
                    *("--api-port", str(api_port), "--data-dir", str(folder / "master-data")),
                    *("--release-window-nodes", "0"),
                    "--traffic-control" if traffic else "--no-traffic-control",
                    *master_args,
                ],
                folder / "master.log",
                env=process_env(),
            ).start()
            fleet = vehicles_process(common, vehicles, folder)
            try:
                async with httpx.AsyncClient(base_url=api, timeout=30) as http:
                    await _wait_healthy(http)
                    start = time.time()
                    fleet.start()
                    result.processes = {
                        "vda-master": _pid(master),
                        "vda-vehicle": _pid(fleet),
                        "mosquitto": broker.process.pid,
                    }
                    profilers.extend(_profiles(result, "start", profile, profile_rate))
                    await _wait_available(api, vehicles)
                    result.available_s = time.time() - start
                    result.cpu_start = cpu_all(result)
                    await _stop_profiles(profilers)
                    profilers.extend(_profiles(result, "send", profile, profile_rate))

                    async def burst() -> None:
                        begin, cpu = time.monotonic(), time.process_time()
                        before = cpu_all(result)
                        result.call_s = await _post_orders(api, vehicles, batch)
                        result.orders_sent_s = time.monotonic() - begin
                        result.cpu_sending = cpu_delta(before, cpu_all(result))
                        result.client_cpu_s = time.process_time() - cpu
                        if profilers:  # the rest of the drive in a profile of its own
                            await _stop_profiles(profilers)
                            profilers.extend(_profiles(result, "finish", profile, profile_rate))

                    await drive_or_idle(result, watcher, vehicles, idle_s, burst)
                    result.rss_mib = {k: peak_rss_mib(p) for k, p in result.processes.items()}
            finally:
                await _stop_profiles(profilers)
                await fleet.stop()
                await master.stop()
    return result


async def _wait_healthy(http: httpx.AsyncClient) -> None:
    async with asyncio.timeout(30):
        while True:
            try:
                if (await http.get("/health")).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            await asyncio.sleep(0.1)


async def _wait_available(api: str, vehicles: int) -> None:
    """Until ``GET /health`` counts ``vehicles`` available ones (as ``GET /vehicles`` says
    each, without a thousand documents per poll)."""
    host, port = _host_port(api)
    async with LeanConnection(host, port) as http, asyncio.timeout(30 + vehicles / 20):
        while True:
            _, body = await http.get("/health")
            if int(orjson.loads(body)["availableVehicles"]) >= vehicles:
                return
            await asyncio.sleep(AVAILABLE_POLL_S)


def _host_port(api: str) -> tuple[str, int]:
    host, _, port = api.removeprefix("http://").partition(":")
    return host, int(port)


def _pid(service: ServiceProcess) -> int:
    if service.process is None:
        msg = f"{service.name} is not running"
        raise RuntimeError(msg)
    return service.process.pid


def _pipe(stream: _Stream | None) -> _Stream:
    if stream is None:
        msg = "the child process has no such pipe"
        raise RuntimeError(msg)
    return stream


async def _post_orders(api: str, vehicles: int, batch: int) -> list[float]:
    """An order for every vehicle: one ``POST /orders`` each, ``POST_CONCURRENCY`` in flight,
    or (``batch`` over 1) ``POST /orders/batch`` with ``batch`` orders each,
    ``BATCH_CONCURRENCY`` in flight (one keep-alive connection per request in flight,
    benchmarks/lean_http.py); each request's time."""
    pending = lane_orders(vehicles, batch)[::-1]
    latencies: list[float] = []
    host, port = _host_port(api)

    async def worker() -> None:
        async with LeanConnection(host, port) as http:
            while pending:
                chunk = pending.pop()
                begin = time.monotonic()
                if batch == 1:
                    status, answer = await http.post_json("/orders", chunk[0])
                    refused = [] if status == 201 else [answer]
                else:
                    status, answer = await http.post_json("/orders/batch", {"orders": chunk})
                    results = orjson.loads(answer)["results"] if status == 200 else [answer]
                    refused = [r for r in results if not isinstance(r, dict) or r["status"] != 201]
                latencies.append(time.monotonic() - begin)
                for problem in refused:
                    print(
                        f"  POST {chunk[0]['serialNumber']}…: {status} {problem!r}", file=sys.stderr
                    )

    in_flight = POST_CONCURRENCY if batch == 1 else BATCH_CONCURRENCY
    await asyncio.gather(*(worker() for _ in range(in_flight)))
    return latencies


# --- the table ------------------------------------------------------------------------------------


def _per_process(figures: dict[str, float], fmt: str) -> str:
    return " ".join(f"{k}={format(v, fmt)}" for k, v in figures.items())


def table(results: list[Result], vehicles: int, *, idle: bool) -> str:
    rows: list[tuple[str, list[str]]] = []

    def row(label: str, value: Callable[[Result], str]) -> None:
        rows.append((label, [value(r) for r in results]))

    row("vehicles available after (s)", lambda r: f"{r.available_s:.2f}")
    row("CPU-s during start-up", lambda r: _per_process(r.cpu_start, ".1f"))
    if idle:
        row("idle CPU % (stack)", lambda r: f"{stack_total(r.idle_cpu_pct):.1f}")
        row("idle CPU % per process", lambda r: _per_process(r.idle_cpu_pct, ".1f"))
    else:
        row("completion (s)", lambda r: f"{r.completion_s:.2f}")
        row("completion / ideal", lambda r: f"{r.completion_s / IDEAL_S:.2f}x")
        row("CPU-s drive (stack)", lambda r: f"{stack_total(r.cpu_drive):.2f}")
        row("CPU-s drive per process", lambda r: _per_process(r.cpu_drive, ".2f"))
        row("of it while sending orders", lambda r: _per_process(r.cpu_sending, ".2f"))
        row("finished / vehicles", lambda r: f"{r.observed.get('finished')}/{vehicles}")
        row("state messages", lambda r: str(r.observed.get("states")))
        row("lost states", lambda r: str(r.observed.get("lost_states")))
        row(
            "order->accepting state p50/p99 ms",
            lambda r: (
                f"{1000 * observed_figure(r.observed, 'accept_p50_s'):.0f}/"
                f"{1000 * observed_figure(r.observed, 'accept_p99_s'):.0f}"
            ),
        )
        row(
            "order->done state min/p50/max s",
            lambda r: "/".join(
                f"{observed_figure(r.observed, key):.2f}"
                for key in ("drive_min_s", "drive_p50_s", "drive_max_s")
            ),
        )
        row(
            "order messages / resends",
            lambda r: f"{r.observed.get('order_messages')}/{r.observed.get('resends')}",
        )
        row("order call p99 ms", lambda r: f"{1000 * percentile(r.call_s, 0.99):.0f}")
        row("all orders sent within (s)", lambda r: f"{r.orders_sent_s:.2f}")
        row("HTTP client CPU-s (benchmark)", lambda r: f"{r.client_cpu_s:.2f}")
    row("peak RSS MiB", lambda r: _per_process(r.rss_mib, ".0f"))
    width = max(len(label) for label, _ in rows)
    columns = [max(len(r.name), *(len(v[i]) for _, v in rows)) for i, r in enumerate(results)]
    lines = [
        " | ".join([" " * width, *(r.name.ljust(c) for r, c in zip(results, columns, strict=True))])
    ]
    for label, values in rows:
        lines.append(
            " | ".join(
                [label.ljust(width), *(v.ljust(c) for v, c in zip(values, columns, strict=True))]
            )
        )
    return "\n".join(lines)


async def run(args: argparse.Namespace) -> None:
    idle_s = args.idle_seconds if args.idle else None
    mode = f"idle {idle_s:.0f} s" if idle_s is not None else f"ideal {IDEAL_S:.0f} s"
    pairs: list[tuple[Result, Result]] = []
    for number in range(1, args.rounds + 1):
        # Alternate which stack goes first, so that neither always meets the machine's later
        # minutes (its speed moves between them).
        peer, ours = await run_round(args, idle_s, number)
        results = peer + ours
        heading = f" (round {number} of {args.rounds})" if args.rounds > 1 else ""
        print(f"\nN = {args.vehicles} ({mode}, CPU-s of the stack without Mosquitto){heading}")
        print(table(results, args.vehicles, idle=args.idle))
        if args.json:
            print(json.dumps([r.__dict__ for r in results], default=str))
        if len(peer) == 1 and args.batch == [1]:  # issue 12's pair: orders one by one
            pairs.append((peer[0], ours[0]))
    if len(pairs) > 1 and idle_s is None:
        print(summary(pairs, IDEAL_S))


async def run_round(
    args: argparse.Namespace, idle_s: float | None, number: int
) -> tuple[list[Result], list[Result]]:
    """Round ``number``: one run of each stack asked for, the peer first in odd rounds and last
    in even ones. Returns the peer's results (none or one) and ours (one per ``--batch``)."""
    peer_first = number % 2 == 1
    peer: list[Result] = []
    ours: list[Result] = []
    with tempfile.TemporaryDirectory(prefix="fleet-bench-") as tmp:
        folder = Path(args.keep_logs or tmp)
        if args.keep_logs and args.rounds > 1:
            folder = folder / f"round-{number}"
        await asyncio.to_thread(folder.mkdir, parents=True, exist_ok=True)
        wants_peer = args.only in (None, "peer")
        if wants_peer and peer_first:
            peer.append(await run_peer(folder, args.vehicles, idle_s))
        runs = args.batch if args.only in (None, "ours") else []
        for batch in runs:  # each in a folder of its own: no run finds another's store
            own = folder / ("ours" if batch == 1 else f"ours-batch-{batch}")
            # A fresh store: never the one an earlier invocation left in --keep-logs.
            await asyncio.to_thread(shutil.rmtree, own, ignore_errors=True)
            await asyncio.to_thread(own.mkdir)
            result = await run_ours(
                own,
                args.vehicles,
                idle_s,
                traffic=args.traffic_control,
                master_args=args.master_arg,
                profile=args.profile,
                profile_rate=args.profile_rate,
                batch=batch,
            )
            ours.append(result)
        if wants_peer and not peer_first:
            peer.append(await run_peer(folder, args.vehicles, idle_s))
    return peer, ours


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    cli.add_argument("--vehicles", type=int, default=100, help="N (100, 1000, 5000)")
    cli.add_argument("--idle", action="store_true", help="no orders: CPU %% while connected")
    cli.add_argument("--idle-seconds", type=float, default=60.0)
    cli.add_argument("--only", choices=["ours", "peer"])
    cli.add_argument("--traffic-control", action="store_true", help="ours with traffic control")
    cli.add_argument(
        "--batch",
        type=int,
        nargs="+",
        default=[1],
        help="ours: orders per request (1: POST /orders; more: POST /orders/batch); one run each",
    )
    cli.add_argument("--master-arg", action="append", default=[], help="one more vda-master flag")
    cli.add_argument("--keep-logs", type=Path, help="keep the services' logs here")
    cli.add_argument(
        "--profile",
        type=Path,
        help="py-spy our processes into this folder: <process>-start.txt until all are "
        "available, -send.txt while the orders are sent, -finish.txt the rest of the drive",
    )
    cli.add_argument(
        "--profile-rate", type=int, default=50, help="py-spy samples per second (--profile)"
    )
    cli.add_argument("--json", action="store_true", help="also print the raw figures")
    cli.add_argument(
        "--rounds",
        type=int,
        default=1,
        help="run both stacks this many times, alternating which goes first; with more than "
        "one, a summary: median [min-max] and issue 12's targets met per round",
    )
    cli.add_argument("--observe", type=int, help=argparse.SUPPRESS)
    args = cli.parse_args()
    if args.rounds < 1:
        cli.error("--rounds must be at least 1")
    if args.observe:
        asyncio.run(observe(args.observe, args.vehicles))
        return 0
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    wanted = min(hard, 4 * args.vehicles + 1024)
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, wanted), hard))
    asyncio.run(run(args))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
