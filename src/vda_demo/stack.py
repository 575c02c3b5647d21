"""Starting and stopping the demo's processes: master control and one process per robot."""

from __future__ import annotations

import asyncio
import contextlib
import signal
import sys
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import structlog

from vda5050.net import bind_problem

log = structlog.get_logger()


class PortTakenError(Exception):
    """A port the demo needs is in use; the message says which and what to do."""


def check_port_free(host: str, port: int, what: str, flag: str) -> None:
    """Raise PortTakenError when ``host:port`` cannot be bound."""
    problem = bind_problem(host, port)
    if problem is not None:
        msg = (
            f"port {port} ({what}) is already in use on {host} ({problem}): stop the program "
            f"using it (e.g. an earlier demo), or pass {flag} with a free port"
        )
        raise PortTakenError(msg)


@dataclass
class Service:
    """A service process of the demo, its command and its log file."""

    name: str
    command: list[str]
    log_path: Path
    process: asyncio.subprocess.Process | None = None

    async def start(self) -> None:
        """Start the process in a session of its own: Ctrl-C at the terminal reaches only the
        demo, which then stops its services in order (robots go OFFLINE, the summary prints)."""
        with self.log_path.open("wb") as sink:
            self.process = await asyncio.create_subprocess_exec(
                *self.command,
                stdout=sink,
                stderr=sink,
                stdin=asyncio.subprocess.DEVNULL,
                start_new_session=True,
            )

    def exited(self) -> int | None:
        return None if self.process is None else self.process.returncode

    def log_tail(self, lines: int = 15) -> str:
        text = self.log_path.read_text(errors="replace") if self.log_path.exists() else ""
        return "\n".join(text.splitlines()[-lines:])

    async def stop(self, timeout_s: float = 8.0) -> int | None:
        """SIGTERM (graceful: a robot publishes OFFLINE first), then SIGKILL after a timeout."""
        process = self.process
        if process is None or process.returncode is not None:
            return None if process is None else process.returncode
        process.send_signal(signal.SIGTERM)
        try:
            async with asyncio.timeout(timeout_s):
                return await process.wait()
        except TimeoutError:
            log.warning("demo.process_killed", service=self.name, timeout_s=timeout_s)
            process.kill()
            return await process.wait()


def python_module(module: str, *args: str) -> list[str]:
    """The command running ``python -m module args`` with this interpreter."""
    return [sys.executable, "-m", module, *args]


@contextlib.asynccontextmanager
async def running(services: Sequence[Service]) -> AsyncIterator[Sequence[Service]]:
    """Start ``services`` in order; stop them in reverse order, also on errors and Ctrl-C."""
    started: list[Service] = []
    try:
        for service in services:
            await service.start()
            started.append(service)
        yield services
    finally:
        for service in reversed(started):
            await asyncio.shield(service.stop())


def first_exited(services: Sequence[Service]) -> Service | None:
    """A service whose process has ended, if any."""
    return next((s for s in services if s.exited() is not None), None)
