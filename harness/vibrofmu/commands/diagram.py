"""`vibrofmu diagram`: bifurcation diagram by simulation (stroboscopic x, up and down sweeps from continued
states) and the largest Lyapunov exponent along it, serial or on Dask (analyses/diagram.py)."""
import sys

from vibrofmu.commands.common import (SET_HELP, Command, Unused, UserError, count, non_negative_int, out_folder,
                                      parse_set, scheduler_workers)


def options(p):
    from vibrofmu.analyses.diagram import DEFAULT_LYAPUNOV_PERIODS, DEFAULT_SAMPLES, PARAMETERS

    p.add_argument("--param", required=True, metavar="NAME",
                   help=f"the swept parameter: {', '.join(PARAMETERS)} (V_bias, V_AC: factors on the scene's "
                        f"voltages, through alpha, beta, gamma)")
    p.add_argument("--from", dest="lo", type=float, required=True, metavar="A", help="first value of the range")
    p.add_argument("--to", dest="hi", type=float, required=True, metavar="B", help="last value of the range")
    p.add_argument("--points", type=count, default=101, help="parameter values, evenly spaced from A to B")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    p.add_argument("--samples", type=count, default=DEFAULT_SAMPLES, help="stroboscopic samples kept per point")
    p.add_argument("--transient", type=non_negative_int, default=None,
                   help="forcing periods discarded per point (default: ceil(2 ln(1e8) / (mu T)), bounded to "
                        "[20, 20000]: an O(1) offset decays below 1e-8 at the linear rate mu/2)")
    p.add_argument("--lyapunov-periods", type=non_negative_int, default=DEFAULT_LYAPUNOV_PERIODS,
                   help="forcing periods of the Benettin estimate per point (0: no exponents)")
    p.add_argument("--workers", type=count, default=1,
                   help="1: in this process; K >= 2: a local Dask cluster of K worker processes")
    p.add_argument("--scheduler", default=None,
                   help="address of an existing Dask scheduler (tcp://HOST:PORT) instead of --workers (default: none)")
    p.add_argument("--out", required=True,
                   help="output folder (diagram.parquet, lyapunov.parquet, convergence.parquet, summary.json, "
                        "diagram.png, lyapunov_convergence.png)")


def _bar(total: int):
    from tqdm import tqdm

    return tqdm(total=total, unit="pt", desc="diagram", mininterval=0.5, dynamic_ncols=True, file=sys.stderr)


def run(args) -> int:
    import numpy as np

    from vibromodel.parameters import Scene

    from vibrofmu.analyses import diagram as dg
    from vibrofmu.output import export

    base = Scene().with_values(**parse_set(args.set))
    dg.check_request(base, args.param, args.lo, args.hi, args.points)
    lo, hi = sorted((args.lo, args.hi))
    values = np.linspace(lo, hi, args.points)
    out = out_folder(args.out)
    total = 2 * args.points * (2 if args.lyapunov_periods else 1)

    client = cluster = None
    if args.workers > 1 or args.scheduler:
        from vibrofmu.study.scheduling import connect
        from vibrofmu.study.spec import SpecError

        try:
            client, cluster = connect(args.scheduler, args.workers)
        except SpecError as error:
            raise UserError(str(error)) from None
    bar = _bar(total)
    try:
        if client is None:
            result = dg.compute(base, args.param, values, args.samples, args.transient, args.lyapunov_periods,
                                progress=lambda kind, n: bar.update(n))
        else:
            from vibrofmu.study.scheduling import STOP, stop_on_sigint

            try:
                with stop_on_sigint():
                    result = dg.compute(base, args.param, values, args.samples, args.transient,
                                        args.lyapunov_periods, client=client, progress=lambda kind, n: bar.update(n),
                                        stop=STOP.is_set)
            except dg.TaskFailed as error:
                bar.close()
                print(f"error: {error}", file=sys.stderr)
                return 1
    finally:
        bar.close()
        if client is not None:
            try:
                client.close()
                if cluster is not None:
                    cluster.close()
            except Exception:  # noqa: BLE001 - a cluster torn down by Ctrl-C: nothing left to close
                pass

    export.write_parquet(dg.diagram_table(result), out / "diagram.parquet")
    ly = dg.lyapunov_table(result)
    export.write_parquet(ly, out / "lyapunov.parquet")
    if args.lyapunov_periods:
        export.write_parquet(dg.convergence_table(result), out / "convergence.parquet")
    title = (f"{export.symbol(args.param)} from {lo:g} to {hi:g}; "
             + export.scene_text({k: v for k, v in base.as_dict().items() if k not in ("x_start", "v_start", args.param)}))
    dg.plot(result, out / "diagram.png", title=export.wrapped(title, 9.0, 11))
    if args.lyapunov_periods:
        dg.plot_convergence(result, out / "lyapunov_convergence.png")

    largest = np.array(ly.column("largest").to_pylist(), dtype=float)
    params = ly.column("parameter").to_pylist()
    directions = ly.column("direction").to_pylist()
    pulled = sum(p.pull_in for points in result.sweeps.values() for p in points)
    summary = {"parameter": args.param, "from": lo, "to": hi, "points": args.points, "samples": args.samples,
               "transient": args.transient or "auto", "lyapunov_periods": args.lyapunov_periods,
               "scene": base.as_dict(), "workers": result.workers, "wall_s": result.wall_s, "cpu_s": result.cpu_s,
               "pull_in_points": pulled}
    if args.lyapunov_periods and np.isfinite(largest).any():
        i = int(np.nanargmax(largest))
        chaotic = [(params[k], directions[k]) for k in range(len(params)) if largest[k] > 0.0]
        summary.update(max_exponent=float(largest[i]), at=params[i], direction=directions[i],
                       min_exponent=float(np.nanmin(largest)), positive_points=len(chaotic),
                       max_sum_error=float(np.nanmax(np.abs(np.array(ly.column("sum").to_pylist(), dtype=float)
                                                            + np.array([dg.scene_at(base, args.param, v).mu
                                                                        for v in params])))))
    export.write_json(out / "summary.json", summary)
    line = (f"{args.points} points x 2 sweeps in {result.wall_s:.1f} s on {result.workers} worker(s) "
            f"({result.cpu_s:.1f} s of CPU in the points)")
    if "max_exponent" in summary:
        line += (f"; largest exponent from {summary['min_exponent']:.3g} to {summary['max_exponent']:.3g} "
                 f"({args.param} = {summary['at']:.6g}, {summary['direction']}), positive at "
                 f"{summary['positive_points']} points; |lambda1 + lambda2 + mu| <= {summary['max_sum_error']:.1e}")
    print(line)
    if pulled:
        print(f"note: {pulled} points ended in pull-in (no samples; the next point restarted from the scene's "
              f"start state)", file=sys.stderr)
    written = ["diagram.parquet", "lyapunov.parquet"] + (["convergence.parquet"] if args.lyapunov_periods else []) + \
        ["summary.json", "diagram.png"] + (["lyapunov_convergence.png"] if args.lyapunov_periods else [])
    print(f"wrote {out}/" + ", ".join(written))
    return 0


def unused(args) -> list[Unused]:
    return scheduler_workers(args)


COMMAND = Command("diagram", "bifurcation diagram by simulation (up and down sweeps) and the largest Lyapunov "
                             "exponent along it, serial or on Dask", options, run, unused)
