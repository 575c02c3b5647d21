"""``vda-probe``: take master control's place for one vehicle and check how it handles orders
that a conforming master never sends (the steps: :mod:`vda_inspect.probes`; docs/inspect.md).

It waits for the vehicle's state (idle, AUTOMATIC, localized), runs each step (publish, then
judge the states, errors and factsheets that follow), prints a line per step and a summary,
writes ``--report FILE`` as JSON, and exits 0 when no step failed, 1 when one did, 2 when the
vehicle could not be probed. It publishes orders: no other master control may command the
vehicle meanwhile.
"""

from __future__ import annotations

import asyncio
import json
import os
import secrets
import sys
import time
from collections.abc import Callable
from contextlib import suppress
from pathlib import Path
from typing import Annotated, Literal

from pydantic import ConfigDict, Field

from vda5050.clock import SystemClock
from vda5050.codec import DecodeFailure, HeaderStamper, decode, encode
from vda5050.config import BrokerConnectionConfig, settings_from_command_line, settings_parser
from vda5050.errors import ConfigError, TopicError
from vda5050.models import Factsheet, InstantActions, Order, State, v3
from vda5050.models.factsheet import AgvKinematic
from vda5050.mqtt import InboundMessage, MqttSession
from vda5050.topics import AgvId, Topic, default_interface_name, parse_topic, topic_prefix
from vda_inspect.probe_judges import Outcome, Seen, Verdict, error_key
from vda_inspect.probes import (
    ProbePlan,
    Step,
    instant_action,
    start_of,
    timed_out,
    trigger_parameters,
    unsupported_field,
)
from vda_master.requests import with_legacy_key
from vda_master.wire3 import (
    factsheet_from_v3,
    instant_actions_to_v3,
    is_v3,
    order_to_v3,
    state_from_v3,
)


class ProbeConfig(BrokerConnectionConfig):
    """Settings of ``vda-probe`` (the broker keys as for the services)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    manufacturer: str = Field(description="the vehicle's manufacturer (topic level)")
    serial_number: str = Field(description="the vehicle's serialNumber (topic level)")
    vda_version: Literal["2.0.0", "2.1.0", "3.0.0"] = Field(
        default="2.0.0", description="the protocol version the vehicle speaks"
    )
    interface_name: str | None = Field(
        default=None, description="first topic level (default: uagv for 2.x, vda5050 for 3.x)"
    )
    wait_s: Annotated[float, Field(gt=0)] = Field(
        default=15.0, description="how long to wait for the vehicle's first state"
    )
    answer_within_s: Annotated[float, Field(gt=0)] = Field(
        default=2.0, description="how long a step waits for the vehicle's answer"
    )
    report: Path | None = Field(default=None, description="write the results as JSON here")
    legacy_instant_actions_key: bool = Field(
        default=True,
        description="to a 2.0.0 vehicle, also write the instantActions array under "
        "'instantActions' (what vda-5050-lib 1.4 reads), as master control does",
    )

    @property
    def agv(self) -> AgvId:
        return AgvId(self.manufacturer, self.serial_number)

    @property
    def major(self) -> int:
        return int(self.vda_version.split(".", 1)[0])

    @property
    def v3(self) -> bool:
        return is_v3(self.vda_version)


class Prober:
    """The MQTT side: the vehicle's states and factsheets in, the steps' messages out."""

    def __init__(self, config: ProbeConfig) -> None:
        self.config = config
        interface = config.interface_name or default_interface_name(config.major)
        self.prefix = topic_prefix(interface, config.major, config.agv)
        self.stamper = HeaderStamper(config.agv, config.vda_version, SystemClock())
        self.session = MqttSession(
            config.mqtt_settings(client_id=f"vda-probe-{os.getpid()}"), name="probe"
        )
        self.states: list[State] = []
        self.factsheets = 0
        #: The vehicle's factsheet in its 2.x reading (its protocol limits, R36).
        self.factsheet: Factsheet | None = None
        self._arrived = asyncio.Event()
        self.undecodable: list[str] = []

    async def on_message(self, message: InboundMessage) -> None:
        try:
            address = parse_topic(message.topic)
        except TopicError:
            return
        if address.topic not in (Topic.STATE, Topic.FACTSHEET):
            return
        if address.topic is Topic.FACTSHEET and not message.retain:
            self.factsheets += 1  # R80: one came, valid or not (that is R14-R20)
        decoded = decode(address.topic, message.payload, address=address)
        if isinstance(decoded, DecodeFailure):
            self.undecodable.append(f"{address.topic.value}: {decoded.summary()}")
        elif isinstance(decoded, Factsheet):
            self.factsheet = decoded
        elif isinstance(decoded, v3.Factsheet):
            with suppress(ValueError, TypeError):
                self.factsheet = factsheet_from_v3(decoded)
        elif isinstance(decoded, v3.State):
            self.states.append(state_from_v3(decoded))
        elif isinstance(decoded, State):
            self.states.append(decoded)
        self._arrived.set()

    def send(self, message: Order | InstantActions) -> None:
        if isinstance(message, Order):
            topic = Topic.ORDER
            outgoing: Order | InstantActions | v3.Order | v3.InstantActions = (
                order_to_v3(message) if self.config.v3 else message
            )
        else:
            topic = Topic.INSTANT_ACTIONS
            if self.config.v3:
                outgoing = instant_actions_to_v3(message)
            elif self.config.legacy_instant_actions_key and self.config.vda_version == "2.0.0":
                outgoing = with_legacy_key(message)
            else:
                outgoing = message
        stamped = self.stamper.stamp(topic, outgoing)
        self.session.publish(f"{self.prefix}/{topic.value}", topic, encode(stamped))

    async def run_step(self, step: Step) -> Verdict:
        """Send the step's message and judge what follows until it decides or time is up."""
        before = (
            frozenset(error_key(e) for e in self.states[-1].errors) if self.states else frozenset()
        )
        first, factsheets = len(self.states), self.factsheets
        if step.message is not None:
            self.send(step.message)
        waited = max(step.within_s, self.config.answer_within_s)
        verdict: Verdict | None = None

        def decided() -> bool:
            nonlocal verdict
            seen = Seen(self.states[first:], before, self.factsheets - factsheets)
            verdict = step.judge(seen) if seen.states else None
            return verdict is not None

        await self._until(decided, waited)
        if verdict is not None:
            return verdict
        return timed_out(
            step, Seen(self.states[first:], before, self.factsheets - factsheets), waited
        )

    async def _until(self, done: Callable[[], bool], within_s: float) -> None:
        """Wait until ``done()`` (checked as messages come) or ``within_s`` passed."""
        deadline = time.monotonic() + within_s
        while not done() and time.monotonic() < deadline:
            self._arrived.clear()
            with suppress(TimeoutError):
                async with asyncio.timeout(deadline - time.monotonic()):
                    await self._arrived.wait()

    async def probe(self) -> dict[str, object]:
        """Wait for the vehicle, then run the steps; the report."""
        for topic in (Topic.STATE, Topic.FACTSHEET):
            self.session.subscribe(f"{self.prefix}/{topic.value}", self.on_message, 0)
        async with asyncio.TaskGroup() as group:
            group.create_task(self.session.run(), name="probe.mqtt")
            try:
                return await self._probe()
            finally:
                await self.session.stop()

    async def _probe(self) -> dict[str, object]:
        await self.session.wait_connected()
        self.send(_request("stateRequest"))  # a vehicle that publishes rarely answers at once
        await self._until(lambda: bool(self.states), self.config.wait_s)
        if not self.states:
            return _unprobed(f"no state of {self.config.agv} within {self.config.wait_s:g} s")
        if self.factsheet is None:  # none retained: ask (R36 reads its protocol limits)
            self.send(_request("factsheetRequest"))
            await self._until(lambda: self.factsheet is not None, self.config.answer_within_s)
        start = start_of(self.states[-1])
        if isinstance(start, str):
            return _unprobed(start)
        limits = None if self.factsheet is None else self.factsheet.protocol_limits
        plan = ProbePlan(
            start,
            secrets.token_hex(3),
            maps_reported=bool(self.states[-1].maps),
            max_order_nodes=None if limits is None else limits.max_array_lens.order_nodes,
            v3=self.config.v3,
            unsupported_field=(
                None
                if self.factsheet is None or self.config.v3
                else unsupported_field(self.factsheet)
            ),
            trigger_parameters=None
            if self.factsheet is None
            else trigger_parameters(self.factsheet),
            differential=self.factsheet is not None
            and self.factsheet.type_specification.agv_kinematic == AgvKinematic.DIFF,
        )
        results: list[dict[str, object]] = []
        skipped_from: str | None = None
        for step in plan.steps:
            if skipped_from is not None:
                results.append(_result(step, "skipped", f"after {skipped_from!r} failed"))
                continue
            verdict = await self.run_step(step)
            if verdict.outcome is Outcome.FAIL and self.states and self.states[-1].driving:
                self.send(_request("cancelOrder"))  # it moves where it should not: stop it
            results.append(_result(step, verdict.outcome.value, verdict.text))
            print(step_line(results[-1]), flush=True)  # noqa: T201 - the tool's output
            if verdict.outcome is Outcome.FAIL and step.essential:
                skipped_from = step.title
        failed = sum(r["outcome"] == Outcome.FAIL.value for r in results)
        return {
            "vehicle": str(self.config.agv),
            "failed": failed,
            "steps": results,
            "undecodable": sorted(set(self.undecodable)),
        }


def _request(action_type: str) -> InstantActions:
    return instant_action(action_type, f"vda-probe-{secrets.token_hex(3)}")


def _result(step: Step, outcome: str, text: str) -> dict[str, object]:
    return {"step": step.title, "rules": list(step.rules), "outcome": outcome, "text": text}


def _unprobed(reason: str) -> dict[str, object]:
    return {"failed": None, "unprobed": reason, "steps": []}


def step_line(result: dict[str, object]) -> str:
    rules = ", ".join(result["rules"])  # type: ignore[arg-type]
    return f"{str(result['outcome']).upper():<7} {rules:<16} {result['step']}: {result['text']}"


def load_config(argv: list[str] | None, environ: dict[str, str] | None = None) -> ProbeConfig:
    parser = settings_parser(
        "vda-probe", "check how one vehicle handles orders it should reject", ProbeConfig
    )
    return settings_from_command_line(parser, ProbeConfig, argv, environ)


def main(argv: list[str] | None = None) -> int:
    try:
        config = load_config(argv)
    except ConfigError as exc:
        print(f"vda-probe: {exc}", file=sys.stderr)  # noqa: T201 - before anything runs
        return 2
    print(f"probing {config.agv} on {config.broker_url}", flush=True)  # noqa: T201
    report = asyncio.run(Prober(config).probe())
    if config.report is not None:
        config.report.write_text(json.dumps(report, indent=2) + "\n")
    if report.get("unprobed"):
        print(f"not probed: {report['unprobed']}", flush=True)  # noqa: T201
        return 2
    steps = report["steps"]
    assert isinstance(steps, list)  # noqa: S101 - Prober.probe's shape
    for result in steps:
        if result["outcome"] == "skipped":
            print(step_line(result), flush=True)  # noqa: T201
    undecodable = report.get("undecodable") or []
    assert isinstance(undecodable, list)  # noqa: S101 - Prober.probe's shape
    for problem in undecodable:
        print(f"not a valid message (R14-R20): {problem}", flush=True)  # noqa: T201
    print(f"{len(steps)} steps, {report['failed']} failed", flush=True)  # noqa: T201
    return 1 if report["failed"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
