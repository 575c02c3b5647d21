"""Async wrappers around the Node.js peers in ``peer/``: start, read JSON lines, send commands.

A peer prints one JSON object per line (``{"event": ..., "t": ..., ...}``). :class:`Peer` keeps
them all in arrival order; ``wait_for`` waits, always with a time limit, until an event matches,
and fails at once when an event named in ``fail_on`` arrives first (so a test quotes the peer's
own error instead of timing out). On failure the message ends with the peer's last lines.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import signal
from collections.abc import AsyncIterator, Callable, Mapping
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

from tests.interop.node_lib import PEERS, NodeRuntime

Event = dict[str, Any]
Predicate = Callable[[Event], bool]
#: One JSON line may hold a whole state; asyncio's default limit (64 KiB) is too small for some.
LINE_LIMIT = 4 * 1024 * 1024
READY_TIMEOUT_S = 15.0


def matching(event: str, **fields: object) -> Predicate:
    """A predicate: the event is named ``event`` and has each of ``fields`` with that value."""

    def matches(candidate: Event) -> bool:
        return candidate.get("event") == event and all(
            candidate.get(key) == value for key, value in fields.items()
        )

    return matches


@dataclass
class Peer:
    """A running peer process and everything it printed."""

    name: str
    process: asyncio.subprocess.Process
    events: list[Event] = field(default_factory=list)
    stderr: list[str] = field(default_factory=list)
    changed: asyncio.Event = field(default_factory=asyncio.Event)

    def find(self, predicate: Predicate, since: int = 0) -> list[Event]:
        """Every event from index ``since`` on that satisfies ``predicate``."""
        return [e for e in self.events[since:] if predicate(e)]

    async def wait_for(
        self,
        predicate: Predicate,
        timeout: float = 10.0,
        *,
        since: int = 0,
        fail_on: Predicate | None = None,
        what: str = "",
        check: Callable[[], None] | None = None,
    ) -> Event:
        """The first event from index ``since`` on that satisfies ``predicate``.

        AssertionError when ``fail_on`` matches an earlier event, when the peer exits, or after
        ``timeout`` seconds. ``check`` runs every 0.2 s and may fail the wait early (e.g. when
        the process on the other side of the interface has exited).
        """
        try:
            async with asyncio.timeout(timeout):
                while True:
                    for event in self.events[since:]:
                        if predicate(event):
                            return event
                        if fail_on is not None and fail_on(event):
                            msg = f"{self.name}: while waiting for {what or 'an event'}: {event}"
                            raise AssertionError(msg + self.tail())
                    if self.process.returncode is not None:
                        code = self.process.returncode
                        msg = f"{self.name} exited ({code}) before {what or 'the event'}"
                        raise AssertionError(msg + self.tail())
                    if check is not None:
                        check()
                    self.changed.clear()
                    with contextlib.suppress(TimeoutError):
                        async with asyncio.timeout(0.2):
                            await self.changed.wait()
        except TimeoutError:
            msg = f"{self.name}: no {what or 'matching event'} within {timeout} s"
            raise AssertionError(msg + self.tail()) from None

    async def send(self, command: Mapping[str, object]) -> None:
        """Write one JSON command line to the peer's stdin."""
        assert self.process.stdin is not None
        self.process.stdin.write(json.dumps(command).encode() + b"\n")
        async with asyncio.timeout(5):
            await self.process.stdin.drain()

    def tail(self, lines: int = 25) -> str:
        """The last events (states shortened) and stderr lines, for failure messages."""
        shown = [_short(e) for e in self.events[-lines:]]
        text = "\n".join(shown + [f"stderr: {line}" for line in self.stderr[-10:]])
        return f"\n--- last lines of {self.name}:\n{text}"

    async def _read_stdout(self) -> None:
        assert self.process.stdout is not None
        async for raw in self.process.stdout:
            try:
                event = json.loads(raw)
            except ValueError:
                event = {"event": "unparsed", "line": raw.decode(errors="replace").rstrip()}
            self.events.append(event)
            self.changed.set()
        self.changed.set()

    async def _read_stderr(self) -> None:
        assert self.process.stderr is not None
        async for raw in self.process.stderr:
            self.stderr.append(raw.decode(errors="replace").rstrip())

    async def _watch_exit(self) -> None:
        await self.process.wait()
        self.changed.set()


def _short(event: Event) -> str:
    if event.get("event") == "state" and isinstance(event.get("state"), dict):
        state = event["state"]
        keys = ("orderId", "lastNodeId", "driving", "errors", "actionStates", "agvPosition")
        return json.dumps({"event": "state", **{k: state.get(k) for k in keys}})
    return json.dumps(event)[:600]


@asynccontextmanager
async def running_peer(
    runtime: NodeRuntime, script: str, config: Mapping[str, object], name: str
) -> AsyncIterator[Peer]:
    """Run ``node peer/<script> '<config>'`` until the block ends, then SIGTERM it (bounded)."""
    process = await asyncio.create_subprocess_exec(
        runtime.node,
        str(PEERS / script),
        json.dumps(config),
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=runtime.env(),
        cwd=PEERS,
        limit=LINE_LIMIT,
    )
    peer = Peer(name, process)
    try:
        async with asyncio.TaskGroup() as group:
            group.create_task(peer._read_stdout(), name=f"test.{name}.stdout")
            group.create_task(peer._read_stderr(), name=f"test.{name}.stderr")
            group.create_task(peer._watch_exit(), name=f"test.{name}.exit")
            try:
                yield peer
            finally:
                await _terminate(process)
    except BaseExceptionGroup as errors:
        # The test's own failure, wrapped by the TaskGroup: show it as it was raised.
        if len(errors.exceptions) == 1:
            raise errors.exceptions[0] from None
        raise


async def _terminate(process: asyncio.subprocess.Process) -> None:
    if process.stdin is not None:
        process.stdin.close()
    if process.returncode is None:
        with contextlib.suppress(ProcessLookupError):
            process.send_signal(signal.SIGTERM)
        try:
            async with asyncio.timeout(10):
                await process.wait()
        except TimeoutError:
            process.kill()
            async with asyncio.timeout(5):
                await process.wait()


# -- the two peers ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class StartPose:
    """Where a virtual AGV stands at start; theta in radians."""

    x: float
    y: float
    theta: float
    map_id: str
    last_node_id: str

    def wire(self) -> dict[str, object]:
        return {
            "x": self.x,
            "y": self.y,
            "theta": self.theta,
            "mapId": self.map_id,
            "lastNodeId": self.last_node_id,
        }


@asynccontextmanager
async def running_agvs(
    runtime: NodeRuntime,
    *,
    broker_url: str,
    interface_name: str,
    manufacturer: str,
    poses: Mapping[str, StartPose],
    **options: object,
) -> AsyncIterator[Peer]:
    """vda-5050-lib virtual AGVs (2.0.0), one per serial number in ``poses``, all ready.

    ``options``: timeLapse, tickRate, vehicleSpeed, stateIntervalS, visualizationIntervalS,
    deviationXyTolerance, initialBatteryCharge (%), fullBatteryChargeTime (hours from 0 to
    100 %) (see peer/agvs.js).
    """
    config = {
        "brokerUrl": broker_url,
        "interfaceName": interface_name,
        "manufacturer": manufacturer,
        "vdaVersion": "2.0.0",
        "agvs": [{"serialNumber": s, "position": p.wire()} for s, p in poses.items()],
        **options,
    }
    async with running_peer(runtime, "agvs.js", config, "vda-5050-lib AGVs") as peer:
        for serial in poses:
            await peer.wait_for(
                matching("ready", serialNumber=serial),
                READY_TIMEOUT_S,
                fail_on=matching("peer_error"),
                what=f"AGV {serial} ready",
            )
        yield peer


@dataclass
class LibMaster:
    """A vda-5050-lib MasterController (peer/master.js) and the commands it takes."""

    peer: Peer
    _ids: itertools.count[int] = field(default_factory=lambda: itertools.count(1))

    async def command(self, cmd: str, **fields: object) -> Event:
        """Send a command; the ``sent`` event (with the message as published) or AssertionError."""
        command_id = str(next(self._ids))
        await self.peer.send({"id": command_id, "cmd": cmd, **fields})
        return await self.peer.wait_for(
            matching("sent", id=command_id),
            5.0,
            fail_on=matching("command_failed", id=command_id),
            what=f"{cmd} command {command_id} sent",
        )

    async def order(self, agv: Mapping[str, str], order: Mapping[str, object]) -> Event:
        return await self.command("order", agv=dict(agv), order=dict(order))

    async def instant_actions(
        self, agv: Mapping[str, str], actions: list[dict[str, object]]
    ) -> Event:
        return await self.command("instantActions", agv=dict(agv), actions=actions)

    async def cancel(self, agv: Mapping[str, str], action_id: str) -> Event:
        return await self.command("cancel", agv=dict(agv), actionId=action_id)


@asynccontextmanager
async def running_lib_master(
    runtime: NodeRuntime, *, broker_url: str, interface_name: str
) -> AsyncIterator[LibMaster]:
    """A started vda-5050-lib MasterController (2.0.0) subscribed to every vehicle."""
    config = {"brokerUrl": broker_url, "interfaceName": interface_name, "vdaVersion": "2.0.0"}
    async with running_peer(runtime, "master.js", config, "vda-5050-lib master") as peer:
        await peer.wait_for(
            matching("ready"), READY_TIMEOUT_S, fail_on=matching("peer_error"), what="ready"
        )
        yield LibMaster(peer)
