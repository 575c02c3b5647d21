"""``python -m vda_demo`` / ``vda-demo``: the whole stack on one machine, completing orders."""

from __future__ import annotations

import argparse
import asyncio
import signal
from pathlib import Path

from vda5050.logs import configure_logging
from vda_demo.runner import DemoOptions, run_demo


def parse_args(argv: list[str] | None = None) -> DemoOptions:
    parser = argparse.ArgumentParser(
        prog="vda-demo",
        description="Start an MQTT broker, master control and the robots robot_0 ... robot_3 "
        "on the warehouse, dispatch four crossing pick-and-drop transports, show live progress "
        "(waits in traffic included) and the minimum separation.",
    )
    parser.add_argument(
        "--broker-host",
        default="127.0.0.1",
        help="address of the embedded broker (default 127.0.0.1)",
    )
    parser.add_argument(
        "--broker-port",
        type=int,
        default=0,
        help="port of the embedded broker (default: a free port)",
    )
    parser.add_argument(
        "--broker-url",
        help="use this broker (e.g. a Mosquitto) instead of "
        "starting one: mqtt://[user:password@]host:port",
    )
    parser.add_argument(
        "--api-port", type=int, default=8050, help="port of the master's HTTP API (default 8050)"
    )
    parser.add_argument(
        "--time-lapse",
        type=float,
        default=3.0,
        help="simulated time runs this many times faster (default 3)",
    )
    parser.add_argument(
        "--forever", action="store_true", help="keep dispatching missions until Ctrl-C"
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=55.0,
        help="give up when the missions take longer (seconds, default 55)",
    )
    parser.add_argument(
        "--config-dir",
        type=Path,
        default=Path("config"),
        help="folder with master.yaml, robot_*.yaml and graphs/ (default config)",
    )
    args = parser.parse_args(argv)
    return DemoOptions(
        broker_host=args.broker_host,
        broker_port=args.broker_port,
        broker_url=args.broker_url,
        api_port=args.api_port,
        time_lapse=args.time_lapse,
        forever=args.forever,
        timeout_s=args.timeout,
        config_dir=args.config_dir,
    )


async def _main(options: DemoOptions) -> int:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    return await run_demo(options, stop)


def main(argv: list[str] | None = None) -> int:
    options = parse_args(argv)
    configure_logging(json=False, level="WARNING")
    return asyncio.run(_main(options))


if __name__ == "__main__":
    raise SystemExit(main())
