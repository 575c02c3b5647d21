"""``vda-master`` / ``python -m vda_master`` (architecture §3.2).

Flags, ``VDA_<FLAG>`` environment variables and config-file keys are the same settings, with
precedence flag > environment > config file > default. SIGTERM and SIGINT stop the service
gracefully and the process exits 0; a bad configuration or graph exits 2 with one message.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import sys
from pathlib import Path

import structlog

from vda5050.cli import add_settings_flags
from vda5050.errors import ConfigError
from vda5050.logs import configure_logging
from vda_master.config import MasterConfig, load_master_config
from vda_master.runtime import MasterProcess

log = structlog.get_logger()


def build_parser() -> argparse.ArgumentParser:
    """``--config`` plus one flag per setting (generated from :class:`MasterConfig`, so that
    every config key is a flag); unset flags stay None so lower layers can fill them."""
    parser = argparse.ArgumentParser(prog="vda-master", description="VDA 5050 master control")
    parser.add_argument("--config", type=Path, help="YAML config file (env VDA_CONFIG)")
    add_settings_flags(parser, MasterConfig)
    return parser


def load_config(argv: list[str] | None, environ: dict[str, str] | None = None) -> MasterConfig:
    """Parse flags and merge them with the environment and the config file."""
    args = vars(build_parser().parse_args(argv))
    env = dict(os.environ) if environ is None else environ
    config_path = args.pop("config") or (Path(env["VDA_CONFIG"]) if env.get("VDA_CONFIG") else None)
    return load_master_config(config_path, args, env)


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
