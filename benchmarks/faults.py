"""Recovery times after faults, measured with real processes on a private Mosquitto (issue 14).

Scenarios (each with a fresh Mosquitto, master and robot_0 on the demo graph, time lapse 2):

- ``vehicle_kill``: SIGKILL of the vehicle mid-order → the master shows it unavailable.
- ``vehicle_restart``: SIGKILL and restart mid-order → the order FAILED, the vehicle available.
- ``broker_outage``: Mosquitto stopped for 5 s mid-order → back, the master holds a fresh state
  of the vehicle, and the order finishes.

Run: PYTHONPATH=. python benchmarks/faults.py [--runs 3]
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import statistics
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable
from pathlib import Path

import httpx

from tests.mosquitto import run_mosquitto
from tests.system.stack import Stack

ORDER = {"manufacturer": "vda-sim", "serialNumber": "robot_0", "destination": "3"}
Scenario = Callable[[Stack, httpx.AsyncClient], Awaitable[dict[str, float]]]


async def _running_order(stack: Stack, http: httpx.AsyncClient) -> str:
    await stack.wait_vehicle(http, "robot_0", lambda v: bool(v.get("available")), timeout=30)
    answer = await http.post(f"{stack.api}/orders", json=ORDER)
    order_id: str = answer.json()["orderId"]
    await stack.wait_order(http, order_id, "RUNNING")
    return order_id


async def vehicle_kill(stack: Stack, http: httpx.AsyncClient) -> dict[str, float]:
    await _running_order(stack, http)
    vehicle = stack.services[-1]
    started = time.monotonic()
    vehicle.signal(signal.SIGKILL)
    await stack.wait_vehicle(
        http, "robot_0", lambda v: v.get("connectionState") == "CONNECTIONBROKEN", timeout=60
    )
    return {"kill → CONNECTIONBROKEN": time.monotonic() - started}


async def vehicle_restart(stack: Stack, http: httpx.AsyncClient) -> dict[str, float]:
    order_id = await _running_order(stack, http)
    vehicle = stack.services[-1]
    vehicle.signal(signal.SIGKILL)
    await vehicle.wait()
    started = time.monotonic()
    stack.start_vehicle("robot_0", "--time-lapse", "2")
    await stack.wait_order(http, order_id, "FAILED", timeout=30)
    failed = time.monotonic() - started
    await stack.wait_vehicle(http, "robot_0", lambda v: bool(v.get("available")), timeout=30)
    return {"restart → order FAILED": failed, "restart → available": time.monotonic() - started}


async def broker_outage(stack: Stack, http: httpx.AsyncClient) -> dict[str, float]:
    order_id = await _running_order(stack, http)
    await asyncio.to_thread(stack.broker.stop)
    await asyncio.sleep(5.0)
    await asyncio.to_thread(stack.broker.start)
    started = time.monotonic()

    def fresh(view: dict[str, object]) -> bool:
        age = view.get("lastStateAgeS")
        return isinstance(age, float | int) and age < time.monotonic() - started

    await stack.wait_vehicle(http, "robot_0", fresh, timeout=60)
    resumed = time.monotonic() - started
    await stack.wait_order(http, order_id, "FINISHED", timeout=60)
    return {
        "broker back → fresh state": resumed,
        "broker back → FINISHED": time.monotonic() - started,
    }


SCENARIOS: dict[str, Scenario] = {
    "vehicle_kill": vehicle_kill,
    "vehicle_restart": vehicle_restart,
    "broker_outage": broker_outage,
}


async def run(name: str, scenario: Scenario, folder: Path) -> dict[str, float]:
    with run_mosquitto(folder / "mosquitto") as mosquitto:
        stack = Stack(mosquitto, f"faults-{name}", folder)
        stack.start_master("--log-level", "WARNING")
        stack.start_vehicle("robot_0", "--time-lapse", "2")
        try:
            async with httpx.AsyncClient(timeout=5) as http:
                return await scenario(stack, http)
        finally:
            await stack.stop_all()


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("--runs", type=int, default=3)
    cli.add_argument("--only", choices=sorted(SCENARIOS), nargs="*")
    args = cli.parse_args()
    chosen = {k: v for k, v in SCENARIOS.items() if not args.only or k in args.only}
    print(f"{'scenario':<18} {'measure':<28} {'median s':>9} {'max s':>7}")
    for name, scenario in chosen.items():
        samples: dict[str, list[float]] = {}
        for _ in range(args.runs):
            with tempfile.TemporaryDirectory() as folder:
                for key, value in asyncio.run(run(name, scenario, Path(folder))).items():
                    samples.setdefault(key, []).append(value)
        for key, values in samples.items():
            print(f"{name:<18} {key:<28} {statistics.median(values):>9.2f} {max(values):>7.2f}")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
