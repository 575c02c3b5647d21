"""``vda-master`` / ``python -m vda_master`` (architecture §3.2).

Flags, ``VDA_<FLAG>`` environment variables and config-file keys are the same settings, with
precedence flag > environment > config file > default. SIGTERM and SIGINT stop the service
gracefully and the process exits 0; a bad configuration or graph exits 2 with one message.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import gc
import os
import signal
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Final

import structlog

from vda5050.cli import add_settings_flags
from vda5050.errors import ConfigError
from vda5050.logs import configure_logging
from vda_master.config import MasterConfig, load_master_config
from vda_master.runtime import MasterProcess

log = structlog.get_logger()
#: The collector's thresholds while master control runs (gc_tuned).
GC_THRESHOLDS: Final = (10_000, 50, 1_000)


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
    process = MasterProcess(config)
    with gc_tuned():
        await process.run(stop)


@contextlib.contextmanager
def gc_tuned() -> Iterator[None]:
    """Freeze what start-up created (imports, the graph, traffic control's conflict sets, the
    app) and collect the young generation every 10,000 allocations instead of 700: with 1000
    vehicles connecting at once the cyclic collector took 0.5 s of the master's 1.4 CPU-s,
    walking the same start-up objects again and again; 0.13 s so tuned. The previous settings
    come back after."""
    thresholds = gc.get_threshold()
    gc.collect()
    gc.freeze()
    gc.set_threshold(*GC_THRESHOLDS)
    try:
        yield
    finally:
        gc.set_threshold(*thresholds)
        gc.unfreeze()


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
