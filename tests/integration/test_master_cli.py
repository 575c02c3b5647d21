"""``python -m vda_master`` as a process: serves the API, exits 0 on SIGTERM (architecture §3.2)."""

from __future__ import annotations

import asyncio
import os
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import httpx
import pytest

from tests.mosquitto import free_port

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration
SRC = Path(__file__).resolve().parents[2] / "src"


async def _health(port: int) -> httpx.Response:
    async with asyncio.timeout(10), httpx.AsyncClient() as client:
        while True:
            try:
                return await client.get(f"http://127.0.0.1:{port}/health")
            except httpx.TransportError:
                await asyncio.sleep(0.05)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
async def test_process_serves_and_stops_gracefully(
    embedded_broker: BrokerAddress, unique_interface_name: str, sig: signal.Signals, tmp_path: Path
) -> None:
    """The service answers /health and exits 0 on SIGTERM and on SIGINT; its store is created
    in the data directory."""
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(SRC), "VDA_API_PORT": str(port)}
    env["VDA_DATA_DIR"] = str(tmp_path / "data")
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "vda_master", "--broker-url", embedded_broker.url,
        "--interface-name", unique_interface_name, env=env,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        response = await _health(port)
        assert response.json()["status"] == "ok"
        process.send_signal(sig)
        async with asyncio.timeout(10):
            _, stderr = await process.communicate()
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()
    assert process.returncode == 0, stderr.decode()
    assert b"master.stopped" in stderr
    assert (tmp_path / "data" / "master.sqlite3").is_file()


async def test_unreachable_store_exits_2_with_one_message(tmp_path: Path) -> None:
    """A database_url nobody answers on stops start-up with exit code 2, naming where it
    looked and never the password."""
    env = {**os.environ, "PYTHONPATH": str(SRC), "VDA_API_PORT": str(free_port())}
    env["VDA_DATABASE_URL"] = f"postgresql://vda:s3cret@127.0.0.1:{free_port()}/fleet"
    env["VDA_DATA_DIR"] = str(tmp_path)
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "vda_master", "--broker-url", "mqtt://127.0.0.1:1", env=env,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    async with asyncio.timeout(30):
        _, stderr = await process.communicate()
    assert process.returncode == 2, stderr.decode()
    message = stderr.decode()
    assert "cannot open the order store at 127.0.0.1:" in message
    assert "/fleet" in message
    assert "s3cret" not in message


async def test_bad_graph_exits_2_with_one_message(tmp_path: Path) -> None:
    """A graph file with an unknown edge endpoint stops start-up with exit code 2 and the id."""
    graph = tmp_path / "g.json"
    nodes = '"nodes": [{"nodeId": "a", "x": 0, "y": 0}]'
    edges = '"edges": [{"edgeId": "e", "startNodeId": "a", "endNodeId": "b"}]'
    graph.write_text(f'{{"mapId": "m", {nodes}, {edges}}}')
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "vda_master", "--graph", str(graph), env=env,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    async with asyncio.timeout(10):
        _, stderr = await process.communicate()
    assert process.returncode == 2
    assert "edge 'e' references unknown end node 'b'" in stderr.decode()
