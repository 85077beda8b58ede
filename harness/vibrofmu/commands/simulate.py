"""`vibrofmu simulate`: the plant FMU under FMPy, exported, optionally against the reference."""
from vibrofmu.commands.common import (FMU_HELP, OAFM_SETTINGS, SIMULATE_SET_HELP, Command, Unused, UserError,
                                      built_plant, non_negative, out_folder, plant_fmu, positive, progress_printer,
                                      split_set, writable_folder)


def options(p):
    from vibromodel import solvers

    from vibrofmu.analyses.simulate import FIDELITIES, MAX_OUTPUT_MB, SOLVERS

    from vibromodel.auto import DEFAULT_TOLERANCE

    p.add_argument("--fidelity", choices=[*FIDELITIES, "auto"], default="exact",
                   help="plant model; auto: the cheapest rung whose error estimate meets --tolerance")
    p.add_argument("--tolerance", type=positive, default=None,
                   help=f"with --fidelity auto: the bound on max|x - x_exact| (default {DEFAULT_TOLERANCE:g})")
    p.add_argument("--solver", choices=list(SOLVERS), default="adaptive",
                   help=" or ".join(f"{entry.option}: {entry.description}" for entry in solvers.SOLVERS.values()))
    # rtol, stop time and output interval are checked with the scene (simulate.check_inputs: ParameterError)
    p.add_argument("--rtol", type=float, default=1e-8, help="relative tolerance of the adaptive solver")
    p.add_argument("--max-step", type=non_negative, default=0.0, help="RK4 step / adaptive ceiling; 0 = automatic")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SIMULATE_SET_HELP)
    p.add_argument("--stop-time", type=float, default=200.0, help="end of the run, tau")
    p.add_argument("--output-interval", type=float, default=0.1, help="communication step (doStep size)")
    p.add_argument("--max-output-mb", type=positive, default=MAX_OUTPUT_MB,
                   help="refuse up front a run whose results (result.csv, and memory) would exceed this size")
    p.add_argument("--compare", action="store_true", help="compare with the DOP853 rtol 1e-12 reference")
    p.add_argument("--fmu", default=None, help=FMU_HELP)
    p.add_argument("--out", required=True, help="output folder (result.csv, summary.json, x.png)")


def run(args) -> int:
    from vibromodel.analytic import OafmSettings
    from vibromodel.parameters import ParameterError, Scene
    from vibromodel.plant import Settings

    from vibrofmu.analyses.simulate import FIDELITIES, SOLVERS, check_inputs, check_output_size, simulate

    scene_values, oafm_values = split_set(args.set)
    scene = Scene().with_values(**scene_values)
    auto = args.fidelity == "auto"
    settings = Settings(fidelity=0 if auto else FIDELITIES[args.fidelity], solver=SOLVERS[args.solver],
                        rtol=args.rtol, max_step=args.max_step, oafm=OafmSettings(**oafm_values))
    fmu = plant_fmu(args.fmu)
    writable_folder(args.out)
    if 0 < args.stop_time < args.output_interval:
        raise UserError(f"--output-interval {args.output_interval:g} is longer than --stop-time {args.stop_time:g}")
    # bad values raise ParameterError now (the note on the scene is printed when the run starts: simulate)
    try:
        check_inputs(scene, settings, args.stop_time, args.output_interval)
    except ParameterError as error:
        if error.name != "stopTime":
            raise
        advice = (error.reason.replace("set oafm_tau_end <= ", "add --set oafm_tau_end=")  # the FMU's names -> options
                  .replace("fidelity 0-3", "another --fidelity").replace("fidelity 4", "--fidelity analytic"))
        raise UserError(f"--stop-time {args.stop_time:g}: {advice}") from None
    check_output_size(args.stop_time, args.output_interval, args.max_output_mb)  # before anything runs
    tolerance = None
    if auto:  # the FMU chooses (fidelity = -1 and its tolerance); the checks above were the exact model's
        from vibromodel.auto import DEFAULT_TOLERANCE
        tolerance = DEFAULT_TOLERANCE if args.tolerance is None else args.tolerance
    out = out_folder(args.out)
    result, summary, _ = simulate(built_plant(fmu), scene, settings, args.stop_time, args.output_interval, out,
                                  compare=args.compare, progress=progress_printer("simulate"),
                                  auto_tolerance=tolerance)
    if auto:
        refusal = f"parameter tolerance = {tolerance!r}: "
        if summary["fidelity_chosen"] is None and refusal in (result.stop_reason or ""):
            raise UserError(f"--tolerance {tolerance:g}: {result.stop_reason.split(refusal, 1)[1]}")
        print(summary["auto_choice"])
    plotted = ", x.png" if (out / "x.png").exists() else " (no x.png: no run to plot)"
    print(f"wrote {out}/result.csv, summary.json{plotted} ({len(result.time)} points, "
          f"wall time {result.wall_time:.3f} s)")
    if "error" in summary:
        e = summary["error"]
        print(f"max |x - x_ref| = {e['max_abs_error_x']:.3e}, RMS = {e['rms_error_x']:.3e}; "
              f"max |v - v_ref| = {e['max_abs_error_v']:.3e}")
    if not result.completed:
        import sys

        import math

        where = (f"stopped at tau = {result.end_time:g} before the stop time {args.stop_time:g}"
                 if math.isfinite(result.end_time) else "failed before its first step")
        print(f"error: the FMU {where}: {result.stop_reason}", file=sys.stderr)
        return 1
    return 0


def unused(args) -> list[Unused]:
    """The settings the fidelity and solver asked for do not read (fidelities and solvers registries)."""
    from vibromodel import fidelities, solvers

    from vibrofmu.analyses.simulate import FIDELITIES, SOLVERS

    if args.fidelity not in FIDELITIES:  # a fidelity chosen at run time: no setting is known to be unused
        return []
    level = fidelities.entry(FIDELITIES[args.fidelity])
    solver = solvers.solver_entry(SOLVERS[args.solver])
    where = f"--fidelity {args.fidelity} ({level.name}) does not read it; leave it out"
    found = []
    if args.tolerance is not None:
        found.append(Unused("tolerance", f"--fidelity {args.fidelity} does not read it (only --fidelity auto "
                                         "chooses by a tolerance); leave it out"))
    if not level.integrated:  # an open-loop level: no solver steps Eq. 3 or 7
        found.append(Unused("solver", f"--fidelity {args.fidelity} ({level.name}) does not read it (only the "
                                      "fidelities that integrate the equation of motion do); leave it out"))
    if not level.uses_rtol:
        found.append(Unused("rtol", where))
        # the levels that integrate nothing (no rtol) have no step either
        found.append(Unused("max_step", where))
    elif level.integrated and "rtol" not in dict(solver.parameters):
        found.append(Unused("rtol", f"--solver {args.solver} ({solver.description}) has no tolerance: --max-step "
                                    f"sets its step; leave --rtol out"))
    if not level.oafm_settings:
        found += [Unused("set", f"--fidelity {args.fidelity} does not read it (only --fidelity analytic fits the "
                                f"OAFM solution); leave it out", shown=f"--set {item}")
                  for item in args.set if item.partition("=")[0].strip() in OAFM_SETTINGS]
    return found


COMMAND = Command("simulate", "run the plant FMU under FMPy and export the results", options, run, unused)
