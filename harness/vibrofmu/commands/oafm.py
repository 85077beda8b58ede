"""`vibrofmu oafm`: the OAFM analytic solution fitted, against the reference, and the FMU's fidelity 4."""
from vibrofmu.commands.common import (Command, Unused, built_plant, count, failed,
                                      non_negative, non_negative_int, out_folder, parse_set, plant_fmu, positive,
                                      study_fmu_options)


def options(p):
    from vibromodel.analytic import OafmSettings
    from vibromodel.oafm import Grid
    from vibromodel.oafm_bases import FAMILIES

    p.add_argument("--basis", choices=list(FAMILIES), default="harmonic", help="basis family of the fit")
    p.add_argument("--order", type=count, default=OafmSettings.order, help="harmonic basis order (1..8)")
    p.add_argument("--tau-star", type=non_negative, default=0.0, help="end of the transient domain; 0 = automatic")
    p.add_argument("--tau-end", type=non_negative, default=0.0,
                   help="end of the steady domain's fit; 0 = automatic")
    p.add_argument("--panel", type=positive, default=Grid.panel, help="collocation panel length")
    p.add_argument("--nodes", type=count, default=Grid.nodes, help="Gauss-Legendre nodes per panel")
    p.add_argument("--study-max-order", type=non_negative_int, default=6,
                   help="convergence study up to this order; 0 = none")
    study_fmu_options(p, ", checked at fidelity 4", "skip the FMU check",
                      "output folder (summary.json, oafm.csv, plots)")


def run(args) -> int:
    from vibromodel.analytic import OafmSettings
    from vibromodel.oafm import Grid
    from vibromodel.parameters import Scene, validate

    from vibrofmu.analyses.oafm_study import run_oafm

    scene = Scene().with_values(**parse_set(args.set))
    validate(scene)
    settings = OafmSettings(basis=args.basis, order=args.order, tau_star=args.tau_star, tau_end=args.tau_end,
                            grid=Grid(panel=args.panel, nodes=args.nodes))
    orders = range(1, args.study_max_order + 1) if args.study_max_order else ()
    fmu = None if args.no_fmu or args.basis != "harmonic" else plant_fmu(args.fmu)
    out = out_folder(args.out)
    summary = run_oafm(scene, settings, out, study_orders=orders, fmu=fmu and built_plant(fmu))
    for domain in summary["domains"]:
        lo, hi = domain["interval"]
        print(f"[{lo:g}, {hi:g}] {domain['basis']}: {len(domain['C'])} C_i, RMS residual "
              f"{domain['residual_rms']:.2e}, max |x~ - x_ref| = {domain['error']['max_abs_error']:.3e}")
    extrapolation = summary["extrapolation"]
    print(f"beyond the fit, [{extrapolation['interval'][0]:g}, {extrapolation['interval'][1]:g}]: "
          f"max |x~ - x_ref| = {extrapolation['max_abs_error']:.3e}")
    print(summary["verdict"])
    check = summary.get("fmu_check")
    if failed(check, "FMU fidelity 4"):
        return 1
    if check:
        print(f"FMU fidelity 4 vs this fit: max |dx| = {check['max_abs_difference_x']:.2e}; cost per doStep "
              f"{1e6 * check['seconds_per_step_fidelity_4']:.1f} us = {check['cost_ratio_4_over_0']:.2f} x fidelity 0")
    print(f"wrote {out}/summary.json, oafm.csv, oafm.png" + (", convergence.png" if orders else ""))
    return 0


def unused(args) -> list[Unused]:
    """--fmu without the FMU check (--no-fmu, or the paper's basis, which the FMU's fidelity 4 does not fit); the
    harmonic basis's order with the paper's basis."""
    found = []
    if args.no_fmu:
        found.append(Unused("fmu", "--no-fmu skips the FMU check; leave one of them out"))
    if args.basis != "harmonic":
        found += [Unused("order", f"--basis {args.basis} has no order (only the harmonic basis does); leave it out"),
                  Unused("fmu", f"the FMU's fidelity 4 fits the harmonic basis: with --basis {args.basis} there is "
                                "no FMU check; leave it out")]
    return found


COMMAND = Command("oafm", "OAFM analytic solution: fit, compare with the reference, reproduce the paper", options, run,
                  unused)
