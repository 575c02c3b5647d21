"""``vda-master`` / ``python -m vda_master`` (architecture §3.2).

Flags, ``VDA_<FLAG>`` environment variables and config-file keys are the same settings, with
precedence flag > environment > config file > default. SIGTERM and SIGINT stop the service
gracefully and the process exits 0; a bad configuration or graph exits 2 with one message.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys

import structlog

from vda5050.config import settings_from_command_line, settings_parser
from vda5050.errors import ConfigError
from vda5050.logs import configure_logging
from vda_master.config import MasterConfig
from vda_master.runtime import MasterProcess

log = structlog.get_logger()


def build_parser() -> argparse.ArgumentParser:
    """``--config`` plus one flag per setting (generated from :class:`MasterConfig`, so that
    every config key is a flag); unset flags stay None so lower layers can fill them."""
    return settings_parser("vda-master", "VDA 5050 master control", MasterConfig)


def load_config(argv: list[str] | None, environ: dict[str, str] | None = None) -> MasterConfig:
    """Parse flags and merge them with the environment and the config file."""
    return settings_from_command_line(build_parser(), MasterConfig, argv, environ)


async def serve(config: MasterConfig) -> None:
    """Run until SIGTERM or SIGINT."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    await MasterProcess(config).run(stop)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script."""
    try:
        config = load_config(argv)
        configure_logging(json=config.log_json, level=config.log_level)
        asyncio.run(serve(config))
    except ConfigError as exc:
        print(f"vda-master: {exc}", file=sys.stderr)  # noqa: T201 - before logging exists
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
