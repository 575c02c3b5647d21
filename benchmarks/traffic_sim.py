"""Traffic control in a deterministic co-simulation (issue 9): the real master service and the
real simulated vehicles in one process on one fake clock, messages passed with a fixed latency
(the engine is ``vda-fleetsim``'s, :mod:`vda_fleetsim.simulation`; this is its research CLI:
ranges of seeds, worker processes, a line over the seeds per K).

``benchmarks/traffic.py`` measures the real stack over MQTT in real time; this one runs the same
transports (:mod:`vda_fleetsim.workload`) without real time and without a broker: a simulated
hour of ten vehicles takes about half a minute, every run is reproducible from its seed, and a
change to traffic control or to the graph can be judged on several seeds before the real
benchmark confirms it. Per run: orders per simulated hour, the mean free-flow time of the
finished orders (the yardstick, which a change of layout or route cost can move), stretch (order
time / free-flow time) mean and p95, deadlocks (orders over 5x their free-flow time, finished or
not), the minimum distance between two vehicles, separation violations, deadlocks resolved by
master control, idle vehicles it moved out of another's way, and how the vehicles with an order
spent their time. ``--dump`` adds the fleet
at the end, what the waits were for (the kind of resource and what the vehicle waited on did)
and where (the kind of node the waiting vehicle stood on, the nodes most waited on), and each
order over 5x its free-flow time with the places it waited longest and whom it waited for
there, the free-flow time of the route it was first given (a planned way round shows above its
own free-flow time), the re-plans and back-offs that changed its route, and the resolved
deadlocks it was a member of (when, and how many vehicles); and the finished orders by stretch
band, each with the share of them that were members of a resolved deadlock.

Run: PYTHONPATH=. python benchmarks/traffic_sim.py [--vehicles 10 20] [--sim-hours 0.5]
     [--seeds 1 2 3 | --seeds 1-24] [--jobs 2] [--latency-ms 20] [--client-delay-ms 0]
     [--graph FILE] [--off] [--master-setting key=value]

``--client-delay-ms`` is how long (simulated) a vehicle whose order ended waits for its next
one; 0, the default, asks at once, in the step the order ended. The real benchmark's client
takes a poll round and an HTTP request, 0.1-0.5 s of simulated time at time lapse 10, in which
master control may already send the idle vehicle out of another's way; the ``parked`` column
counts those moves.

``--jobs N`` runs N simulations at once in worker processes (one per core; every run is
deterministic and independent, so the figures are those of a single process, printed in seed
order). A change to traffic control needs many seeds before its tail can be told from another
set of seeds' (docs/traffic.md, *Three ways to predict better*: about 18 seeds on each side for
a tail halved).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path
from typing import Any

import structlog
import yaml

from vda_fleetsim.cli import add_any_station_option, seed_list
from vda_fleetsim.runs import SimRun, results_of
from vda_fleetsim.workload import DEADLOCK_FACTOR, SAFETY_M

REPO = Path(__file__).resolve().parents[1]
WAREHOUSE = REPO / "config" / "graphs" / "warehouse.json"


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    cli.add_argument("--vehicles", type=int, nargs="+", default=[10])
    cli.add_argument("--sim-hours", type=float, default=0.5)
    cli.add_argument(
        "--seeds", type=seed_list, nargs="+", default=[[1, 2, 3]], help="seeds or ranges (1-24)"
    )
    cli.add_argument("--jobs", type=int, default=1, help="simulations run at once (processes)")
    cli.add_argument("--latency-ms", type=float, default=20.0)
    cli.add_argument(
        "--client-delay-ms",
        type=float,
        default=0.0,
        help="simulated ms from an order's end until the next one is asked for",
    )
    cli.add_argument("--graph", type=Path, default=WAREHOUSE)
    cli.add_argument("--off", action="store_true", help="traffic control off")
    cli.add_argument("--master-setting", action="append", default=[], help="key=value (YAML)")
    cli.add_argument("--dump", action="store_true", help="the fleet and the waits after each run")
    cli.add_argument(
        "--two-stops",
        action="store_true",
        help="each transport is one order with two stops (pick, then drop); orders/h then "
        "counts transports, and free flow and stretch are the whole transport's",
    )
    cli.add_argument(
        "--eta",
        action="store_true",
        help="also print how well master control's expectedFinishAt foretold each order's end: "
        "the error over the order's duration (median and 90th percentile of its size, and the "
        "mean: above 0, later than expected), at creation, the same with nothing learned, and "
        "halfway",
    )
    add_any_station_option(cli)
    args = cli.parse_args()
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(40))
    settings: dict[str, Any] = {"traffic_control": not args.off}
    for item in args.master_setting:
        key, _, value = item.partition("=")
        settings[key] = yaml.safe_load(value)
    print(f"{args.sim_hours} h per run, latency {args.latency_ms} ms, client delay "
          f"{args.client_delay_ms} ms, settings {settings}, "
          f"any station of type: {args.any_station or 'none'}, "
          f"{'an order of two stops' if args.two_stops else 'an order'} per transport leg"
          f"{'s' if args.two_stops else ''}")  # fmt: skip
    print(f"{'K':>3} {'seed':>4} {'orders/h':>9} {'ff s':>5} {'stretch':>8} {'p95':>6} "
          f"{'dead':>5} {'failed':>6} {'min m':>6} {'viol':>5} {'resolved':>8} {'parked':>6}"
          "  time")  # fmt: skip
    seeds = [seed for group in args.seeds for seed in group]
    runs = [
        SimRun(args.graph, count, seed, args.latency_ms / 1000, args.sim_hours, settings,
             frozenset(args.any_station), dump=args.dump,
             client_delay_s=args.client_delay_ms / 1000, two_stops=args.two_stops,
             safety_m=SAFETY_M)
        for count in args.vehicles
        for seed in seeds
    ]  # fmt: skip
    reports: list[dict[str, Any]] = []
    for run, (r, dumped) in zip(runs, results_of(runs, args.jobs), strict=True):
        shares = ", ".join(f"{k} {v:.0%}" for k, v in r["time"].items())
        print(
            f"{run.count:>3} {run.seed:>4} {r['orders_per_h']:>9.0f} {r['free_flow_s']:>5.1f} "
            f"{r['stretch_mean']:>8.2f} "
            f"{r['stretch_p95']:>6.2f} {r['deadlocks']:>5} {r['failed']:>6} "
            f"{r['min_m']:>6.2f} {r['violations']:>5} {r['resolved']:>8} "
            f"{r['parking_moves']:>6}  {shares}",
            flush=True,
        )
        if args.eta:
            print(eta_line(r["eta"]), flush=True)
        print(dumped, end="", flush=True)
        reports.append(r)
        if len(reports) == len(seeds):  # this K's last seed
            if len(reports) > 1:
                print(seeds_summary(run.count, reports, args.sim_hours), flush=True)
            reports = []
    return 0


def eta_line(figures: dict[str, dict[str, float]]) -> str:
    """expectedFinishAt's error over the order's duration, per moment it was taken."""
    parts = [
        f"{key} p50 {f['p50']:.0%} p90 {f['p90']:.0%} bias {f['bias']:+.0%}"
        for key, f in figures.items()
    ]
    return "      expectedFinishAt error: " + "; ".join(parts)


def seeds_summary(count: int, reports: list[dict[str, Any]], sim_hours: float) -> str:
    """One line over the seeds of one K: the orders over 5x summed (and per simulated hour),
    throughput and stretch averaged. A change to traffic control is judged on this line, over
    enough seeds: the same code gave 57, 75 and 56 over 5x on three sets of eight seeds at
    K = 20 (docs/traffic.md)."""
    slow = sum(r["deadlocks"] for r in reports)
    hours = sim_hours * len(reports)
    return (
        f"{count:>3}  all: {len(reports)} seeds, {slow} orders over {DEADLOCK_FACTOR:g}x "
        f"({slow / hours:.1f} per simulated hour, per seed "
        f"{'/'.join(str(r['deadlocks']) for r in reports)}), "
        f"{statistics.mean(r['orders_per_h'] for r in reports):.0f} orders/h, "
        f"stretch {statistics.mean(r['stretch_mean'] for r in reports):.2f}, "
        f"{sum(r['parking_moves'] for r in reports)} moves out of the way"
    )


if __name__ == "__main__":
    sys.exit(main())
