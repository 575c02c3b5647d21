"""Vehicle benchmark: N simulated vehicles in one process, driving orders (issue 3 item 9).

Starts Mosquitto on a free port (or uses ``--broker-url``), runs ``VehicleService`` with N
vehicles in a fresh process per N, sends every vehicle a 20-node order, and measures over a window
while they drive: CPU % of the vehicle process, RSS per vehicle, and how late ticks and state
messages are (state lateness = from the tick that raised the event to the moment the state is
built and stamped for sending). Target: 1000 vehicles, lateness p99 < 100 ms.

Run: python benchmarks/vehicles.py [--counts 100 500 1000] [--seconds 30]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import resource
import shutil
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

import aiomqtt  # noqa: TID251 - the order sender stands in for master control

from vda5050.codec import encode
from vda5050.logs import configure_logging
from vda5050.testing import make_order
from vda_vehicle.config import VehicleSettings
from vda_vehicle.service import VehicleService

MOSQUITTO = shutil.which("mosquitto") or "/usr/sbin/mosquitto"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def percentile(samples: list[float], fraction: float) -> float:
    if not samples:
        return float("nan")
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(fraction * len(ordered)))]


def rss_mib() -> float:
    pages = int(Path("/proc/self/statm").read_text(encoding="ascii").split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


async def send_orders(url_port: int, serials: list[str], *, lockstep: bool) -> None:
    """One 20-node order per vehicle; vehicle i stands at (2i, 0) and drives along +y.

    Nodes are 10 m apart. Unless ``lockstep``, each vehicle's first edge is shortened by a random
    0-9 m so that, as in a real fleet, vehicles do not all pass their nodes in the same tick.
    """
    async with aiomqtt.Client("127.0.0.1", url_port) as client:
        for index, serial in enumerate(serials):
            phase = 0.0 if lockstep else random.uniform(0.0, 9.0)
            positions = [(2.0 * index, max(0.0, 10.0 * k - phase)) for k in range(20)]
            order = make_order(
                [f"n{k}" for k in range(20)],
                manufacturer="bench",
                serial_number=serial,
                positions=positions,
            )
            await client.publish(f"bench/v2/bench/{serial}/order", encode(order), qos=1)


async def measure(count: int, port: int, seconds: float, *, lockstep: bool) -> dict[str, float]:
    """Run ``count`` vehicles against the broker on ``port``; return the figures."""
    base_rss = rss_mib()
    settings = VehicleSettings(
        broker_url=f"mqtt://127.0.0.1:{port}",
        interface_name="bench",
        manufacturer="bench",
        serial_number="b",
        count=count,
        log_level="WARNING",
    )
    service = VehicleService(settings)
    async with asyncio.TaskGroup() as group:
        group.create_task(service.run(), name="bench.vehicles")
        async with asyncio.timeout(120):
            await service.wait_connected()
        serials = [r.agv.serial_number for r in service.runtimes]
        await send_orders(port, serials, lockstep=lockstep)
        await asyncio.sleep(3)  # let every order arrive and the vehicles start
        service.metrics.tick_lateness_s.clear()
        service.metrics.state_lateness_s.clear()
        sent_before = service.metrics.states_sent
        cpu_before, wall_before = time.process_time(), time.monotonic()
        await asyncio.sleep(seconds)
        cpu = (time.process_time() - cpu_before) / (time.monotonic() - wall_before)
        driving = sum(r.state.driving for r in service.runtimes)
        rss = rss_mib()
        ticks = list(service.metrics.tick_lateness_s)
        states = list(service.metrics.state_lateness_s)
        states_sent = service.metrics.states_sent - sent_before
        service.stop()
    return {
        "vehicles": count,
        "driving": driving,
        "cpu_pct": 100 * cpu,
        "rss_per_vehicle_kib": (rss - base_rss) * 1024 / count,
        "tick_p50_ms": 1000 * statistics.median(ticks),
        "tick_p99_ms": 1000 * percentile(ticks, 0.99),
        "state_p50_ms": 1000 * statistics.median(states),
        "state_p99_ms": 1000 * percentile(states, 0.99),
        "states_per_s": states_sent / seconds,
    }


def run_one(count: int, port: int, seconds: float, *, lockstep: bool) -> None:
    """Child process: measure and print one JSON line."""
    configure_logging(json=True, level="WARNING")
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, min(hard, 4 * count + 256)), hard))
    print(json.dumps(asyncio.run(measure(count, port, seconds, lockstep=lockstep))), flush=True)


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    cli.add_argument("--counts", type=int, nargs="+", default=[100, 500, 1000])
    cli.add_argument("--seconds", type=float, default=30.0)
    cli.add_argument(
        "--lockstep", action="store_true", help="all vehicles pass their nodes in the same tick"
    )
    cli.add_argument("--child", type=int, help=argparse.SUPPRESS)
    cli.add_argument("--port", type=int, help=argparse.SUPPRESS)
    args = cli.parse_args()
    if args.child:
        run_one(args.child, args.port, args.seconds, lockstep=args.lockstep)
        return 0
    port = free_port()
    broker = subprocess.Popen(  # noqa: S603 - a fixed local binary
        [MOSQUITTO, "-p", str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    time.sleep(0.3)
    header = f"{'vehicles':>8} {'driving':>7} {'CPU %':>6} {'RSS/veh KiB':>11} "
    header += f"{'tick p50/p99 ms':>16} {'state p50/p99 ms':>17} {'states/s':>8}"
    print(header)
    try:
        for count in args.counts:
            command = [sys.executable, __file__, "--child", str(count), "--port", str(port)]
            command += ["--seconds", str(args.seconds), *(["--lockstep"] if args.lockstep else [])]
            out = subprocess.run(command, capture_output=True, text=True, check=True)  # noqa: S603
            row = json.loads(out.stdout.strip().splitlines()[-1])
            print(
                f"{row['vehicles']:>8} {row['driving']:>7} {row['cpu_pct']:>6.1f} "
                f"{row['rss_per_vehicle_kib']:>11.1f} "
                f"{row['tick_p50_ms']:>7.1f}/{row['tick_p99_ms']:<8.1f} "
                f"{row['state_p50_ms']:>8.1f}/{row['state_p99_ms']:<8.1f} "
                f"{row['states_per_s']:>8.0f}",
                flush=True,
            )
    finally:
        broker.terminate()
        broker.wait()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
