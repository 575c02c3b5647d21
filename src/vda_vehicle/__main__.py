"""``vda-vehicle`` / ``python -m vda_vehicle``: run simulated VDA 5050 vehicles (architecture §3.2).

SIGTERM and SIGINT shut down gracefully: OFFLINE (retained) on every vehicle, then DISCONNECT,
exit 0.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import sys

import structlog

from vda5050.collector import tuned_collector
from vda5050.config import settings_from_command_line, settings_parser
from vda5050.errors import ConfigError
from vda5050.logs import configure_logging
from vda_vehicle.config import VehicleSettings, load_graph
from vda_vehicle.service import VehicleService

log = structlog.get_logger()


def parser() -> argparse.ArgumentParser:
    """``--config`` plus one flag per setting (generated from :class:`VehicleSettings`); each
    is also a config key and an environment variable VDA_<KEY>."""
    return settings_parser("vda-vehicle", __doc__.splitlines()[0], VehicleSettings)


def settings_from(argv: list[str] | None, environ: dict[str, str]) -> VehicleSettings:
    return settings_from_command_line(parser(), VehicleSettings, argv, environ)


async def serve(settings: VehicleSettings) -> None:
    """Run the service until SIGTERM or SIGINT."""
    graph = load_graph(settings.graph) if settings.graph is not None else None
    # The collector is tuned before the fleet is built (the service's tick loop keeps it so):
    # its one full collection then walks the imported modules only, not a thousand vehicles
    # as they connect (vda5050.collector).
    with tuned_collector():
        service = VehicleService(settings, graph)
        loop = asyncio.get_running_loop()
        for signum in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(signum, service.stop)
        await service.run()


def main(argv: list[str] | None = None) -> int:
    try:
        settings = settings_from(argv, dict(os.environ))
        configure_logging(level=settings.log_level)
        asyncio.run(serve(settings))
    except ConfigError as exc:
        print(f"vda-vehicle: {exc}", file=sys.stderr)  # noqa: T201 - before logging exists
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
