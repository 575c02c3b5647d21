"""Publish-path benchmark: CPU per publication of many MqttSessions in one process (issue 12).

N sessions (one MQTT connection each, as ``vda-vehicle --count N`` has) against a private
Mosquitto; every tick each session publishes one QoS 0 message of ``--size`` bytes (a
visualization), as a vehicle process does at its visualization rate. Prints the process's CPU
time per publication, which is the cost of ``MqttSession.publish`` through the outbox, the drain
loop, aiomqtt and paho to the socket (docs/performance.md, "Direct socket writes").

Run: .venv/bin/python benchmarks/publish.py [--sessions 300] [--seconds 10] [--tick-s 0.1]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for tests.*

from tests.mosquitto import run_mosquitto
from vda5050.logs import configure_logging
from vda5050.mqtt import MqttSession, MqttSettings
from vda5050.topics import Topic


async def measure(url: str, args: argparse.Namespace) -> None:
    sessions = [
        MqttSession(MqttSettings(url=url, client_id=f"publish-{i}", keepalive_s=60))
        for i in range(args.sessions)
    ]
    payload = b"x" * args.size
    kind = Topic(args.kind)
    async with asyncio.TaskGroup() as group:
        for number, session in enumerate(sessions):
            group.create_task(session.run(), name=f"benchmark.session_{number}")
        async with asyncio.timeout(60):
            for session in sessions:
                await session.wait_connected()
        cpu, began, sent = time.process_time(), time.monotonic(), 0
        while time.monotonic() - began < args.seconds:
            for number, session in enumerate(sessions):
                topic = f"bench/v2/acme/{number}/{kind.value}"
                session.publish(topic, kind, payload)
                sent += 1
            await asyncio.sleep(args.tick_s)
        await asyncio.sleep(0.5)  # the last tick's publications leave
        used = time.process_time() - cpu
        print(
            f"{args.sessions} sessions, {sent} publications of {args.size} B: "
            f"{used:.2f} CPU-s, {used / sent * 1e6:.1f} µs per publication"
        )
        for session in sessions:
            await session.stop()


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    cli.add_argument("--sessions", type=int, default=300)
    cli.add_argument("--seconds", type=float, default=10.0)
    cli.add_argument("--tick-s", type=float, default=0.1)
    cli.add_argument("--size", type=int, default=600, help="payload bytes")
    cli.add_argument(
        "--kind",
        default="visualization",
        choices=["visualization", "state"],
        help="the topic kind published (a visualization goes to the socket at once, a state "
        "through the outbox and its drain loop)",
    )
    args = cli.parse_args()
    configure_logging(json=True, level="WARNING")
    with tempfile.TemporaryDirectory() as folder, run_mosquitto(Path(folder)) as broker:
        asyncio.run(measure(broker.address.url, args))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
