"""Speed-up of a study from 1 to 2 local workers, measured by one command:

    python -m vibrofmu.study.scaling [--kind monte-carlo] [--engine fmu] [--set NAME=VALUE]... [--order 1,2,2,1]

runs the same study (default: monte-carlo through the FMU at mu = 0.02, 600 samples: ~15 ms a case and ~10 s
of work for one idle worker -- a study much smaller than that measures the fixed costs, not the scaling) once
per entry of --order, each in a fresh folder and a fresh LocalCluster, and prints for each run the compute
wall time (first task to last result, summary.json run.compute_wall_s), the mean cost per case, the overhead
per case (worker-seconds not spent in a case, per case) and the scheduler's cost per task; then the speed-up
T(1) / T(2) of the mean compute wall times, and the 64-worker projection (analysis.projection) of the
2-worker runs. Alternating 1, 2, 2, 1 cancels a slow drift of the machine's load to first order; the speed-up
at equal cost per case, 2 e_2 / e_1 (e_W = sum of case costs / (W x compute wall), the parallel efficiency),
also leaves out the cost per case's drift with the load of a shared machine.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

DEFAULT_SETS = ["mu=0.02", "samples=600"]


def run_once(kind: str, engine: str, workers: int, sets: list[str], out: Path) -> dict:
    command = [sys.executable, "-m", "vibrofmu.cli", "study", kind, "--engine", engine, "--workers", str(workers),
               "--out", str(out)]
    for item in sets:
        command += ["--set", item]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"error: {' '.join(command)} exited with {done.returncode}: "
                         f"{(done.stderr.strip().splitlines() or ['no output'])[-1]}")
    return json.loads((out / "summary.json").read_text())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m vibrofmu.study.scaling", description=__doc__.split("\n\n")[0])
    parser.add_argument("--kind", default="monte-carlo", choices=["monte-carlo", "basins", "response-map"])
    parser.add_argument("--engine", default="fmu", choices=["core", "fmu"])
    parser.add_argument("--set", action="append", default=None, metavar="NAME=VALUE",
                        help=f"study settings (default: {' '.join(DEFAULT_SETS)})")
    parser.add_argument("--order", default="1,2,2,1", help="worker counts, run in this order (default 1,2,2,1)")
    args = parser.parse_args(argv)
    try:
        order = [int(n) for n in args.order.split(",")]
    except ValueError:
        print(f"error: --order {args.order!r}: expected worker counts like 1,2,2,1", file=sys.stderr)
        return 2
    if not order or min(order) < 1:
        print(f"error: --order {args.order!r}: worker counts must be >= 1", file=sys.stderr)
        return 2
    sets = DEFAULT_SETS if args.set is None else args.set
    runs = []
    with tempfile.TemporaryDirectory(prefix="vibrofmu-scaling-") as folder:
        for k, workers in enumerate(order):
            summary = run_once(args.kind, args.engine, workers, sets, Path(folder) / f"run{k}")
            run = summary["run"]
            runs.append((workers, summary))
            print(f"workers {workers}: compute {run['compute_wall_s']:.2f} s (command {summary['wall_s']:.2f} s), "
                  f"{run['computed']} cases, {run['case_cost_s_mean'] * 1e3:.1f} ms a case, overhead "
                  f"{run['overhead_s_per_case'] * 1e3:.1f} ms a case, scheduler {run['scheduler_s_per_task'] * 1e3:.2f} ms a task, "
                  f"batch {run['batch_size']}", flush=True)
    by, efficiency = {}, {}
    for workers, summary in runs:
        run = summary["run"]
        by.setdefault(workers, []).append(run["compute_wall_s"])
        # parallel efficiency: the fraction of the workers' time spent inside cases, sum(c) / (W T)
        efficiency.setdefault(workers, []).append(run["case_cost_s_sum"] / (workers * run["compute_wall_s"]))
    if 1 in by and 2 in by:
        speedup = statistics.mean(by[1]) / statistics.mean(by[2])
        pairs = ", ".join(f"{statistics.mean(by[1]) / t:.2f}" for t in by[2])
        print(f"speed-up 2 workers vs 1: {speedup:.2f}x (mean compute wall {statistics.mean(by[1]):.2f} s / "
              f"{statistics.mean(by[2]):.2f} s; per 2-worker run: {pairs})")
        # T(W) = N c / (W e_W): at equal cost per case the speed-up is 2 e_2 / e_1. On a shared machine the
        # cost per case drifts with the load; this ratio leaves that drift out and keeps what scheduling loses
        e1, e2 = statistics.mean(efficiency[1]), statistics.mean(efficiency[2])
        print(f"speed-up at equal cost per case, 2 e_2 / e_1: {2 * e2 / e1:.2f}x (parallel efficiency e_1 = "
              f"{e1:.3f}, e_2 = {e2:.3f}: the share of the workers' time spent inside cases)")
    last = [summary for workers, summary in runs if workers == max(order)][-1]
    projection = last.get("projection_64_workers", {})
    if projection:
        at = projection["at_the_batch_size_for_these_workers"]
        print(f"64-worker projection (from the last {max(order)}-worker run): {at['cases_per_s']:.0f} cases/s at batch "
              f"size {at['batch_size']} = min(W b / (b c_w + c_s) = {at['worker_bound']:.0f}, b / c_s = "
              f"{at['scheduler_bound']:.0f}); c_w = {projection['case_cost_s'] * 1e3:.1f} ms, "
              f"c_s = {projection['scheduler_s_per_task'] * 1e3:.2f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
