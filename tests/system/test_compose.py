"""docker-compose.yml: valid for docker-compose, and its commands start a working stack.

No Docker engine runs here, so the second test takes every service of the default profile
(command, environment, ports) from the file and starts it as a local process, with the
container-network names and ports mapped to free loopback ports.
"""

from __future__ import annotations

import asyncio
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from tests.mosquitto import free_port
from tests.system.stack import REPO, ServiceProcess, process_env

COMPOSE = REPO / "docker-compose.yml"
pytestmark = pytest.mark.integration


def compose_services(profiles: set[str]) -> dict[str, dict[str, Any]]:
    """The services that run with ``profiles`` active (YAML merge keys resolved)."""
    document = yaml.safe_load(COMPOSE.read_text())
    return {
        name: service
        for name, service in document["services"].items()
        if not service.get("profiles") or profiles & set(service["profiles"])
    }


def default_profiles() -> set[str]:
    """COMPOSE_PROFILES from the .env file docker-compose reads."""
    for line in (REPO / ".env").read_text().splitlines():
        if line.startswith("COMPOSE_PROFILES="):
            return set(line.split("=", 1)[1].split(","))
    return set()


@pytest.mark.skipif(shutil.which("docker-compose") is None, reason="docker-compose not installed")
def test_docker_compose_accepts_the_file() -> None:
    """`docker-compose config` validates the file; each broker sits in its own profile."""
    result = subprocess.run(  # noqa: S603
        [shutil.which("docker-compose") or "docker-compose", "config"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env={**os.environ, "VDA_MQTT_PORT": "18830", "VDA_HTTP_PORT": "18050"},
    )
    assert result.returncode == 0, result.stderr
    services = yaml.safe_load(result.stdout)["services"]
    assert set(services) == {"broker", "mosquitto", "master", "robot_0", "robot_1"}
    assert services["broker"]["profiles"] == ["amqtt"]
    assert services["mosquitto"]["profiles"] == ["mosquitto"]
    assert all("profiles" not in services[name] for name in ("master", "robot_0", "robot_1"))
    # The host ports are configurable, so a local Mosquitto on 1883 does not clash (issue 8).
    assert "18830" in str(services["broker"]["ports"])
    assert "18050" in str(services["master"]["ports"])
    # The API needs a key (compose binds it to 0.0.0.0 inside the container).
    assert services["master"]["environment"]["VDA_API_OPERATOR_KEYS"]


def test_both_brokers_answer_to_the_same_network_alias() -> None:
    """The amqtt and the mosquitto profile expose their broker as `mqtt` on port 1883."""
    everything = compose_services({"amqtt", "mosquitto"})
    for name in ("broker", "mosquitto"):
        assert everything[name]["networks"] == {"default": {"aliases": ["mqtt"]}}
        assert everything[name]["ports"] == ["${VDA_MQTT_PORT:-1883}:1883"]
    for name in ("master", "robot_0", "robot_1"):
        env = everything[name]["environment"]
        assert env["VDA_BROKER_URL"] == "mqtt://mqtt:1883"


def interpolate(value: str) -> str:
    """docker-compose's ``${NAME:-default}`` with NAME unset: the default."""
    return re.sub(r"\$\{[A-Z_]+:-([^}]*)\}", r"\1", value)


def localize(value: str, broker_port: int, api_port: int) -> str:
    """Map container addresses to this machine: broker `mqtt:1883`, API 8050, 0.0.0.0."""
    return (
        interpolate(value)
        .replace("mqtt://mqtt:1883", f"mqtt://127.0.0.1:{broker_port}")
        .replace("0.0.0.0", "127.0.0.1")  # noqa: S104 - replaced, not bound
        .replace("1883", str(broker_port))
        .replace("8050", str(api_port))
    )


def local_process(
    name: str, service: dict[str, Any], logs: Path, ports: tuple[int, int]
) -> ServiceProcess:
    """The service's command and environment from the file, run locally by its console script."""
    command = [localize(str(part), *ports) for part in service["command"]]
    executable = Path(sys.executable).parent / command[0]
    assert executable.is_file(), f"console script {command[0]} is not installed"
    environment = {
        key: localize(str(value), *ports)
        for key, value in dict(service.get("environment") or {}).items()
    }
    return ServiceProcess(
        name,
        [str(executable), *command[1:]],
        logs / f"{name}.log",
        process_env(**environment),
        verbatim=True,
    )


async def test_compose_services_start_a_working_stack(tmp_path: Path) -> None:
    """The default profile's commands, variables and ports run the demo's reference order."""
    services = compose_services(default_profiles())
    assert set(services) == {"broker", "master", "robot_0", "robot_1"}
    assert services["master"]["ports"] == ["127.0.0.1:${VDA_HTTP_PORT:-8050}:8050"]
    key = interpolate(services["master"]["environment"]["VDA_API_OPERATOR_KEYS"])
    ports = (free_port(), free_port())
    started = []
    try:
        for name in ("broker", "master", "robot_0", "robot_1"):
            started.append(local_process(name, services[name], tmp_path, ports).start())  # noqa: PERF401 - stop what started if a later start fails
        api = f"http://127.0.0.1:{ports[1]}"
        headers = {"Authorization": f"Bearer {key}"}
        async with httpx.AsyncClient(timeout=5, headers=headers) as http, asyncio.timeout(40):
            while True:
                try:
                    vehicles = (await http.get(f"{api}/vehicles")).json()
                    if sum(bool(v["available"]) for v in vehicles) == 2:
                        break
                except httpx.TransportError:
                    pass
                await asyncio.sleep(0.2)
            answer = await http.post(
                f"{api}/orders",
                json={
                    "manufacturer": "vda-sim",
                    "serialNumber": "robot_0",
                    "route": ["17", "12", "11"],
                },
            )
            assert answer.status_code == 201, answer.text
            while (await http.get(f"{api}/orders/{answer.json()['orderId']}")).json()[
                "status"
            ] != "FINISHED":
                await asyncio.sleep(0.2)
    finally:
        for process in reversed(started):
            await process.stop()
    for process in started:
        assert process.process is not None
        assert process.process.returncode == 0, f"{process.name}:\n{process.log()[-2000:]}"
