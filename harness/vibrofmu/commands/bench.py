"""`vibrofmu bench`: work-precision of every fidelity, solver and setting; the speed-accuracy ladder."""
import sys

from vibrofmu.commands.common import FMU_HELP, Command, Unused, built_plant, count, out_folder, plant_fmu


def options(p):
    p.add_argument("--quick", action="store_true", help="tau in [0, 200], fewer settings, 1 timed repeat")
    p.add_argument("--repeats", type=count, default=None, help="timed runs per case after the warm-up "
                                                               "(default: 3; --quick 1)")
    p.add_argument("--ladder-rounds", type=count, default=None,
                   help="interleaved rounds of the speed-accuracy ladder (default: 3)")
    p.add_argument("--ladder-only", action="store_true",
                   help="only the speed-accuracy ladder (tau in [0, 200]; a few minutes): bench.json, ladder.png")
    p.add_argument("--peers", action="store_true",
                   help="only the comparison with other ODE solvers (numbalsoda, diffrax, CVODE, SciPy) at equal "
                        "accuracy, interleaved rounds (--ladder-rounds, default 3): peers.json, peers.png; the "
                        "peers are an optional extra: pip install -e '.[peers]'")
    p.add_argument("--curve", action="store_true",
                   help="only the two-parameter continuation benchmark: a fold curve of 200 points in (omega, Delta) "
                        "(bench.json: seconds, CPU seconds, per point; target < 60 s on 2 cores); needs no FMU")
    p.add_argument("--auto-only", action="store_true",
                   help="only what fidelity auto and the error estimates cost at set-up (a minute): bench.json")
    p.add_argument("--no-instructions", action="store_true",
                   help="skip the ladder's instruction counts (valgrind's callgrind, a few minutes)")
    p.add_argument("--fmu", default=None, help=FMU_HELP)
    p.add_argument("--out", required=True, help="output folder (bench.json, work_precision.png, ladder.png)")


def run(args) -> int:
    if args.curve:
        return run_curve(args)
    from vibrofmu.analyses import extremes
    from vibrofmu.speed import bench

    fmu = plant_fmu(args.fmu)
    out = out_folder(args.out)
    fmu = built_plant(fmu)

    def say(line):
        print(line, file=sys.stderr, flush=True)

    if args.peers:
        from vibrofmu.speed import peers

        record = peers.run_peers(fmu, out, quick=args.quick, rounds=args.ladder_rounds, say=say)
        for line in peers.peers_lines(record):
            print(line)
        print(f"peers in {record['peers']['seconds']:.0f} s; wrote {out}/peers.json, {out}/peers.png")
        return 0
    if args.auto_only:
        summary = bench.run_auto_only(fmu, out, rounds=args.ladder_rounds, progress=say)
        for line in bench.summary_lines(summary):
            print(line)
        print(f"auto in {summary['bench']['seconds']:.0f} s; wrote {out}/bench.json")
        return 0
    if args.ladder_only:
        summary = bench.run_ladder_only(fmu, out, quick=args.quick, progress=say, ladder_rounds=args.ladder_rounds,
                                        instructions=not args.no_instructions)
        for line in bench.summary_lines(summary):
            print(line)
        print(f"ladder in {summary['bench']['seconds']:.0f} s; wrote {out}/bench.json, {out}/ladder.png")
        return 0
    summary = bench.run_bench(fmu, out, quick=args.quick, repeats=args.repeats, ladder_rounds=args.ladder_rounds,
                              instructions=not args.no_instructions,
                              extreme_rows=lambda quick: extremes.extreme_rows(quick, fmu), progress=say)
    for line in bench.summary_lines(summary):
        print(line)
    print(f"{len(summary['cases'])} cases in {summary['bench']['seconds']:.0f} s; wrote {out}/bench.json, "
          f"{out}/work_precision.png, {out}/ladder.png")
    return 0


def run_curve(args) -> int:
    import os

    from vibrofmu.analyses import curves
    from vibrofmu.output import export

    out = out_folder(args.out)
    load = os.getloadavg()
    record = curves.bench_curve(progress=lambda line: print(line, file=sys.stderr, flush=True))
    record.update({"cpu_count": os.cpu_count(), "load_average_at_start": list(load),
                   "load_average_at_end": list(os.getloadavg())})
    export.write_json(out / "bench.json", {"curve": record})
    print(f"fold curve: {record['points']} points in {record['seconds']:.1f} s wall clock, {record['cpu_seconds']:.1f} s "
          f"CPU ({1e3 * record['cpu_seconds_per_point']:.0f} ms CPU per point; load average {load[0]:.1f} at the start "
          f"on {record['cpu_count']} cores; target {record['target']})"
          + "".join(f"; {e['event']} at omega = {e['omega']:.10g}, Delta = {e['Delta']:.10g}" for e in record["events"]))
    check = record["fold_system"]
    print(f"fold system at all {check['points']} points by {check['checked_by']}: |P(z) - z| <= "
          f"{check['max_residual']:.1e}, |det(M - I)| <= {check['max_det']:.1e}")
    print(f"wrote {out}/bench.json")
    return 0


def unused(args) -> list[Unused]:
    if args.curve:
        return [Unused(dest, "--curve runs only the fold-curve benchmark; leave it out")
                for dest in ("repeats", "ladder_rounds", "ladder_only", "peers", "no_instructions", "fmu", "quick",
                             "auto_only")]
    if args.peers:
        return [Unused("repeats", "--peers runs each setting once per round (the rounds are --ladder-rounds); leave "
                                  "it out"),
                Unused("ladder_only", "--peers runs only the comparison with other solvers; give one of the two"),
                Unused("no_instructions", "--peers counts no instructions; leave it out", harmless=True)]
    if args.auto_only:
        return [Unused("repeats", "--auto-only runs no work-precision cases (its rounds are --ladder-rounds); leave "
                                  "it out"),
                Unused("ladder_only", "--auto-only runs no ladder; give one of the two"),
                Unused("no_instructions", "--auto-only counts no instructions; leave it out", harmless=True)]
    return [Unused("repeats", "--ladder-only runs no work-precision cases (the ladder's rounds are --ladder-rounds); "
                              "leave it out")] if args.ladder_only else []


COMMAND = Command("bench", "work-precision: error vs wall time of every fidelity, solver and setting, beside "
                           "solve_ivp and the compiled floor; the speed targets", options, run, unused)
