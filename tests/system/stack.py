"""Real processes for system tests: brokers, ``python -m vda_master``, ``python -m vda_vehicle``,
and a watcher that captures every message on the test's interface and checks it against schemas/.
"""

from __future__ import annotations

import asyncio
import functools
import json
import os
import signal
import subprocess
import sys
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import aiomqtt
import httpx
from jsonschema import Draft202012Validator, FormatChecker, ValidationError

from tests.integration.mqtt_helpers import client_for
from tests.mosquitto import free_port, wait_listening
from tests.spec_files import OFFICIAL_SCHEMAS, official_schema
from vda5050 import schemas
from vda5050.broker import BrokerAddress
from vda_inspect.rules import Inspector, InspectSettings
from vda_inspect.severity import Severity

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "config"
GRAPH = CONFIG / "graphs" / "demo.json"


def process_env(**extra: str) -> dict[str, str]:
    """The environment of a service process: this repository's sources first on the path."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("VDA_")}
    env["PYTHONPATH"] = str(REPO / "src")
    env.update(extra)
    return env


@dataclass
class ServiceProcess:
    """A service started as ``python -m <module> <args>``, logging to a file."""

    name: str
    args: list[str]
    log_path: Path
    env: dict[str, str] = field(default_factory=process_env)
    process: subprocess.Popen[bytes] | None = None
    #: Run ``args`` as a whole command line (e.g. a console script) instead of ``python -m``.
    verbatim: bool = False

    def start(self) -> ServiceProcess:
        command = self.args if self.verbatim else [sys.executable, "-m", *self.args]
        with self.log_path.open("ab") as sink:
            self.process = subprocess.Popen(  # noqa: S603 - our interpreter, our modules
                command,
                stdout=sink,
                stderr=sink,
                stdin=subprocess.DEVNULL,
                env=self.env,
                cwd=REPO,
            )
        return self

    @property
    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def signal(self, sig: signal.Signals) -> None:
        assert self.process is not None
        self.process.send_signal(sig)

    async def wait(self, timeout: float = 10.0) -> int:
        assert self.process is not None
        return await asyncio.to_thread(self.process.wait, timeout)

    async def stop(self) -> int | None:
        """SIGTERM, then SIGKILL if it does not end within 10 s."""
        if self.process is None or self.process.poll() is not None:
            return None if self.process is None else self.process.returncode
        self.process.terminate()
        try:
            return await self.wait(10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            return await self.wait(5)

    def log(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""


class Broker(Protocol):
    """A broker the test can stop and start again on the same address."""

    address: BrokerAddress

    def stop(self) -> None: ...
    def start(self) -> None: ...


@dataclass
class AmqttBroker:
    """The project's amqtt broker as its own process (``python -m vda5050.broker_service``)."""

    address: BrokerAddress
    log_path: Path
    service: ServiceProcess | None = None

    def start(self) -> None:
        self.service = ServiceProcess(
            "broker",
            [
                "vda5050.broker_service",
                "--host",
                self.address.host,
                "--port",
                str(self.address.port),
                "--log-level",
                "WARNING",
            ],
            self.log_path,
        ).start()
        wait_listening(self.address, self.service.process, self.log_path)

    def stop(self) -> None:
        if self.service is not None and self.service.process is not None:
            self.service.process.terminate()
            self.service.process.wait(10)


@dataclass
class Captured:
    """Every message seen on ``<interface>/#``, in arrival order."""

    messages: list[aiomqtt.Message] = field(default_factory=list)
    #: When each message arrived (the event loop's clock), in the same order.
    times: list[float] = field(default_factory=list)
    arrived: asyncio.Event = field(default_factory=asyncio.Event)

    def payloads(self, topic: str) -> list[dict[str, object]]:
        return [json.loads(m.payload) for m in self.messages if str(m.topic) == topic]

    async def wait_until(self, predicate: Callable[[], bool], timeout: float = 20.0) -> None:
        async with asyncio.timeout(timeout):
            while not predicate():
                self.arrived.clear()
                await self.arrived.wait()

    def inspect_violations(self) -> list[str]:
        """What ``vda-inspect`` finds against the standard in the captured traffic (amqtt
        raises the delivery QoS, so QoS is not judged)."""
        inspector = Inspector(InspectSettings(check_qos=False))
        found = []
        for message, at in zip(self.messages, self.times, strict=True):
            payload = message.payload if isinstance(message.payload, bytes) else b""
            found += inspector.observe(
                str(message.topic), payload, qos=message.qos, retain=message.retain, now=at
            )
        return [f"{f.rule}: {f.text}" for f in found if f.severity is Severity.VIOLATION]

    def schema_problems(self) -> list[str]:
        """Every captured message checked against schemas/<version>/<topic>.schema.json and,
        when the shared folder is present, against the official (patched) schema."""
        problems = []
        for message in self.messages:
            topic = str(message.topic).rsplit("/", 1)[-1]
            try:
                payload = json.loads(message.payload)
            except ValueError as exc:
                problems.append(f"{message.topic}: not JSON ({exc})")
                continue
            version = payload.get("version", "2.1.0")
            for name, validator in _validators(version, topic):
                problems.extend(
                    f"{message.topic} ({name}): {error.message} at {error.json_path}"
                    for error in validator.iter_errors(payload)
                    if not _official_defect(error)
                )
        return problems


def _validators(version: str, topic: str) -> list[tuple[str, Draft202012Validator]]:
    """The project's schema, and the official (patched) one when the shared folder is present."""
    found = [("schemas/", schemas.validator(f"{version}/{topic}.schema.json"))]
    if OFFICIAL_SCHEMAS.is_dir():
        found.append(("official", _official_validator(version, topic)))
    return found


def _official_defect(error: ValidationError) -> bool:
    """The official 2.1.0 factsheet schema puts the blockingTypes enum on the array itself, so no
    array of blocking types can pass it; the prose (§6.15) lists an array of NONE/SOFT/HARD."""
    return error.validator == "enum" and error.json_path.endswith(".blockingTypes")


@functools.cache
def _official_validator(version: str, topic: str) -> Draft202012Validator:
    return Draft202012Validator(official_schema(version, topic), format_checker=FormatChecker())


async def retained(address: BrokerAddress, topic: str, timeout: float = 3.0) -> dict[str, object]:
    """The retained message of ``topic`` as a fresh subscriber gets it; AssertionError if none."""
    async with client_for(address) as client:
        await client.subscribe(topic, qos=1)
        async with asyncio.timeout(timeout):
            message = await anext(aiter(client.messages))
    assert message.retain, f"{topic}: the message is not retained"
    return dict(json.loads(message.payload))


@asynccontextmanager
async def capturing(address: BrokerAddress, interface: str) -> AsyncIterator[Captured]:
    """Capture ``<interface>/#`` (QoS 1, so nothing is lost) until the block ends; reconnects
    when the broker restarts."""
    captured = Captured()

    async def collect() -> None:
        while True:
            try:
                async with client_for(address) as client:
                    await client.subscribe(f"{interface}/#", qos=1)
                    async for message in client.messages:
                        captured.messages.append(message)
                        captured.times.append(asyncio.get_running_loop().time())
                        captured.arrived.set()
            except aiomqtt.MqttError:
                await asyncio.sleep(0.2)

    async with asyncio.TaskGroup() as group:
        task = group.create_task(collect(), name="test.capture")
        try:
            yield captured
        finally:
            task.cancel()


@dataclass
class Stack:
    """Master control and vehicles of one test, on one interface name."""

    broker: Broker
    interface: str
    logs: Path
    api_port: int = field(default_factory=free_port)
    services: list[ServiceProcess] = field(default_factory=list)

    @property
    def api(self) -> str:
        return f"http://127.0.0.1:{self.api_port}"

    def start_master(
        self, *extra: str, url: str | None = None, env: dict[str, str] | None = None
    ) -> ServiceProcess:
        service = ServiceProcess(
            "master",
            [
                "vda_master",
                "--config",
                str(CONFIG / "master.yaml"),
                "--broker-url",
                url or self.broker.address.url,
                "--interface-name",
                self.interface,
                "--api-port",
                str(self.api_port),
                "--graph",
                str(GRAPH),
                "--data-dir",
                str(self.logs / "master-data"),
                *extra,
            ],
            self.logs / "master.log",
            process_env(**(env or {})),
        ).start()
        self.services.append(service)
        return service

    def start_vehicle(
        self, robot: str, *extra: str, url: str | None = None, env: dict[str, str] | None = None
    ) -> ServiceProcess:
        service = ServiceProcess(
            robot,
            [
                "vda_vehicle",
                "--config",
                str(CONFIG / f"{robot}.yaml"),
                "--broker-url",
                url or self.broker.address.url,
                "--interface-name",
                self.interface,
                "--graph",
                str(GRAPH),
                "--time-lapse",
                "4",
                *extra,
            ],
            self.logs / f"{robot}.log",
            process_env(**(env or {})),
        ).start()
        self.services.append(service)
        return service

    async def stop_all(self) -> None:
        for service in reversed(self.services):
            await service.stop()

    async def vehicle(self, http: httpx.AsyncClient, robot: str) -> dict[str, object]:
        answer = await http.get(f"{self.api}/vehicles/vda-sim/{robot}")
        return dict(answer.json()) if answer.status_code == 200 else {}

    async def wait_vehicle(
        self,
        http: httpx.AsyncClient,
        robot: str,
        predicate: Callable[[dict[str, object]], object],
        timeout: float = 20.0,
    ) -> dict[str, object]:
        """Poll the master's view of ``robot`` until ``predicate`` holds."""
        async with asyncio.timeout(timeout):
            while True:
                try:
                    vehicle = await self.vehicle(http, robot)
                except httpx.TransportError:
                    vehicle = {}
                if vehicle and predicate(vehicle):
                    return vehicle
                await asyncio.sleep(0.1)

    async def wait_order(
        self, http: httpx.AsyncClient, order_id: str, status: str, timeout: float = 30.0
    ) -> dict[str, object]:
        async with asyncio.timeout(timeout):
            while True:
                info = (await http.get(f"{self.api}/orders/{order_id}")).json()
                if info["status"] == status:
                    return dict(info)
                await asyncio.sleep(0.1)

    def logs_text(self) -> str:
        return "\n".join(f"--- {s.name}\n{s.log()[-3000:]}" for s in self.services)
