"""Mosquitto with password authentication: right credentials work, wrong ones are retried."""

from __future__ import annotations

import asyncio
from pathlib import Path

import httpx
import pytest

from tests.mosquitto import run_mosquitto
from tests.system.stack import Stack

pytestmark = pytest.mark.mosquitto


async def test_credentials_on_a_password_protected_mosquitto(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """Right credentials (URL or VDA_USERNAME/VDA_PASSWORD) connect; wrong ones log a clear
    error and the service keeps retrying without crashing."""
    with run_mosquitto(tmp_path / "mosquitto", credentials=("fleet", "s3cret")) as broker:
        stack = Stack(broker, unique_interface_name, tmp_path)
        host, port = broker.address.host, broker.address.port
        try:
            stack.start_master(url=f"mqtt://fleet:s3cret@{host}:{port}")
            stack.start_vehicle("robot_0", env={"VDA_USERNAME": "fleet", "VDA_PASSWORD": "s3cret"})
            bad = stack.start_vehicle("robot_1", url=f"mqtt://fleet:wrong@{host}:{port}")
            async with httpx.AsyncClient(timeout=5) as http:
                await stack.wait_vehicle(http, "robot_0", lambda v: bool(v.get("available")))
                await asyncio.sleep(2.0)
                robot_1 = await stack.vehicle(http, "robot_1")
            assert robot_1.get("connectionState") is None
            assert bad.running, "a refused login must not end the service"
            assert "check username and password" in bad.log()
        finally:
            await stack.stop_all()
