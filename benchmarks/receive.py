"""Receive-path benchmark: CPU per received message of one MqttSession (issue 12, the master).

One session (master control's one connection) subscribes to ``bench/#`` on a private Mosquitto
with a handler that only counts. A separate process (paho, so its CPU is not counted) publishes
``--messages`` QoS 0 messages of ``--size`` bytes over 1000 vehicle topics, either as fast as it
can (``--rate 0``: a burst, as the states after a burst of orders) or at ``--rate`` messages per
second (a fleet's steady state stream). Prints this process's CPU per message received: the cost
of paho's read, aiomqtt's queue and ``MqttSession``'s dispatch to the handler.

Run: .venv/bin/python benchmarks/receive.py [--messages 50000] [--size 600] [--rate 0]
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
from vda5050.mqtt import InboundMessage, MqttSession, MqttSettings

#: The publisher: paho in a child process, QoS 0, paced when a rate is given.
PUBLISHER = """
import sys, time
from paho.mqtt import client as mqtt
from paho.mqtt.enums import CallbackAPIVersion
host, port, count, size, rate = sys.argv[1], int(sys.argv[2]), *map(int, sys.argv[3:6])
client = mqtt.Client(CallbackAPIVersion.VERSION2)
client.connect(host, port)
client.loop_start()
payload = b"x" * size
began = time.monotonic()
for number in range(count):
    client.publish(f"bench/v2/acme/{number % 1000}/state", payload, qos=0)
    if rate and number % 100 == 99:
        ahead = began + (number + 1) / rate - time.monotonic()
        if ahead > 0:
            time.sleep(ahead)
while client.want_write():
    time.sleep(0.01)
client.loop_stop()
client.disconnect()
"""


async def measure(host: str, port: int, args: argparse.Namespace) -> str:
    session = MqttSession(
        MqttSettings(url=f"mqtt://{host}:{port}", client_id="receive-bench", keepalive_s=60)
    )
    received = 0
    done = asyncio.Event()

    async def count(_: InboundMessage) -> None:
        nonlocal received
        received += 1
        if received == args.messages:
            done.set()

    session.subscribe("bench/#", count)
    async with asyncio.TaskGroup() as group:
        group.create_task(session.run(), name="benchmark.session")
        async with asyncio.timeout(10):
            await session.wait_connected()
        cpu, began = time.process_time(), time.monotonic()
        publisher = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            PUBLISHER,
            *(host, str(port), str(args.messages), str(args.size), str(args.rate)),
        )
        try:
            async with asyncio.timeout(120):
                await done.wait()
        except TimeoutError:
            pass
        used, wall = time.process_time() - cpu, time.monotonic() - began
        await publisher.wait()
        await session.stop()
    return (
        f"{received} of {args.messages} messages of {args.size} B in {wall:.2f} s: "
        f"{used:.2f} CPU-s, {used / max(received, 1) * 1e6:.1f} µs per message"
    )


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    cli.add_argument("--messages", type=int, default=50_000)
    cli.add_argument("--size", type=int, default=600, help="payload bytes (a state: 500-1500)")
    cli.add_argument("--rate", type=int, default=0, help="messages/s; 0: as fast as possible")
    cli.add_argument("--runs", type=int, default=3)
    args = cli.parse_args()
    configure_logging(json=True, level="WARNING")
    with tempfile.TemporaryDirectory(prefix="receive-") as folder:
        for _ in range(args.runs):
            with run_mosquitto(Path(folder) / "broker") as broker:
                print(asyncio.run(measure(broker.address.host, broker.address.port, args)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
