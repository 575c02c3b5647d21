"""``vda-inspect`` / ``python -m vda_inspect``: listen to the VDA 5050 traffic on a broker
and report what breaks the standard (the rules: :mod:`vda_inspect.rules`; docs/inspect.md).

For integrators testing a vehicle or a master control of any maker: point it at the broker,
run the vehicle (or the fleet) through its paces, stop it with Ctrl-C (or ``--duration-s``).
Each kind of finding is printed once as it first occurs; at the end a summary per vehicle, and
the whole report as JSON with ``--report FILE``. Exit status 0 without violations, 1 with
some, 2 for a bad configuration. It only subscribes: it publishes nothing.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sys
import time
from contextlib import suppress
from pathlib import Path
from typing import Annotated

from pydantic import ConfigDict, Field, field_validator

from vda5050.config import (
    BrokerConnectionConfig,
    settings_from_command_line,
    settings_parser,
)
from vda5050.errors import ConfigError
from vda5050.mqtt import InboundMessage, MqttSession
from vda_inspect.rules import Finding, Inspector, InspectSettings
from vda_inspect.severity import Severity

#: How often silent vehicles are looked for (R92).
TICK_S = 1.0


class InspectConfig(BrokerConnectionConfig):
    """Settings of ``vda-inspect`` (the broker keys as for the services)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    interface_names: list[str] = Field(
        default_factory=lambda: ["uagv", "vda5050"],
        description="first topic levels to listen under (2.x uagv, 3.x vda5050 by default)",
    )
    duration_s: Annotated[float, Field(ge=0)] = Field(
        default=0.0, description="stop after this many seconds (0: at Ctrl-C or SIGTERM)"
    )
    report: Path | None = Field(default=None, description="write the report as JSON here")
    answer_within_s: Annotated[float, Field(gt=0)] = Field(
        default=2.0,
        description="an order no state of its vehicle carries (or names in an error) within "
        "this long is a violation of R93",
    )
    check_qos: bool = Field(
        default=True,
        description="judge each message's QoS (R03-R05); off for brokers that raise the "
        "delivery QoS to the subscription's, as the embedded amqtt broker does",
    )

    @field_validator("interface_names", mode="before")
    @classmethod
    def _split_names(cls, value: object) -> object:
        """``--interface-names uagv,vda5050`` as well as a YAML/JSON list."""
        if isinstance(value, str) and not value.lstrip().startswith("["):
            return [part.strip() for part in value.split(",") if part.strip()]
        return value


def summary_lines(report: dict[str, object]) -> list[str]:
    """The end-of-run summary: messages per vehicle and each kind of finding with its count."""
    lines = [f"{report['messages']} messages, {report['violations']} violations"]
    vehicles = report["vehicles"]
    assert isinstance(vehicles, dict)  # noqa: S101 - Inspector.report's shape
    for vehicle, entry in vehicles.items():
        counts = ", ".join(f"{topic} {n}" for topic, n in entry["messages"].items())
        lines.append(f"{vehicle}: {counts}")
        lines.extend(
            f"  {f['severity']:<9} {f['rule']:<8} {f['topic']} ({f['side']}) x{f['count']}: "
            f"{f['first']}"
            for f in entry["findings"]
        )
    broken = report["unreadableTopics"]
    assert isinstance(broken, list)  # noqa: S101 - Inspector.report's shape
    lines.extend(f"  violation R01 x{b['count']}: {b['first']}" for b in broken)
    return lines


def finding_line(finding: Finding) -> str:
    return (
        f"{finding.severity.value:<9} {finding.rule:<8} {finding.vehicle} {finding.topic} "
        f"({finding.side}): {finding.text}"
    )


class Listener:
    """The MQTT side: every message to the inspector, its first finding of a kind printed."""

    def __init__(self, config: InspectConfig) -> None:
        self.config = config
        self.inspector = Inspector(
            InspectSettings(check_qos=config.check_qos, answer_within_s=config.answer_within_s)
        )
        self._shown: set[tuple[str, str, str, str, Severity]] = set()
        self._unjudged: set[str] = set()
        self.session = MqttSession(
            config.mqtt_settings(client_id=f"vda-inspect-{os.getpid()}"), name="inspect"
        )

    async def on_message(self, message: InboundMessage) -> None:
        """One message to the inspector; a message it cannot judge is reported once per topic
        and the listening goes on (house style: bad input never stops a service)."""
        try:
            found = self.inspector.observe(
                message.topic,
                message.payload,
                qos=message.qos,
                retain=message.retain,
                now=time.monotonic(),
            )
        except Exception as exc:  # noqa: BLE001 - one message must not end the inspection
            if message.topic not in self._unjudged:
                self._unjudged.add(message.topic)
                print(f"could not judge a message on {message.topic}: {exc!r}", flush=True)  # noqa: T201
            return
        self._show(found)

    def _show(self, found: list[Finding]) -> None:
        for finding in found:
            key = (finding.vehicle, finding.topic, finding.side, finding.rule, finding.severity)
            if key not in self._shown:
                self._shown.add(key)
                print(finding_line(finding), flush=True)  # noqa: T201 - the tool's output

    async def run(self, stop: asyncio.Event) -> dict[str, object]:
        for name in self.config.interface_names:
            self.session.subscribe(f"{name}/#", self.on_message, 1)
        async with asyncio.TaskGroup() as group:
            group.create_task(self.session.run(), name="inspect.mqtt")
            deadline = time.monotonic() + self.config.duration_s if self.config.duration_s else None
            while not stop.is_set() and (deadline is None or time.monotonic() < deadline):
                with suppress(TimeoutError):
                    async with asyncio.timeout(TICK_S):
                        await stop.wait()
                self._show(self.inspector.tick(time.monotonic()))
            await self.session.stop()
        return self.inspector.report()


def load_config(argv: list[str] | None, environ: dict[str, str] | None = None) -> InspectConfig:
    parser = settings_parser("vda-inspect", "check the VDA 5050 traffic on a broker", InspectConfig)
    return settings_from_command_line(parser, InspectConfig, argv, environ)


async def inspect(config: InspectConfig) -> dict[str, object]:
    """Listen until SIGINT/SIGTERM or the duration; the report."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    return await Listener(config).run(stop)


def main(argv: list[str] | None = None) -> int:
    try:
        config = load_config(argv)
    except ConfigError as exc:
        print(f"vda-inspect: {exc}", file=sys.stderr)  # noqa: T201 - before anything runs
        return 2
    print(  # noqa: T201 - the tool's output
        f"listening on {config.broker_url} under {', '.join(config.interface_names)}", flush=True
    )
    report = asyncio.run(inspect(config))
    print("\n".join(summary_lines(report)), flush=True)  # noqa: T201
    if config.report is not None:
        config.report.write_text(json.dumps(report, indent=2) + "\n")
    return 1 if report["violations"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
