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
    assert set(services) == {
        "broker", "mosquitto", "master", "master-postgres", "postgres", "robot_0", "robot_1"
    }  # fmt: skip
    assert services["broker"]["profiles"] == ["amqtt"]
    assert services["mosquitto"]["profiles"] == ["mosquitto"]
    assert all("profiles" not in services[name] for name in ("robot_0", "robot_1"))
    # Master control on SQLite (a volume for its file) or, in the postgres profile, on the
    # postgres service's database once that answers.
    assert services["master"]["profiles"] == ["sqlite"]
    assert services["master"]["environment"]["VDA_DATA_DIR"] == "/data"
    assert services["master"]["volumes"] == ["master-data:/data:rw"]
    on_postgres = services["master-postgres"]
    assert on_postgres["profiles"] == services["postgres"]["profiles"] == ["postgres"]
    assert on_postgres["environment"]["VDA_DATABASE_URL"].startswith("postgresql://vda:")
    assert "@postgres:5432/vda" in on_postgres["environment"]["VDA_DATABASE_URL"]
    assert on_postgres["depends_on"] == {"postgres": {"condition": "service_healthy"}}
    # The host ports are configurable, so a local Mosquitto on 1883 does not clash (issue 8).
    assert "18830" in str(services["broker"]["ports"])
    assert "18050" in str(services["master"]["ports"])
    # The API needs a key (compose binds it to 0.0.0.0 inside the container).
    assert services["master"]["environment"]["VDA_API_OPERATOR_KEYS"]


def test_both_brokers_answer_to_the_same_network_alias() -> None:
    """The amqtt and the mosquitto profile expose their broker as `mqtt` on port 1883."""
    everything = compose_services({"amqtt", "mosquitto", "sqlite", "postgres"})
    for name in ("broker", "mosquitto"):
        assert everything[name]["networks"] == {"default": {"aliases": ["mqtt"]}}
        assert everything[name]["ports"] == ["${VDA_MQTT_PORT:-1883}:1883"]
    for name in ("master", "master-postgres", "robot_0", "robot_1"):
        env = everything[name]["environment"]
        assert env["VDA_BROKER_URL"] == "mqtt://mqtt:1883"


def interpolate(value: str) -> str:
    """docker-compose's ``${NAME:-default}`` with NAME unset: the default."""
    return re.sub(r"\$\{[A-Z_]+:-([^}]*)\}", r"\1", value)


def localize(value: str, broker_port: int, api_port: int) -> str:
    """Map container addresses to this machine: broker `mqtt:1883`, API 8050, 0.0.0.0."""
    text = (
        interpolate(value)
        .replace("mqtt://mqtt:", "mqtt://127.0.0.1:")
        .replace("0.0.0.0", "127.0.0.1")  # noqa: S104 - replaced, not bound
    )
    # One pass over whole numbers: a free port such as 18838 must not be replaced again.
    ports = {"1883": str(broker_port), "8050": str(api_port)}
    return re.sub(r"(?<!\d)(1883|8050)(?!\d)", lambda match: ports[match[1]], text)


def test_localize_replaces_each_port_once() -> None:
    """A free port that contains the default port (18838 contains 1883) is not replaced again."""
    assert localize("mqtt://mqtt:1883", 18838, 18050) == "mqtt://127.0.0.1:18838"
    assert localize("--port 8050 --bind 0.0.0.0", 18838, 28050) == "--port 28050 --bind 127.0.0.1"
    assert localize("port 18830", 1, 2) == "port 18830"


def local_process(
    name: str, service: dict[str, Any], logs: Path, ports: tuple[int, int]
) -> ServiceProcess:
    """The service's command and environment from the file, run locally by its console script
    (the container's /data volume is a folder under ``logs``)."""
    command = [localize(str(part), *ports) for part in service["command"]]
    executable = Path(sys.executable).parent / command[0]
    assert executable.is_file(), f"console script {command[0]} is not installed"
    environment = {
        key: localize(str(value), *ports)
        for key, value in dict(service.get("environment") or {}).items()
    }
    if "VDA_DATA_DIR" in environment:
        environment["VDA_DATA_DIR"] = str(logs / "volume-data")
    return ServiceProcess(
        name,
        [str(executable), *command[1:]],
        logs / f"{name}.log",
        process_env(**environment),
        verbatim=True,
    )


async def test_compose_services_start_a_working_stack(tmp_path: Path) -> None:
    """The default profiles' commands, variables and ports run the demo's reference order;
    master control keeps it in its SQLite file on the data volume."""
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
    assert (tmp_path / "volume-data" / "master.sqlite3").is_file()
