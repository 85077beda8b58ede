"""`vibrofmu continuation`: periodic orbits of the exact model continued in one parameter, through contact loss,
with folds, period doublings, Neimark-Sacker points and grazing located (docs/continuation.md)."""
import math
import sys

from vibrofmu.commands.common import (FMU_HELP, SET_HELP, Command, Unused, UserError, built_plant, count,
                                      out_folder, parse_set, plant_fmu, positive)

PARAMETERS = ("omega", "Delta", "mu", "alpha", "gamma")  # analyses.continuation.PARAMETERS (checked by a test)
BENCH_SCENE = {"mu": 0.05, "Delta": 0.1, "R": 3.0}  # the benchmark's branch: omega 0.6 -> 1.2, two folds, grazing
BENCH_POINTS = 200
FOLLOW = ("fold", "period-doubling", "grazing", "neimark-sacker", "all")  # analyses.curves.KINDS, all of them, and NS
# (refused: NO_NEIMARK_SACKER)
NO_NEIMARK_SACKER = ("--follow neimark-sacker: there is no Neimark-Sacker point to follow: a complex pair of "
                     "multipliers has |rho|^2 = det M = exp(-mu T) < 1 for every mu >= 0, so it never reaches the "
                     "unit circle (docs/continuation.md, Events)")
BENCH_STEP_POINTS = 50  # step sized for 50 points on a straight branch: the 200 then reach past both folds and grazings



def options(p):
    p.add_argument("--param", choices=PARAMETERS,
                   help="the parameter to continue in (no default: required unless --bench)")
    p.add_argument("--from", dest="start", type=float, metavar="A",
                   help="first value of the parameter (no default: required unless --bench)")
    p.add_argument("--to", dest="stop", type=float, metavar="B",
                   help="last value of the parameter (no default: required unless --bench)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    p.add_argument("--points", type=count, default=200,
                   help="points of a straight branch over [A, B] (sets the largest step; a winding branch takes "
                        "up to 4x as many)")
    p.add_argument("--no-doubling", action="store_true", help="do not switch to the doubled branches")
    p.add_argument("--max-period", type=count, default=8, metavar="N",
                   help="follow a period-doubling cascade up to orbits of period N T: at every period doubling of "
                        "a branch of period n T with 2n <= N the branch of period 2n T is continued (a doubling on "
                        "a branch of period N T is located, not followed; default 8)")
    p.add_argument("--confirm", action="store_true",
                   help="confirm every located event by long FMU runs on either side (confirmations.json)")
    p.add_argument("--delta", type=positive, default=None,
                   help="distance in the parameter of the FMU runs from an event (default: 1 %% of |B - A|)")
    p.add_argument("--fmu", default=None, help=FMU_HELP + ", for --confirm")
    p.add_argument("--chart", nargs=3, type=positive, metavar=("DELTA_LO", "DELTA_HI", "N"),
                   help="also the two-parameter chart in (omega, Delta): omega-branches at N forcing amplitudes "
                        "(geometric grid) beside the slow flow's folds (chart.png, chart.parquet, chart.json, "
                        "the fold table); needs --param omega (default: no chart)")
    p.add_argument("--bench", action="store_true",
                   help=f"the cost benchmark: a branch of {BENCH_POINTS} points on the scene "
                        f"{', '.join(f'{k}={v:g}' for k, v in BENCH_SCENE.items())}, omega 0.6 -> 1.2 (bench.json)")
    p.add_argument("--follow", choices=FOLLOW,
                   help="continue every point of this kind on the branch in two parameters (--param and --param2): "
                        "curves.parquet, curves.png; 'all' follows folds, period doublings and grazings; "
                        "neimark-sacker is refused: none exists at mu >= 0 (default: none)")
    p.add_argument("--param2", choices=PARAMETERS, help="the second parameter of --follow (no default: required with --follow)")
    p.add_argument("--to2", type=float, metavar="VALUE", help="the curves run up to this value of --param2 (no default: required with --follow)")
    p.add_argument("--from2", type=float, metavar="VALUE",
                   help="... and down to this one (default: the scene's value: the curves go one way only)")
    p.add_argument("--out", required=True, help="output folder (branch.parquet, branch.png, summary.json)")


def _scene(args):
    from vibromodel.parameters import Scene, validate

    scene = Scene().with_values(**parse_set(args.set))
    if args.param in parse_set(args.set):
        raise UserError(f"--set {args.param}=...: {args.param} is the continued parameter (given by --from/--to)")
    for value in (args.start, args.stop):
        if not math.isfinite(value):
            raise UserError(f"--param {args.param}: --from/--to must be finite, got {value:g}")
        validate(scene.with_values(**{args.param: value}))  # ParameterError names the parameter and value
    if args.param == "omega" and min(args.start, args.stop) <= 0:
        raise UserError(f"--param omega: the forcing frequency must be > 0, got {min(args.start, args.stop):g}")
    if args.param == "mu" and min(args.start, args.stop) < 0:
        raise UserError(f"--param mu: the damping must be >= 0, got {min(args.start, args.stop):g}")
    if args.start == args.stop:
        raise UserError(f"--from and --to are both {args.start:g}: a branch needs a range")
    return scene


def run(args) -> int:
    if args.bench:
        args.param, args.start, args.stop = "omega", 0.6, 1.2
        args.set = args.set + [f"{k}={v}" for k, v in BENCH_SCENE.items()]
    if args.param is None or args.start is None or args.stop is None:
        raise UserError("continuation needs --param NAME --from A --to B (or --bench)")
    if args.chart:
        lo, hi, n = args.chart
        if args.param != "omega":
            raise UserError(f"--chart draws the (omega, Delta) plane: it needs --param omega, got --param {args.param}")
        if not (lo < hi and n == int(n) and n >= 2):
            raise UserError(f"--chart {lo:g} {hi:g} {n:g}: need DELTA_LO < DELTA_HI and an integer N >= 2")
    scene = _scene(args)
    if args.follow == "neimark-sacker":
        raise UserError(NO_NEIMARK_SACKER)
    if args.follow:
        if args.param2 is None or args.to2 is None:
            raise UserError("--follow needs --param2 NAME --to2 VALUE")
        if args.param2 == args.param:
            raise UserError(f"--param2 {args.param2}: it is the branch's parameter already; name another")
        from vibromodel.parameters import validate

        for value in (args.to2, args.from2):
            if value is not None:
                if not math.isfinite(value):
                    raise UserError(f"--param2 {args.param2}: --to2/--from2 must be finite, got {value:g}")
                validate(scene.with_values(**{args.param2: value}))
    elif args.param2 is not None or args.to2 is not None or args.from2 is not None:
        raise UserError("--param2, --to2 and --from2 serve --follow: add --follow KIND or leave them out")
    fmu = plant_fmu(args.fmu) if args.confirm else None
    out = out_folder(args.out)
    fmu = fmu and built_plant(fmu)

    from vibrofmu.analyses import continuation as cont
    from vibrofmu.analyses import continuation_output as output
    from vibrofmu.output import export

    def say(line):
        print(line, file=sys.stderr, flush=True)

    def progress(index, point):
        if index % 20 == 0:
            say(f"continuation: {index} points, {args.param} = {point.p:.8g}, x in [{point.x_min:.4g}, "
                f"{point.x_max:.4g}], max |rho| = {point.rho_max:.4g}")

    from vibrofmu.analyses.shooting import ShootingError

    try:
        result = cont.branch(scene, args.param, args.start, args.stop,
                             points=BENCH_STEP_POINTS if args.bench else args.points,
                             double=not args.no_doubling, max_period=args.max_period, progress=progress,
                             max_points=BENCH_POINTS if args.bench else None)
    except ShootingError as error:
        hint = (f" (the electrodes sit at x = +-3R/2 = +-{1.5 * scene.R:g}; a larger R, e.g. --set R=3, leaves room "
                f"for large orbits)" if "pull-in" in str(error) else "")
        print(f"error: continuation in {args.param} from {args.start:g}: {error}{hint}", file=sys.stderr)
        return 1
    output.write_branch(out / "branch.parquet", result)
    others = export.scene_text({k: v for k, v in scene.as_dict().items() if k not in ("x_start", "v_start", args.param)})
    title = f"periodic orbits continued in {export.symbol(args.param)} ({others})"
    output.plot_branch(out / "branch.png", result, title)
    summary = {"scene": scene.as_dict(), "param": args.param, "from": args.start, "to": args.stop,
               "points": len(result.points), "stop_reason": result.stop_reason, "seconds": result.seconds,
               "cpu_seconds": result.cpu_seconds,
               "events": [{"event": pt.event, "value": pt.p, "x_min": pt.x_min, "x_max": pt.x_max,
                           "multipliers": [[r.real, r.imag] for r in pt.multipliers]} for pt in result.events()],
               "doubled_branches": [{"periods": br.problem.periods, "points": len(br.points),
                                     "stop_reason": br.stop_reason,
                                     "events": [{"event": pt.event, "value": pt.p} for pt in br.events()]}
                                    for br in result.doubled]}
    steps = cont.cascade(result)
    if len(steps) >= 2:  # a cascade: the doubling points in order of period, and Feigenbaum's ratios
        summary["cascade"] = {"param": args.param,
                              "doublings": [{"periods": pt.periods, "to_periods": 2 * pt.periods, "value": pt.p,
                                             "multipliers": [[r.real, r.imag] for r in pt.multipliers],
                                             "residual": pt.residual} for pt in steps],
                              "ratios": cont.feigenbaum_ratios([pt.p for pt in steps])}
    print(f"{len(result.points)} orbits from {args.param} = {args.start:g} ({result.stop_reason}) in "
          f"{result.seconds:.1f} s ({result.cpu_seconds:.1f} s CPU)")
    for pt in result.events():
        print(f"{pt.event} at {args.param} = {pt.p:.10g}: x in [{pt.x_min:.5g}, {pt.x_max:.5g}], multipliers "
              + ", ".join(f"{r.real:.5g}{r.imag:+.2g}j" if r.imag else f"{r.real:.6g}" for r in pt.multipliers))
    for index, br in enumerate(result.doubled, 1):
        print(f"doubled branch {index}: {len(br.points)} orbits of period {br.problem.periods}T ({br.stop_reason})"
              + "".join(f"; {pt.event} at {pt.p:.8g}" for pt in br.events()))
    named = [("branch", result)] + [(f"doubled branch {i}", b) for i, b in enumerate(result.doubled, 1)]
    for name, br in named:
        if br.stop_reason.startswith("stopped at"):
            print(f"warning: {name} {br.stop_reason} before {args.param} = {args.stop:g}; raise --points")
        elif br.stop_reason.startswith("pull-in"):
            print(f"warning: {name} ends at {br.stop_reason}")
    if "cascade" in summary:
        print("cascade: " + ", ".join(f"{d['periods']}T -> {d['to_periods']}T at {args.param} = {d['value']:.10g}"
                                      for d in summary["cascade"]["doublings"])
              + "; ratios of successive intervals " + ", ".join(f"{r:.4f}" for r in summary["cascade"]["ratios"])
              + " (Feigenbaum's delta 4.6692)")
    status = 0
    if args.confirm:
        delta = args.delta or 0.01 * abs(args.stop - args.start)
        records = cont.confirm(result, fmu, delta, progress=print)
        summary["confirmations"] = records
        export.write_json(out / "confirmations.json", records)
    if args.bench:
        import os

        bench = {"points": len(result.points), "seconds": result.seconds, "cpu_seconds": result.cpu_seconds,
                 "seconds_per_point": result.seconds / len(result.points), "cpu_count": os.cpu_count(),
                 "load_average_1min": os.getloadavg()[0],
                 "target": f"{BENCH_POINTS} points in < 60 s", "scene": scene.as_dict()}
        export.write_json(out / "bench.json", bench)
        print(f"bench: {bench['points']} points in {bench['seconds']:.1f} s wall clock, {bench['cpu_seconds']:.1f} s "
              f"CPU ({1e3 * bench['seconds_per_point']:.0f} ms per point; load average "
              f"{bench['load_average_1min']:.1f} on {bench['cpu_count']} cores; target {bench['target']})")
    if args.follow:
        from vibrofmu.analyses import curves as two

        kinds = two.KINDS if args.follow == "all" else (args.follow,)
        found = []
        scale1 = abs(args.stop - args.start)
        for kind in kinds:
            with_kind = [(name, br) for name, br in named if any(pt.event == kind for pt in br.points)]
            if not with_kind:
                print(f"no {kind} on the branches: no {kind} curve")
            for name, br in with_kind:
                try:  # a doubled branch's curves are of its orbits (period 2T, 4T, ...), stepped on the T range
                    found.append(two.curves_from_branch(br, kind, args.param2, args.to2, args.from2,
                                                        points=args.points, scale1=scale1, progress=say))
                except ShootingError as error:
                    print(f"error: {kind} curves of the {name} in ({args.param}, {args.param2}): {error}",
                          file=sys.stderr)
                    status = 1
        merged = two.merge(found, (args.param, args.param2))
        fixed = export.scene_text({k: v for k, v in scene.as_dict().items()
                                   if k not in ("x_start", "v_start", args.param, args.param2)})
        output.write_curves(out, merged, scene, f"{', '.join(k for k in kinds if any(c.kind == k for c in merged.curves))} curves continued in "
                                                f"({export.symbol(args.param)}, {export.symbol(args.param2)}) ({fixed})")
        summary["curves"] = output.curves_summary(merged)
        for line in output.curves_lines(merged):
            print(line)
    if args.chart:
        import numpy as np

        lo, hi, n = args.chart
        data = output.chart(scene, np.geomspace(lo, hi, int(n)), args.points, progress=say)
        output.write_chart(out, data, merged if args.follow and args.param2 == "Delta" else None)
        if args.follow and args.param2 != "Delta":
            print(f"note: chart.png is the (omega, Delta) plane: the curves in (omega, {args.param2}) are in "
                  "curves.png only")
        summary["chart"] = {"rows": data["rows"], "slow_flow_cusp_Delta": data["slow_flow_cusp_Delta"]}
        for line in output.agreement_table(data):
            print(line)
    export.write_json(out / "summary.json", summary)
    print(f"wrote {out}/branch.parquet, branch.png, branch.pdf, summary.json" + (", confirmations.json" if args.confirm else "")
          + (", curves.parquet, curves.png, curves.pdf" if args.follow else "")
          + (", bench.json" if args.bench else "") + (", chart.png, chart.pdf, chart.parquet, chart.json" if args.chart else ""))
    return status


def unused(args) -> list[Unused]:
    """--bench fixes the branch (parameter, range, points); --delta and --fmu serve --confirm only."""
    found = [Unused(dest, f"--bench continues its own branch (omega 0.6 -> 1.2, {BENCH_POINTS} points); leave it "
                          "out") for dest in ("param", "start", "stop") if args.bench]
    if args.bench and not args.chart:  # (--chart reads --points)
        found.append(Unused("points", f"--bench continues its own branch ({BENCH_POINTS} points); leave it out"))
    if args.no_doubling:
        found.append(Unused("max_period", "--no-doubling follows no doubled branch; leave --max-period out"))
    if not args.confirm:
        found += [Unused(dest, "only --confirm runs the FMU; add --confirm or leave it out") for dest in ("delta", "fmu")]
    return found


COMMAND = Command("continuation", "periodic orbits continued in one parameter through contact loss: folds, "
                                  "period doubling, grazing; the (omega, Delta) chart of the averaging's validity",
                  options, run, unused)
