"""README command 1: the demo completes both missions and exits 0; a taken port is explained."""

from __future__ import annotations

import asyncio
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


async def test_demo_finishes_both_missions() -> None:
    """The demo starts broker, master, robot_0 and robot_1, finishes their orders, exits 0."""
    port = free_port()
    result = await asyncio.to_thread(run_demo, "--api-port", str(port), "--time-lapse", "8")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "mosquitto_sub -h 127.0.0.1 -p" in result.stdout
    assert f"open http://127.0.0.1:{port}/ to watch the fleet" in result.stdout
    assert "All orders finished" in result.stdout
    summary = result.stdout.split("All orders finished")[1]
    assert summary.count("robot_0") == 1  # the reference route
    assert summary.count("robot_1") == 2  # pick, then drop


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
