"""`vibrofmu stability`: steady vibrations against omega by the slow flow, shooting/Floquet and FMU sweeps."""
import math
import sys

from vibrofmu.commands.common import (Command, Unused, UserError, built_plant, count, failed,
                                      out_folder, parse_set, plant_fmu, positive, study_fmu_options)


def options(p):
    p.add_argument("--omega-range", nargs=3, type=positive, metavar=("LO", "HI", "N"),
                   help="frequency grid (default: omega_e -+ max(3 mu, 3 |kappa(r_peak)|), 201 points)")
    p.add_argument("--sweep-points", type=count, default=25, help="frequencies per FMU sweep direction")
    study_fmu_options(p, ", for the sweeps", "skip the FMU sweeps and the fidelity-3 check",
                      "output folder (summary.json, frequency_response.png)")


def run(args) -> int:
    from vibromodel.averaging import averaged, steady_states
    from vibromodel.parameters import Scene, validate

    from vibrofmu.analyses.stability import default_range, multiplier_error_note, stability_study, write_study

    scene = Scene().with_values(**parse_set(args.set))
    validate(scene)
    if scene.omega <= 0:
        raise UserError(f"the stability study needs a forcing frequency omega > 0, got omega = {scene.omega:g}")
    model = averaged(scene)
    if args.omega_range:
        (lo, hi), n = args.omega_range[:2], args.omega_range[2]
        if not (0 < lo < hi and math.isfinite(hi) and n == int(n) and n >= 3):
            raise UserError(f"--omega-range {' '.join(f'{v:g}' for v in args.omega_range)}: need 0 < LO < HI "
                            f"and an integer N >= 3")
        n = int(n)
    else:
        (lo, hi), n = default_range(model), 201
    fmu = None if args.no_fmu else plant_fmu(args.fmu)
    out = out_folder(args.out)
    fmu = fmu and built_plant(fmu)

    def progress(label, done, total):
        if done == total or done % max(1, total // 10) == 0:
            print(f"{label}: {done}/{total}", file=sys.stderr, flush=True)

    study = stability_study(scene, (lo, hi), n, fmu=fmu, sweep_points=args.sweep_points, progress=progress)
    write_study(study, out)
    summary = study["summary"]
    states = steady_states(model.flow(), model.r_max)
    print(f"omega = {scene.omega:.8g} (omega_e = {model.omega_e:.8g}): "
          + ", ".join(f"r = {s.r:.5g} {s.kind}" for s in states))
    agree = summary["classification_agreement"]
    excluded = f", points within {agree['excluded_margin']:.2g} of a fold excluded" if study["folds"] else ""
    print(f"slow flow vs Floquet classification: {agree['points_agreeing']}/{agree['points_compared']} grid points "
          f"agree ({100 * agree['fraction']:.1f} %){excluded}")
    errors = summary["slow_flow_vs_shooting"]
    print(f"slow flow vs shooting: max relative r error {errors['max_relative_r_error']:.2e} (omega "
          f"{errors['at_omega']:.6g}), max |exp(lambda T) - rho| {errors['max_multiplier_error']:.2e} (omega "
          f"{errors['at_omega_multiplier']:.6g})")
    note = multiplier_error_note(scene, model, errors["at_omega_multiplier"])
    if note:
        print(note)
    for row in summary["fold_frequencies"]["folds"]:
        print("fold: " + ", ".join(f"{k} {v:.8g}" for k, v in row.items() if not k.startswith("r_")))
    for direction, sweep in ((d, summary["fmu_sweeps"][d]) for d in ("up", "down") if "fmu_sweeps" in summary):
        print(f"FMU sweep {direction}: {sum(sweep['settled'])}/{len(sweep['omega'])} points settled; max relative "
              f"difference to the slow flow {sweep['max_relative_difference_to_slow_flow']:.2e} at the "
              f"{sweep['points_compared']} settled points away from the folds")
    check = summary.get("fidelity_3")
    if failed(check, "fidelity 3 check"):
        return 1
    if check:
        print(f"fidelity 3 vs 0 after the transient: max |dx| = {check['max_abs_error_after_transient']:.2e} "
              f"({100 * check['relative_to_amplitude']:.2f} % of the amplitude); speed-up end to end "
              f"{check['end_to_end_speedup']:.1f}x, model {check['model_speedup']:.1f}x, "
              f"integration alone {check['integration_speedup']:.1f}x")
    print(f"wrote {out}/summary.json, frequency_response.png")
    return 0


def unused(args) -> list[Unused]:
    return [Unused(dest, "--no-fmu skips the FMU sweeps; leave one of them out") for dest in ("fmu", "sweep_points")
            if args.no_fmu]


COMMAND = Command("stability", "steady vibrations vs omega: slow flow, shooting/Floquet, FMU sweeps", options, run,
                  unused)
