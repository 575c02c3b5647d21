"""Master CPU per ``POST /orders`` with a large fleet known to it (issue 12, the HTTP burst).

The scenario of ``benchmarks/fleet.py`` (ours) without broker and without vehicle process, so
that only the master's own work per request is measured, in CPU time (less dependent on how
busy the shared machine is than latencies; still ±10% between runs on a loaded 2-core machine,
so compare medians of alternating runs):

- the lanes graph of ``fleet.py`` for N vehicles (3N nodes, 2N edges), traffic control off,
  ``release_window_nodes: 0``, the SQLite store in a temporary folder with its writer, as
  ``vda-master`` runs it;
- N simulated vehicles (``vda_vehicle``'s own runtimes, VDA 2.0.0, on nodes a0 … a(N-1)): their
  ONLINE, factsheet and first state are ingested by the master, which then holds them all as
  available;
- the burst: one ``POST /orders`` per vehicle with its serial number and its two-edge route,
  ``--concurrency`` (32) requests in flight, each as an ASGI call into the master's FastAPI app
  (no socket, no HTTP parsing: uvicorn's share is not counted); the published order messages go
  to a publisher that builds each payload and drops it (the MQTT session's share is not counted
  either). Every request must be answered 201 and every order published. ``--batch B``: the
  same orders through ``POST /orders/batch``, B to a request (every order must be created);
  the figures are then per order, not per request.

The cyclic garbage collector is tuned as ``vda-master`` tunes it (``vda5050.collector``;
``--default-gc``: CPython's thresholds; a tree without that module runs with CPython's, for
before/after runs with ``PYTHONPATH`` pointing at an older ``src``).

Printed: process CPU (all threads: the event loop and the store's SQLite thread) and main-thread
CPU per POST in µs, over the burst plus the write-ahead and queued writes it caused, of it the
time in the garbage collector (``gc.callbacks``), and the wall time per request for
orientation. ``--runs K`` repeats the whole scenario K times (fresh
master each time) and prints the median. ``--profile`` runs one more burst under cProfile and
prints the top functions (main thread only) by own time and by cumulative time; ``--spy FILE``
samples one more burst with py-spy (``.venv/bin/pip install py-spy``; collapsed stacks into
FILE, all threads, on-CPU samples only) and prints the shares of the samples by function, less
distorted than cProfile's. ``--gc-off`` keeps the collector out of the bursts, so that its
pauses are not charged to whatever frame allocated last.

Run:
    .venv/bin/python benchmarks/post_orders.py                    # N = 1000, 3 runs
    .venv/bin/python benchmarks/post_orders.py --vehicles 200 --runs 5 --profile
    .venv/bin/python benchmarks/post_orders.py --runs 0 --spy /tmp/post.txt   # py-spy only
    .venv/bin/python benchmarks/post_orders.py --log-level INFO   # with the INFO log lines
    .venv/bin/python benchmarks/post_orders.py --batch 100 --concurrency 4   # POST /orders/batch
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import cProfile
import gc
import io
import os
import pstats
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Self

import orjson
import structlog

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for benchmarks.*

from benchmarks.fleet import SPEED_MPS, lane_orders, lanes_graph
from vda5050.clock import SystemClock
from vda5050.logs import configure_logging
from vda5050.mqtt import Payload
from vda5050.topics import Topic
from vda_master.api import create_app
from vda_master.config import MasterConfig
from vda_master.graph import load_graph
from vda_master.journal import Journal
from vda_master.service import MasterService
from vda_master.store import StoreWriter, open_store
from vda_vehicle.config import VehicleSettings
from vda_vehicle.config import load_graph as load_vehicle_graph
from vda_vehicle.service import VehicleService

try:
    from vda5050.collector import tuned_collector
except ImportError:  # a tree before the collector was tuned (for before/after runs)
    tuned_collector = contextlib.nullcontext  # type: ignore[assignment]

INTERFACE = "fleet"


class DroppingPublisher:
    """Builds each payload as the MQTT session would, then drops it; counts order messages."""

    def __init__(self) -> None:
        self.orders = 0

    def publish(self, topic: str, kind: Topic, payload: bytes | Callable[[], bytes]) -> None:
        del topic
        if callable(payload):
            payload()
        if kind is Topic.ORDER:
            self.orders += 1


def vehicle_messages(graph: Path, vehicles: int) -> list[tuple[str, bytes]]:
    """What each simulated vehicle publishes on connecting: ONLINE, factsheet, state."""
    settings = VehicleSettings.model_validate(
        {
            "interface_name": INTERFACE,
            "graph": graph,
            "start_node": "a0",
            "count": vehicles,
            "serial_number": "ours",
            "manufacturer": "ours",
            "vda_version": "2.0.0",
            "speed_max_mps": SPEED_MPS,
        }
    )
    fleet = VehicleService(settings, load_vehicle_graph(graph))
    sent: list[tuple[str, bytes]] = []

    def record(topic: str, kind: Topic, payload: Payload) -> None:
        del kind
        sent.append((topic, payload() if callable(payload) else payload))

    for runtime in fleet.runtimes:
        runtime.attach(record)
        runtime.on_connected()
    return sent


@dataclass
class Answer:
    status: int = 0
    body: bytes = b""


async def call(app: Any, path: str, body: bytes) -> Answer:  # noqa: ANN401 - an ASGI app
    """One ``POST`` into the ASGI app, as uvicorn would hand it over (no socket)."""
    scope = {
        "type": "http",
        "asgi": {"version": "3.0", "spec_version": "2.3"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": path,
        "raw_path": path.encode(),
        "root_path": "",
        "query_string": b"",
        "headers": [
            (b"host", b"master"),
            (b"content-type", b"application/json"),
            (b"content-length", str(len(body)).encode()),
        ],
        "client": ("127.0.0.1", 50000),
        "server": ("127.0.0.1", 8050),
    }
    answer = Answer()
    delivered = False

    async def receive() -> dict[str, Any]:
        nonlocal delivered
        if delivered:
            await asyncio.Event().wait()  # nothing more: the client waits for the answer
        delivered = True
        return {"type": "http.request", "body": body, "more_body": False}

    async def send(message: dict[str, Any]) -> None:
        if message["type"] == "http.response.start":
            answer.status = message["status"]
        elif message["type"] == "http.response.body":
            answer.body += message.get("body", b"")

    await app(scope, receive, send)
    return answer


class GcTimer:
    """Time spent in the cyclic garbage collector while installed, per generation."""

    def __init__(self) -> None:
        self.seconds = [0.0, 0.0, 0.0]
        self.counts = [0, 0, 0]
        self._began = 0.0

    def __enter__(self) -> Self:
        gc.callbacks.append(self._callback)
        return self

    def __exit__(self, *exc: object) -> None:
        gc.callbacks.remove(self._callback)

    def _callback(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self._began = time.perf_counter()
        else:
            self.seconds[info["generation"]] += time.perf_counter() - self._began
            self.counts[info["generation"]] += 1


@dataclass
class Figures:
    posts: int  # orders, one per POST /orders or many per POST /orders/batch
    cpu_s: float
    main_cpu_s: float
    wall_s: float
    latencies_s: list[float]
    gc: GcTimer

    @property
    def cpu_us(self) -> float:
        return self.cpu_s / self.posts * 1e6

    @property
    def main_cpu_us(self) -> float:
        return self.main_cpu_s / self.posts * 1e6


@dataclass
class Sampling:
    """How one burst is watched: cProfile in-process, or py-spy into ``spy_file``."""

    profiler: cProfile.Profile | None = None
    spy_file: Path | None = None


async def burst(
    vehicles: int,
    concurrency: int,
    sampling: Sampling | None = None,
    *,
    gc_off: bool = False,
    default_gc: bool = False,
    batch: int = 1,
    short_post: bool = True,
) -> Figures:
    """A fresh master with ``vehicles`` available vehicles, then one POST per vehicle."""
    with tempfile.TemporaryDirectory(prefix="post-orders-") as tmp:
        folder = Path(tmp)
        graph_path = folder / "lanes.json"
        lanes_graph(graph_path, vehicles)
        config = MasterConfig.model_validate(
            {
                "interface_name": INTERFACE,
                "graph": graph_path,
                "release_window_nodes": 0,
                "traffic_control": False,
                "data_dir": folder / "master-data",
            }
        )
        publisher = DroppingPublisher()
        service = MasterService(config, load_graph(graph_path), publisher, SystemClock())
        # Tuned from start-up on, as the master's gc loop does (vda5050.collector).
        collector = contextlib.nullcontext() if default_gc else tuned_collector()
        async with open_store(config.database_url, config.data_dir) as store:
            writer = StoreWriter(store)
            flushing = asyncio.create_task(writer.flush_loop(), name="bench.store_flush_loop")
            service.attach_journal(Journal(store, writer, service.clock))
            try:
                with collector:
                    figures = await _start_and_burst(
                        service,
                        graph_path,
                        writer,
                        vehicles=vehicles,
                        concurrency=concurrency,
                        sampling=sampling,
                        gc_off=gc_off,
                        batch=batch,
                        short_post=short_post,
                    )
            finally:
                gc.enable()
                await writer.close()
                await flushing
        if publisher.orders != vehicles:
            msg = f"{publisher.orders} order messages published for {vehicles} POSTs"
            raise RuntimeError(msg)
        return figures


async def _start_and_burst(
    service: MasterService,
    graph_path: Path,
    writer: StoreWriter,
    *,
    vehicles: int,
    concurrency: int,
    sampling: Sampling | None,
    gc_off: bool,
    batch: int,
    short_post: bool,
) -> Figures:
    for topic, payload in vehicle_messages(graph_path, vehicles):
        service.ingest(topic, payload)
    now = service.clock.monotonic()
    unavailable = [v for v in service.fleet if service.availability(v, now)]
    if len(service.fleet) != vehicles or unavailable:
        msg = f"{len(unavailable)} of {len(service.fleet)} vehicles not available"
        raise RuntimeError(msg)
    await writer.flush(timeout_s=60)  # the registry writes of the start
    gc.collect()  # the simulated vehicles' garbage is not the master's
    if gc_off:
        gc.disable()
    app = create_app(service, short_post=short_post)
    groups = lane_orders(vehicles, batch)
    if batch == 1:
        requests = [("/orders", orjson.dumps(order), 1) for (order,) in groups]
    else:
        requests = [("/orders/batch", orjson.dumps({"orders": g}), len(g)) for g in groups]
    return await _timed_burst(app, requests, concurrency, writer, sampling)


async def _timed_burst(
    app: Any,  # noqa: ANN401 - an ASGI app
    requests: list[tuple[str, bytes, int]],
    concurrency: int,
    writer: StoreWriter,
    sampling: Sampling | None,
) -> Figures:
    """``requests`` (path, body, orders in it), ``concurrency`` in flight."""
    pending = list(reversed(requests))
    latencies: list[float] = []
    failures: list[str] = []

    async def worker() -> None:
        while pending:
            path, body, _ = pending.pop()
            begin = time.perf_counter()
            answer = await call(app, path, body)
            latencies.append(time.perf_counter() - begin)
            if answer.status not in (200, 201) or (
                path.endswith("/batch")
                and any(r["status"] != 201 for r in orjson.loads(answer.body)["results"])
            ):
                failures.append(f"{answer.status} {answer.body.decode()[:300]}")

    sampling = sampling or Sampling()
    spy = _start_spy(sampling.spy_file)
    if spy is not None:
        await asyncio.sleep(1.0)  # attached before the burst starts
    cpu, main_cpu, wall = time.process_time(), time.thread_time(), time.perf_counter()
    if sampling.profiler is not None:
        sampling.profiler.enable()
    with GcTimer() as collector:
        await asyncio.gather(*(worker() for _ in range(concurrency)))
        await writer.flush(timeout_s=60)  # what the burst queued for the store
    if sampling.profiler is not None:
        sampling.profiler.disable()
    if spy is not None:
        spy.send_signal(signal.SIGINT)
        await asyncio.to_thread(spy.wait, 30)
    figures = Figures(
        sum(orders for _, _, orders in requests),
        time.process_time() - cpu,
        time.thread_time() - main_cpu,
        time.perf_counter() - wall,
        latencies,
        collector,
    )
    if failures:
        msg = f"{len(failures)} POSTs failed, first: {failures[0]}"
        raise RuntimeError(msg)
    return figures


def _start_spy(output: Path | None) -> subprocess.Popen[bytes] | None:
    """py-spy sampling this process at 500 Hz into ``output`` (collapsed stacks)."""
    if output is None:
        return None
    spy = Path(sys.executable).parent / "py-spy"
    command = [str(spy), "record", "--pid", str(os.getpid()), "--rate", "500", "--nonblocking"]
    command += ["--format", "raw", "--output", str(output)]
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # noqa: S603


def summarize_spy(path: Path, limit: int) -> None:
    """Shares of py-spy's samples: per function, its own (top of stack) and its inclusive share."""
    own: Counter[str] = Counter()
    inclusive: Counter[str] = Counter()
    total = 0
    for line in path.read_text().splitlines():
        stack, _, count_text = line.rpartition(" ")
        count = int(count_text)
        frames = [_frame(f) for f in stack.split(";")]
        total += count
        own[frames[-1]] += count
        for frame in set(frames):
            inclusive[frame] += count
    print(f"\npy-spy: {total} samples of one burst (all threads, on CPU)")
    for title, counter in (("own", own), ("inclusive", inclusive)):
        print(f"\n--- by {title} share ---")
        for frame, count in counter.most_common(limit):
            print(f"{count / total:6.1%}  {frame}")


def _frame(text: str) -> str:
    """``function (path/to/module.py:12)`` as ``function (module.py)``."""
    name, _, where = text.partition(" (")
    return f"{name} ({Path(where.rstrip(')').split(':')[0]).name})" if where else name


def percentile(samples: list[float], fraction: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(fraction * len(ordered)))]


def describe(figures: Figures) -> str:
    lat = figures.latencies_s
    collections = "/".join(str(n) for n in figures.gc.counts)
    gc_us = sum(figures.gc.seconds) / figures.posts * 1e6
    return (
        f"CPU/order {figures.cpu_us:5.0f} µs (main thread {figures.main_cpu_us:5.0f} µs, of it "
        f"GC {gc_us:4.0f} µs in {collections} collections of gen 0/1/2)  "
        f"wall {figures.wall_s:5.2f} s  latency p50/p99 "
        f"{percentile(lat, 0.5) * 1e3:5.1f}/{percentile(lat, 0.99) * 1e3:5.1f} ms"
    )


def print_profile(profiler: cProfile.Profile, posts: int, limit: int) -> None:
    stats = pstats.Stats(profiler)
    total = sum(row[2] for row in stats.stats.values())  # type: ignore[attr-defined]
    print(f"\ncProfile of one burst (main thread; {total / posts * 1e6:.0f} µs/POST profiled):")
    for key, title in (("tottime", "own time"), ("cumulative", "cumulative")):
        out = io.StringIO()
        pstats.Stats(profiler, stream=out).strip_dirs().sort_stats(key).print_stats(limit)
        print(f"\n--- by {title} ---")
        lines = out.getvalue().splitlines()
        start = next(i for i, line in enumerate(lines) if line.lstrip().startswith("ncalls"))
        print("\n".join(lines[start:]))


async def run(args: argparse.Namespace) -> None:
    ways = (True, False) if args.compare_fastapi else (True,)
    results: dict[bool, list[Figures]] = {way: [] for way in ways}
    for index in range(args.runs):
        for short in ways:
            figures = await burst(
                args.vehicles,
                args.concurrency,
                gc_off=args.gc_off,
                default_gc=args.default_gc,
                batch=args.batch,
                short_post=short,
            )
            results[short].append(figures)
            way = "" if len(ways) == 1 else (" short way" if short else " via FastAPI")
            print(f"run {index + 1}{way}: {describe(figures)}", flush=True)
    for short, figures_of_way in results.items():
        if not figures_of_way:
            continue
        cpu = statistics.median(f.cpu_us for f in figures_of_way)
        main = statistics.median(f.main_cpu_us for f in figures_of_way)
        way = "" if len(ways) == 1 else (" (short way)" if short else " (via FastAPI)")
        print(
            f"\nN = {args.vehicles}, {args.concurrency} in flight, {args.runs} runs{way}: median "
            f"CPU per order {cpu:.0f} µs (main thread {main:.0f} µs); load average "
            f"{os.getloadavg()[0]:.2f}"
        )
    if args.profile:
        profiler = cProfile.Profile()
        figures = await burst(
            args.vehicles,
            args.concurrency,
            Sampling(profiler=profiler),
            gc_off=args.gc_off,
            default_gc=args.default_gc,
            batch=args.batch,
        )
        print_profile(profiler, figures.posts, args.limit)
    if args.spy is not None:
        await burst(
            args.vehicles,
            args.concurrency,
            Sampling(spy_file=args.spy),
            gc_off=args.gc_off,
            default_gc=args.default_gc,
            batch=args.batch,
        )
        summarize_spy(args.spy, args.limit)


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("--vehicles", type=int, default=1000)
    cli.add_argument("--concurrency", type=int, default=32, help="requests in flight")
    cli.add_argument("--runs", type=int, default=3)
    cli.add_argument(
        "--batch", type=int, default=1, help="orders per request (more than 1: POST /orders/batch)"
    )
    cli.add_argument("--profile", action="store_true", help="one more burst under cProfile")
    cli.add_argument("--spy", type=Path, help="one more burst sampled by py-spy into this file")
    cli.add_argument(
        "--gc-off",
        action="store_true",
        help="no cyclic GC in the bursts: profiles without collections charged to random frames",
    )
    cli.add_argument(
        "--default-gc",
        action="store_true",
        help="CPython's default collector thresholds instead of vda-master's tuning",
    )
    cli.add_argument(
        "--compare-fastapi",
        action="store_true",
        help="alternate each run with one that leaves POST /orders to FastAPI (api_fast)",
    )
    cli.add_argument("--limit", type=int, default=40, help="rows of each profile table")
    cli.add_argument("--log-level", default="WARNING", help="as the master's (fleet.py: WARNING)")
    args = cli.parse_args()
    configure_logging(json=True, level=args.log_level)
    with Path(os.devnull).open("w") as sink:
        if args.log_level.upper() != "WARNING":  # the lines are rendered, then dropped
            structlog.configure(logger_factory=structlog.PrintLoggerFactory(file=sink))
        asyncio.run(run(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
