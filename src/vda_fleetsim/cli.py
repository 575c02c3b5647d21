"""``vda-fleetsim``: how many vehicles a floor needs, simulated (docs/fleetsim.md).

Runs a fleet of simulated vehicles under master control on a graph file for a simulated time,
each vehicle taking pick-then-drop transports between the graph's ``pick`` and ``drop`` stations
without end, for each fleet size asked for and each seed, and prints one line per fleet size
(the mean over the seeds): transports per hour, per vehicle and added per vehicle over the
fleet size before (where it falls, more vehicles stop paying), order time, stretch (order time
over the time the same order takes a vehicle alone), orders over 5x that time, how the vehicles
spent their time, the closest two came. ``--where`` adds the nodes where vehicles waited most.

Exit status: 0 after a report, 2 for a usage or configuration error (said on stderr).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import structlog
import yaml
from pydantic import ValidationError

from vda5050.errors import ConfigError
from vda5050.graph_file import GraphNode
from vda_fleetsim.runs import SimRun, results_of
from vda_fleetsim.workload import DEADLOCK_FACTOR
from vda_master.graph import Graph, GraphError, load_graph

DEFAULT_GRAPH: Final = Path("config/graphs/warehouse.json")
#: What a vehicle spent its time on (Simulation's categories) and the column it goes in.
TIME_COLUMNS: Final = {
    "driving": "driving",
    "action": "actions",
    "waits in traffic": "waiting",
    "charging": "charging",
    "no order": "idle",
}
WHERE_TOP: Final = 8


def main(argv: Sequence[str] | None = None) -> int:
    cli = _parser()
    args = cli.parse_args(argv)
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(40))
    try:
        master = _settings(args.master_setting, "--master-setting")
        vehicle = _settings(args.vehicle_setting, "--vehicle-setting")
        graph = load_graph(args.graph)
        _check_stations(graph)
        master.setdefault("traffic_control", not args.off)
        seeds = [seed for group in args.seeds for seed in group]
        runs = [
            SimRun(args.graph, count, seed, args.latency_ms / 1000, args.sim_hours, master,
                   frozenset(args.any_station), dump=args.where,
                   client_delay_s=args.client_delay_ms / 1000, two_stops=args.two_stops,
                   vehicle_settings=vehicle, start_node=args.start_node)
            for count in args.vehicles
            for seed in seeds
        ]  # fmt: skip
        print(_title(args, graph.nodes, seeds, master), flush=True)  # noqa: T201
        print(_header(), flush=True)  # noqa: T201
        rows = _report(runs, args.jobs, len(seeds), where=args.where)
    except (ConfigError, GraphError, ValidationError, OSError, ValueError) as exc:
        print(f"vda-fleetsim: {exc}", file=sys.stderr)  # noqa: T201
        return 2
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=2, allow_nan=False, default=str) + "\n")
    return 0


def _parser() -> argparse.ArgumentParser:
    cli = argparse.ArgumentParser(
        prog="vda-fleetsim",
        description="Simulate a fleet taking pick-and-drop transports on a graph, for several "
        "fleet sizes, faster than real time: how many vehicles does the floor need?",
    )
    cli.add_argument("--graph", type=Path, default=DEFAULT_GRAPH, help="the graph file")
    cli.add_argument(
        "--vehicles", type=_positive_int, nargs="+", default=[4, 8, 12], help="fleet sizes"
    )
    cli.add_argument("--sim-hours", type=_positive_float, default=1.0, help="simulated per run")
    cli.add_argument(
        "--seeds", type=seed_list, nargs="+", default=[[1]], help="seeds or ranges (1-8)"
    )
    cli.add_argument("--jobs", type=_positive_int, default=1, help="runs at once (processes)")
    cli.add_argument("--off", action="store_true", help="traffic control off (an upper bound)")
    cli.add_argument(
        "--master-setting", action="append", default=[], help="master config key=value (YAML)"
    )
    cli.add_argument(
        "--vehicle-setting",
        action="append",
        default=[],
        help="vehicle config key=value (YAML), e.g. speed_max_mps=2.0",
    )
    cli.add_argument("--start-node", help="where the first vehicle stands (default: parking)")
    add_any_station_option(cli)
    cli.add_argument(
        "--two-stops", action="store_true", help="each transport is one order with two stops"
    )
    cli.add_argument(
        "--client-delay-ms",
        type=float,
        default=200.0,
        help="simulated ms from an order's end to the next one (a client's reaction)",
    )
    cli.add_argument(
        "--latency-ms", type=float, default=20.0, help="message latency (simulated ms)"
    )
    cli.add_argument("--where", action="store_true", help="the nodes where vehicles waited most")
    cli.add_argument("--json", type=Path, help="also write the rows to this file")
    return cli


def add_any_station_option(cli: argparse.ArgumentParser) -> None:
    """``--any-station pick drop``: the leg kinds that ask for any station of their type."""
    cli.add_argument(
        "--any-station",
        nargs="+",
        choices=["pick", "drop"],
        default=[],
        help="legs of these kinds ask for any station of the type (POST /orders stationType)",
    )


def seed_list(text: str) -> list[int]:
    """A seed (``7``) or an inclusive range of seeds (``1-24``)."""
    first, dash, last = text.partition("-")
    try:
        low = int(first)
        high = int(last) if dash else low
    except ValueError:
        msg = f"{text!r}: a seed is a whole number, a range is like 1-24"
        raise argparse.ArgumentTypeError(msg) from None
    if high < low:
        msg = f"{text!r}: the range ends before it starts"
        raise argparse.ArgumentTypeError(msg)
    return list(range(low, high + 1))


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        msg = f"{text!r}: give a whole number of at least 1"
        raise argparse.ArgumentTypeError(msg)
    return value


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0 or math.isinf(value):
        msg = f"{text!r}: give a number above 0"
        raise argparse.ArgumentTypeError(msg)
    return value


def _settings(items: list[str], flag: str) -> dict[str, Any]:
    settings: dict[str, Any] = {}
    for item in items:
        key, equals, value = item.partition("=")
        if not equals or not key:
            msg = f"{flag} {item!r}: give key=value"
            raise ValueError(msg)
        settings[key.strip()] = yaml.safe_load(value)
    return settings


def _check_stations(graph: Graph) -> None:
    """The transports need pick and drop stations."""
    for kind in ("pick", "drop"):
        if not graph.station_nodes(kind):
            msg = (
                f"the graph has no node with stationType {kind!r}: the transports go from "
                "pick stations to drop stations (docs/fleetsim.md)"
            )
            raise ValueError(msg)


def _title(
    args: argparse.Namespace,
    nodes: Mapping[str, GraphNode],
    seeds: list[int],
    master: dict[str, Any],
) -> str:
    kinds: defaultdict[str, int] = defaultdict(int)
    for node in nodes.values():
        if node.station_type:
            kinds[node.station_type] += 1
    stations = ", ".join(f"{n} {kind}" for kind, n in sorted(kinds.items()))
    control = "on" if master.get("traffic_control", True) else "off"
    return (
        f"{args.graph} ({len(nodes)} nodes: {stations}); {args.sim_hours:g} simulated h per "
        f"run, seeds {' '.join(map(str, seeds))}; traffic control {control}; "
        f"{'one order of two stops' if args.two_stops else 'two orders'} per transport"
    )


def _header() -> str:
    return (
        f"{'vehicles':>8} {'transports/h':>12} {'per vehicle':>11} {'added':>6} {'order s':>8} "
        f"{'p95':>6} {'stretch':>7} {'p95':>5} {f'>{DEADLOCK_FACTOR:g}x':>4} "
        + " ".join(f"{name:>8}" for name in TIME_COLUMNS.values())
        + f" {'closest m':>9}"
    )


def _report(runs: list[SimRun], jobs: int, per_size: int, *, where: bool) -> list[dict[str, Any]]:
    """Print one line per fleet size (the mean over its seeds) as soon as its runs are done."""
    rows: list[dict[str, Any]] = []
    reports: list[dict[str, Any]] = []
    for run, (report, _) in zip(runs, results_of(runs, jobs), strict=True):
        reports.append(report)
        if len(reports) < per_size:
            continue
        row = _row(run, reports)
        if rows:  # what each vehicle added over the fleet size before: where more stop paying
            before = rows[-1]
            added = row["transports_per_h"] - before["transports_per_h"]
            row["added_per_vehicle_h"] = added / (row["vehicles"] - before["vehicles"])
        rows.append(row)
        print(_line(row), flush=True)  # noqa: T201
        if where:
            print(_where(reports), flush=True)  # noqa: T201
        reports = []
    return rows


def _row(run: SimRun, reports: list[dict[str, Any]]) -> dict[str, Any]:
    """The mean over one fleet size's seeds."""
    per_order = 1.0 if run.two_stops else 0.5  # orders per transport leg

    def mean(key: str) -> float:
        values = [r[key] for r in reports if not math.isnan(r[key])]
        return statistics.fmean(values) if values else math.nan

    transports = mean("orders_per_h") * per_order
    time = {
        column: statistics.fmean(r["time"].get(key, 0.0) for r in reports)
        for key, column in TIME_COLUMNS.items()
    }
    return {
        "vehicles": run.count,
        "transports_per_h": transports,
        "transports_per_vehicle_h": transports / run.count,
        "order_s_mean": mean("order_s_mean"),
        "order_s_p95": mean("order_s_p95"),
        "stretch_mean": mean("stretch_mean"),
        "stretch_p95": mean("stretch_p95"),
        "orders_over_5x": sum(r["deadlocks"] for r in reports),
        "failed": sum(r["failed"] for r in reports),
        "time_shares": time,
        "closest_m": min(r["min_m"] for r in reports),
        "violations": sum(r["violations"] for r in reports),
        "seeds": len(reports),
    }


def _line(row: dict[str, Any]) -> str:
    shares = " ".join(f"{row['time_shares'][name]:>8.0%}" for name in TIME_COLUMNS.values())
    gain = row.get("added_per_vehicle_h")
    added = "-" if gain is None else f"{gain:.1f}"
    warning = ""
    if row["violations"]:
        warning += f"  {row['violations']} separation violations"
    if row["failed"]:
        warning += f"  {row['failed']} orders failed"
    return (
        f"{row['vehicles']:>8} {row['transports_per_h']:>12.0f} "
        f"{row['transports_per_vehicle_h']:>11.1f} {added:>6} {row['order_s_mean']:>8.1f} "
        f"{row['order_s_p95']:>6.1f} {row['stretch_mean']:>7.2f} {row['stretch_p95']:>5.2f} "
        f"{row['orders_over_5x']:>4} {shares} {row['closest_m']:>9.2f}{warning}"
    )


def _where(reports: list[dict[str, Any]]) -> str:
    """The nodes waited on most, as shares of all the waiting of this fleet size."""
    waited: defaultdict[str, float] = defaultdict(float)
    for report in reports:
        for node, seconds in report["waited_at"].items():
            waited[node] += seconds
    total = sum(waited.values())
    if not total:
        return f"{'':>8} nobody waited in traffic"
    top = sorted(waited.items(), key=lambda item: -item[1])[:WHERE_TOP]
    places = ", ".join(f"{node} {seconds / total:.0%}" for node, seconds in top)
    return f"{'':>8} waited most at: {places}"
