"""README command 1: the demo completes both missions and exits 0; a taken port is explained."""

from __future__ import annotations

import asyncio
import re
import socket
import subprocess
import sys

import pytest

from tests.mosquitto import free_port
from tests.system.stack import REPO, process_env

pytestmark = pytest.mark.integration


def run_demo(*args: str, timeout: float = 90) -> subprocess.CompletedProcess[str]:
    return subprocess.run(  # noqa: S603 - our interpreter, our module
        [sys.executable, "-m", "vda_demo", *args],
        cwd=REPO,
        env=process_env(),
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


async def test_demo_finishes_the_crossing_missions() -> None:
    """The demo starts broker, master and four robots on the warehouse, finishes their crossing
    transports (one order each: pick at one stop, drop at the next), exits 0 with the closest
    approach measured, and says where the live map is."""
    port = free_port()
    result = await asyncio.to_thread(run_demo, "--api-port", str(port), "--time-lapse", "8")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "mosquitto_sub -h 127.0.0.1 -p" in result.stdout
    assert f"open http://127.0.0.1:{port}/ to watch the fleet" in result.stdout
    assert "All orders finished" in result.stdout
    summary = result.stdout.split("All orders finished")[1]
    finished = summary.split("closest approach")[0]
    for robot in ("robot_0", "robot_1", "robot_2", "robot_3"):
        assert finished.count(robot) == 1, summary  # one order: pick, then drop
    closest = re.search(r"closest approach: ([0-9.]+) m", summary)
    assert closest is not None, summary
    assert float(closest.group(1)) >= 1.69


def test_demo_explains_a_taken_api_port() -> None:
    """With the API port in use the demo says which port and what to do, and exits 2."""
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        result = run_demo("--api-port", str(port), timeout=30)
    assert result.returncode == 2
    assert f"port {port} (master HTTP API) is already in use" in result.stderr
    assert "--api-port" in result.stderr
