"""Where the start-up of a fleet goes (issue 12: all vehicles available <= 2 s after start).

The same set-up as ``benchmarks/fleet.py`` for our stack (one ``vda-master``, one
``vda-vehicle --count N``, VDA 2.0.0, traffic control off, a fresh Mosquitto), but only the
start-up, with a timeline: from starting the vehicles' process, when the observer (a plain MQTT
client in this process) saw the first and the last vehicle's ``connection`` ONLINE, ``state``
and ``factsheet``, and when ``GET /health`` (polled at 10 Hz, as fleet.py does) counted the
first and the last vehicle available, with each poll's answer time.

Run: .venv/bin/python benchmarks/startup.py [--vehicles 1000] [--runs 1] [--profile DIR]
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for tests.* and benchmarks.*

import aiomqtt  # noqa: TID251 - the observer is nobody's MQTT session, just a listener
import httpx
import orjson

from benchmarks.fleet import (
    AVAILABLE_POLL_S,
    INTERFACE,
    _wait_healthy,
    cpu_s,
    lanes_graph,
    vehicles_process,
)
from tests.mosquitto import free_port, run_mosquitto
from tests.system.stack import ServiceProcess, process_env


@dataclass
class Timeline:
    """Seconds after the vehicles' process started."""

    first: dict[str, float] = field(default_factory=dict)
    last: dict[str, float] = field(default_factory=dict)
    seen: dict[str, set[str]] = field(default_factory=dict)
    polls: list[tuple[float, float, int, int]] = field(default_factory=list)
    #: Messages per topic (connection counts ONLINE ones only), instant actions per type.
    counts: dict[str, int] = field(default_factory=dict)

    def note(self, kind: str, serial: str, t: float, vehicles: int) -> None:
        seen = self.seen.setdefault(kind, set())
        if serial in seen:
            return
        seen.add(serial)
        self.first.setdefault(kind, t)
        if len(seen) == vehicles:
            self.last[kind] = t


async def _observe(port: int, vehicles: int, start: list[float], timeline: Timeline) -> None:
    async with aiomqtt.Client("127.0.0.1", port) as client:
        for topic in ("connection", "state", "factsheet", "instantActions"):
            await client.subscribe(f"{INTERFACE}/+/+/+/{topic}")
        async for message in client.messages:
            if not start:
                continue
            levels = message.topic.value.split("/")
            kind = levels[-1]
            payload = message.payload if isinstance(message.payload, bytes) else b""
            if kind == "connection" and b'"ONLINE"' not in payload:
                continue
            if kind == "instantActions":
                for action in orjson.loads(payload).get("actions", []):
                    name = str(action.get("actionType"))
                    timeline.counts[name] = timeline.counts.get(name, 0) + 1
                continue
            timeline.counts[kind] = timeline.counts.get(kind, 0) + 1
            timeline.note(kind, levels[3], time.time() - start[0], vehicles)


async def _poll(http: httpx.AsyncClient, vehicles: int, start: float, timeline: Timeline) -> None:
    async with asyncio.timeout(30 + vehicles / 20):
        while True:
            sent = time.time()
            answer = (await http.get("/health")).json()
            took = time.time() - sent
            available = int(answer["availableVehicles"])
            timeline.polls.append((sent - start, took, int(answer["vehicles"]), available))
            if available >= vehicles:
                return
            await asyncio.sleep(AVAILABLE_POLL_S)


def _profile(pid: int, path: Path) -> subprocess.Popen[bytes]:
    spy = Path(sys.executable).parent / "py-spy"
    command = [str(spy), "record", "--pid", str(pid), "--rate", "50", "--nonblocking"]
    command += ["--format", "raw", "--output", str(path)]
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # noqa: S603


async def run_once(vehicles: int, profile: Path | None) -> str:
    with tempfile.TemporaryDirectory(prefix="startup-") as tmp:
        folder = Path(tmp)
        graph = folder / "lanes.json"
        lanes_graph(graph, vehicles)
        api_port = free_port()
        with run_mosquitto(folder / "broker") as broker:
            common = ["--broker-url", broker.address.url, "--interface-name", INTERFACE]
            common += ["--graph", str(graph), "--log-level", "WARNING"]
            master = ServiceProcess(
                "master",
                [
                    "vda_master",
                    *common,
                    *("--api-port", str(api_port), "--data-dir", str(folder / "data")),
                    *("--release-window-nodes", "0", "--no-traffic-control"),
                ],
                folder / "master.log",
                env=process_env(),
            ).start()
            fleet = vehicles_process(common, vehicles, folder)
            timeline = Timeline()
            start: list[float] = []
            spies: list[subprocess.Popen[bytes]] = []
            watcher = asyncio.create_task(_observe(broker.address.port, vehicles, start, timeline))
            try:
                async with httpx.AsyncClient(
                    base_url=f"http://127.0.0.1:{api_port}", timeout=30
                ) as http:
                    await _wait_healthy(http)
                    await asyncio.sleep(0.5)  # the observer subscribed
                    assert master.process is not None  # noqa: S101
                    cpu_master = cpu_s(master.process.pid)
                    start.append(time.time())
                    fleet.start()
                    assert fleet.process is not None  # noqa: S101
                    if profile is not None:
                        spies.append(_profile(master.process.pid, profile / "master-start.txt"))
                        spies.append(_profile(fleet.process.pid, profile / "vehicles-start.txt"))
                    await _poll(http, vehicles, start[0], timeline)
                    cpu = (
                        cpu_s(master.process.pid) - cpu_master,
                        cpu_s(fleet.process.pid),
                    )
            finally:
                for spy in spies:
                    spy.send_signal(signal.SIGINT)
                    spy.wait(30)
                watcher.cancel()
                await fleet.stop()
                await master.stop()
    return _report(timeline, cpu, vehicles)


def _report(timeline: Timeline, cpu: tuple[float, float], vehicles: int) -> str:
    lines = [f"N = {vehicles}"]
    lines.extend(
        f"  {kind:<10} first {timeline.first.get(kind, float('nan')):6.2f} s"
        f"  last {timeline.last.get(kind, float('nan')):6.2f} s"
        f"  ({len(timeline.seen.get(kind, ()))} seen)"
        for kind in ("connection", "state", "factsheet")
    )
    first_available = next((t for t, _, _, a in timeline.polls if a), float("nan"))
    end, took, _, _ = timeline.polls[-1]
    lines.append(f"  available  first {first_available:6.2f} s  last {end + took:6.2f} s")
    slowest = max(timeline.polls, key=lambda p: p[1])
    lines.append(
        f"  GET /health: {len(timeline.polls)} polls, slowest {1000 * slowest[1]:.0f} ms"
        f" at {slowest[0]:.2f} s ({slowest[2]} vehicles known)"
    )
    polls = " ".join(f"{t:.1f}:{k}/{a}:{1000 * d:.0f}ms" for t, d, k, a in timeline.polls)
    lines.append(f"  polls (t: known/available: answer time): {polls}")
    counts = ", ".join(f"{k} {v}" for k, v in sorted(timeline.counts.items()))
    lines.append(f"  messages until available: {counts}")
    lines.append(f"  CPU-s until available: master {cpu[0]:.2f}, vehicles {cpu[1]:.2f}")
    return "\n".join(lines)


def main() -> None:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("--vehicles", type=int, default=1000)
    cli.add_argument("--runs", type=int, default=1)
    cli.add_argument("--profile", type=Path, help="py-spy raw profiles of both processes here")
    args = cli.parse_args()
    if args.profile is not None:
        args.profile.mkdir(parents=True, exist_ok=True)
    for _ in range(args.runs):
        load = " ".join(Path("/proc/loadavg").read_text().split()[:3])
        print(f"load average before: {load}")
        print(asyncio.run(run_once(args.vehicles, args.profile)), flush=True)


if __name__ == "__main__":
    main()
