"""``vda-broker``: the embedded amqtt broker as a standalone service (docker-compose, demos).

Flags (each also an environment variable ``VDA_<FLAG>``): ``--host`` (default 127.0.0.1; use
0.0.0.0 in a container), ``--port`` (default 1883), ``--username``/``--password`` (default:
anonymous access). SIGTERM/SIGINT stop it cleanly with exit status 0.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import sys

import structlog

from vda5050.broker import EmbeddedBroker
from vda5050.logs import configure_logging

log = structlog.get_logger()


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    env = os.environ
    parser = argparse.ArgumentParser(prog="vda-broker", description=__doc__.splitlines()[0])
    parser.add_argument("--host", default=env.get("VDA_HOST", "127.0.0.1"))
    parser.add_argument("--port", type=int, default=int(env.get("VDA_PORT", "1883")))
    parser.add_argument("--username", default=env.get("VDA_USERNAME") or None)
    parser.add_argument("--password", default=env.get("VDA_PASSWORD") or None)
    parser.add_argument("--log-level", default=env.get("VDA_LOG_LEVEL", "INFO"))
    return parser.parse_args(argv)


async def serve(args: argparse.Namespace) -> int:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    broker = EmbeddedBroker(args.host, args.port, username=args.username, password=args.password)
    try:
        await broker.start()
    except OSError as exc:
        log.error(  # noqa: TRY400 - the reason is enough; a traceback would only add noise
            "broker.start_failed",
            host=args.host,
            port=args.port,
            error=str(exc),
            hint="the port is probably in use: stop that program or pass --port",
        )
        return 2
    try:
        await stop.wait()
    finally:
        await broker.stop()
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    configure_logging(json=not sys.stderr.isatty(), level=args.log_level)
    return asyncio.run(serve(args))


if __name__ == "__main__":
    raise SystemExit(main())
