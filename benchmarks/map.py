"""Web map benchmark (issue 11): frame time of the live map with 1000 vehicles moving.

Generates a grid graph (4 m spacing, edges both ways), starts a private Mosquitto, the master and
one vehicle process with ``--count N`` on that graph (visualization at its default 1 Hz), sends
every vehicle to a random node through ``POST /orders`` (whole route released), then opens the
map in headless Debian chromium and measures over a window while they drive:

- frame time: requestAnimationFrame deltas (p50/p95/p99, and frames over 50 ms);
- latency: master receiving a vehicle's message → the change painted (p50/p95);
- the page's own script time per frame update (p50/p95/p99);
- CPU % of the master process over the window (context for issue 12).

Run: python benchmarks/map.py [--vehicles 1000] [--seconds 15] [--screenshot FILE]
     [--traffic-control] [--nodes-per-vehicle 1.2]
Needs mosquitto and chromium (apt-get install mosquitto chromium).
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import json
import math
import os
import random
import re
import resource
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import httpx
from playwright.async_api import async_playwright

REPO = Path(__file__).resolve().parents[1]
MOSQUITTO = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
#: Seconds each POST /orders of the dispatch took to be answered.
POST_SECONDS: list[float] = []
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def percentile(samples: list[float], fraction: float) -> float:
    if not samples:
        return float("nan")
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(fraction * len(ordered)))]


def grid_graph(columns: int, rows: int, spacing_m: float = 4.0) -> dict[str, object]:
    """A warehouse-like grid: node ``c,r`` at (c·spacing, r·spacing), neighbours joined both
    ways, a few stations for the legend."""
    nodes: list[dict[str, object]] = []
    edges: list[dict[str, object]] = []
    for row in range(rows):
        for column in range(columns):
            node: dict[str, object] = {
                "nodeId": f"{column},{row}",
                "x": column * spacing_m,
                "y": row * spacing_m,
            }
            if row == 0 and column % 10 == 0:
                node.update(stationType="charging", stationName=f"C{column // 10}")
            nodes.append(node)
            for d_column, d_row in ((1, 0), (0, 1)):
                if column + d_column < columns and row + d_row < rows:
                    a, b = f"{column},{row}", f"{column + d_column},{row + d_row}"
                    edges.append({"edgeId": f"{a}>{b}", "startNodeId": a, "endNodeId": b})
                    edges.append({"edgeId": f"{b}>{a}", "startNodeId": b, "endNodeId": a})
    return {"mapId": "bench", "nodes": nodes, "edges": edges}


def raise_file_limit(count: int) -> None:
    """Each vehicle holds its own MQTT connection: the processes need more than 1024 files."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, min(hard, 4 * count + 256)), hard))


@contextmanager
def process(command: list[str], log: Path) -> Iterator[subprocess.Popen[bytes]]:
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    with log.open("wb") as sink:
        child = subprocess.Popen(  # noqa: S603 - our interpreter and a local binary
            command, stdout=sink, stderr=sink, stdin=subprocess.DEVNULL, env=env, cwd=REPO
        )
    try:
        yield child
    finally:
        child.terminate()
        try:
            child.wait(15)
        except subprocess.TimeoutExpired:
            child.kill()


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text(encoding="ascii").rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def wait_available(api: httpx.Client, count: int, timeout_s: float) -> int:
    """Until ``count`` vehicles are available; returns how many were."""
    deadline = time.monotonic() + timeout_s
    available = 0
    while time.monotonic() < deadline:
        try:
            vehicles = api.get("/vehicles").json()
        except httpx.TransportError:
            vehicles = []
        available = sum(1 for v in vehicles if v.get("available"))
        if available >= count:
            break
        time.sleep(0.5)
    return available


def dispatch(api: httpx.Client, graph: dict[str, object]) -> str:
    """One order per available vehicle, to a random node; says how many were accepted, and
    why the others were refused (with traffic control, a vehicle sent out of another's way
    while the orders go out is busy: 409)."""
    node_ids = [str(n["nodeId"]) for n in graph["nodes"]]  # type: ignore[attr-defined]
    sent = 0
    refused: collections.Counter[str] = collections.Counter()
    for vehicle in api.get("/vehicles").json():
        if not vehicle["available"]:
            continue
        body = {
            "manufacturer": vehicle["manufacturer"],
            "serialNumber": vehicle["serialNumber"],
            "destination": random.choice(node_ids),
        }
        started = time.monotonic()
        answer = api.post("/orders", json=body)
        POST_SECONDS.append(time.monotonic() - started)
        if answer.status_code == 201:
            sent += 1
        else:
            why = re.sub(r"vehicle \S+", "vehicle …", str(answer.json().get("detail")))
            why = re.sub(r"'[^']*'", "…", why)  # names of nodes, orders
            refused[f"{answer.status_code} {why[:70]}"] += 1
        time.sleep(0.005)  # no burst of a thousand orders at once
    reasons = "; ".join(f"{count} x {why}" for why, count in refused.most_common(3))
    return f"{sent}" + (f"  (refused: {reasons})" if refused else "")


async def measure_page(url: str, seconds: float, screenshot: Path | None) -> dict[str, object]:
    async with async_playwright() as playwright:
        browser = await playwright.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        page = await browser.new_page(viewport={"width": 1600, "height": 1000})
        errors: list[str] = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        await page.goto(url)
        await page.wait_for_function("() => window.vdaMap && window.vdaMap.ready")
        await asyncio.sleep(3)  # let the first batches settle
        await page.evaluate("window.vdaMap.probe.latencies.length = 0")
        await page.evaluate("window.vdaMap.probe.scriptMs.length = 0")
        await page.evaluate("window.vdaMap.probe.serverMs.length = 0")
        frames: list[float] = await page.evaluate(f"window.vdaMap.probe.frames({seconds * 1000})")
        latencies: list[float] = await page.evaluate("window.vdaMap.probe.latencies")
        script: list[float] = await page.evaluate("window.vdaMap.probe.scriptMs")
        served: list[float] = await page.evaluate("window.vdaMap.probe.serverMs")
        statuses: dict[str, int] = await page.evaluate(
            "(() => { const c = {}; for (const s of window.vdaMap.statuses.values())"
            " c[s] = (c[s] || 0) + 1; return c; })()"
        )
        markers = await page.locator("[data-vehicle]").count()
        if screenshot is not None:
            await page.screenshot(path=str(screenshot))
        await browser.close()
    return {
        "frames": frames,
        "latencies": latencies,
        "script": script,
        "served": served,
        "statuses": statuses,
        "markers": markers,
        "errors": errors,
    }


def report(result: dict[str, object], seconds: float, master_cpu_pct: float) -> None:
    frames: list[float] = result["frames"]  # type: ignore[assignment]
    latencies: list[float] = result["latencies"]  # type: ignore[assignment]
    print(f"vehicles on the map   {result['markers']}  statuses {result['statuses']}")
    print(
        f"frame time            p50 {statistics.median(frames):.1f} ms  "
        f"p95 {percentile(frames, 0.95):.1f} ms  p99 {percentile(frames, 0.99):.1f} ms  "
        f"max {max(frames):.1f} ms  ({len(frames) / seconds:.1f} frames/s, "
        f"{sum(f > 50 for f in frames)} frames > 50 ms)"
    )
    script: list[float] = result["script"]  # type: ignore[assignment]
    if script:
        print(
            f"page script per frame p50 {statistics.median(script):.2f} ms  "
            f"p95 {percentile(script, 0.95):.2f} ms  p99 {percentile(script, 0.99):.2f} ms"
        )
    if latencies:
        print(
            f"message to screen     p50 {statistics.median(latencies):.1f} ms  "
            f"p95 {percentile(latencies, 0.95):.1f} ms  ({len(latencies)} changes painted)"
        )
    served: list[float] = result["served"]  # type: ignore[assignment]
    if served:
        print(
            f"  of which master     p50 {statistics.median(served):.1f} ms  "
            f"p95 {percentile(served, 0.95):.1f} ms  (received -> sent on the stream)"
        )
    print(f"master CPU            {master_cpu_pct:.0f} % of one core")
    if result["errors"]:
        print(f"page errors           {result['errors']}")


def print_logs(work: Path) -> None:
    for log in ("master.log", "vehicles.log", "mosquitto.log"):
        tail = (work / log).read_text(encoding="utf-8", errors="replace")[-2000:]
        print(f"--- {log}\n{tail}")


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    cli.add_argument("--vehicles", type=int, default=1000)
    cli.add_argument("--seconds", type=float, default=15.0)
    cli.add_argument("--screenshot", type=Path, default=None)
    cli.add_argument(
        "--traffic-control", action="store_true", help="master control with traffic control"
    )
    cli.add_argument(
        "--nodes-per-vehicle",
        type=float,
        default=1.2,
        help="grid size (40 columns); the default packs the fleet (the map's worst case), 4 "
        "gives traffic control room",
    )
    args = cli.parse_args()
    raise_file_limit(args.vehicles)
    columns = 40
    rows = max(10, math.ceil(args.vehicles * args.nodes_per_vehicle / columns))
    graph = grid_graph(columns, rows)
    broker_port, api_port = free_port(), free_port()
    broker = f"mqtt://127.0.0.1:{broker_port}"
    with tempfile.TemporaryDirectory() as scratch, ExitStack() as stack:
        work = Path(scratch)
        graph_file = work / "grid.json"
        graph_file.write_text(json.dumps(graph), encoding="utf-8")
        (work / "mosquitto.conf").write_text(
            f"listener {broker_port} 127.0.0.1\nallow_anonymous true\nmax_queued_messages 10000\n",
            encoding="utf-8",
        )
        stack.enter_context(
            process([MOSQUITTO, "-c", str(work / "mosquitto.conf")], work / "mosquitto.log")
        )
        time.sleep(0.5)
        common = ["--broker-url", broker, "--interface-name", "bench", "--graph", str(graph_file)]
        common += ["--log-level", "WARNING"]
        # Whole routes released at once, a patient resend: the vehicles keep driving even when a
        # 2-core machine running all of this confirms orders late (this measures the map).
        master_args = ["-m", "vda_master", *common, "--api-port", str(api_port)]
        master_args += ["--data-dir", str(work / "master-data")]
        master_args += ["--release-window-nodes", "0", "--confirm-timeout-s", "5"]
        # The map's cost is measured, not traffic control's (with it on, a thousand orders to
        # random nodes of the grid outlast the request timeout: docs/web.md, *Measurements*).
        master_args += ["--traffic-control" if args.traffic_control else "--no-traffic-control"]
        master = stack.enter_context(process([sys.executable, *master_args], work / "master.log"))
        fleet_args = ["-m", "vda_vehicle", *common, "--count", str(args.vehicles)]
        fleet_args += ["--manufacturer", "bench", "--serial-number", "b"]
        stack.enter_context(process([sys.executable, *fleet_args], work / "vehicles.log"))
        with httpx.Client(base_url=f"http://127.0.0.1:{api_port}", timeout=10) as api:
            print(f"starting {args.vehicles} vehicles on a {columns}×{rows} grid …", flush=True)
            available = wait_available(api, args.vehicles, timeout_s=180)
            if available < args.vehicles:
                print_logs(work)
                print(f"only {available} of {args.vehicles} vehicles became available")
                return 1
            try:
                print(f"orders accepted        {dispatch(api, graph)}", flush=True)
                posts = sorted(POST_SECONDS)
                print(
                    f"POST /orders           p50 {posts[len(posts) // 2] * 1000:.1f} ms"
                    f"  p99 {posts[int(len(posts) * 0.99)] * 1000:.1f} ms"
                    f"  max {posts[-1] * 1000:.1f} ms  (the first {POST_SECONDS[0] * 1000:.1f} ms)",
                    flush=True,
                )
            except httpx.TransportError as exc:
                print_logs(work)
                print(f"the master stopped answering: {exc}")
                return 1
        cpu_before, wall_before = cpu_seconds(master.pid), time.monotonic()
        result = asyncio.run(
            measure_page(f"http://127.0.0.1:{api_port}/", args.seconds, args.screenshot)
        )
        master_cpu = 100 * (cpu_seconds(master.pid) - cpu_before) / (time.monotonic() - wall_before)
        report(result, args.seconds, master_cpu)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
