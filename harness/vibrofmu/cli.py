"""The `vibrofmu` command: build, simulate, closed-loop, demo, oafm, stability, bench, doctor."""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

from vibromodel.analytic import OafmSettings
from vibromodel.averaging import averaged, steady_states
from vibromodel.control import Law
from vibromodel.oafm import Grid
from vibromodel.oafm_bases import FAMILIES
from vibromodel.parameters import ParameterError, Scene
from vibromodel.plant import Settings
from vibromodel.tracking import ReferenceKind

from . import bench, closed_loop, doctor
from .build import BUILD_DIR, CLOSED_LOOP_FMU, CONTROLLER_FMU, PLANT_FMU, build_all, build_plant
from .cosim import SceneError, load_scene
from .demo import run_demo
from .oafm_study import run_oafm
from .simulate import FIDELITIES, SOLVERS, simulate
from .stability import default_range, stability_study, write_study


def parse_set(items: list[str]) -> dict[str, float]:
    """NAME=VALUE pairs -> {name: float}; unknown names and non-numbers raise ParameterError."""
    values = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep:
            raise ParameterError(item, None, "expected NAME=VALUE")
        try:
            values[name.strip()] = float(text)
        except ValueError:
            raise ParameterError(name.strip(), text, "not a number") from None
    Scene().with_values(**values)  # unknown names fail here
    return values


def progress_printer(label: str):
    """Print progress every 10 % on stderr for long runs."""
    state = {"next": 10}

    def progress(done: int, total: int):
        if total >= 20000 and 100 * done >= state["next"] * total:
            print(f"{label}: {state['next']} %", file=sys.stderr, flush=True)
            state["next"] += 10

    return progress


def ensure_fmu(path: Path) -> Path:
    if not path.exists():
        print(f"building {path} ...", file=sys.stderr)
        build_plant(path.parent)
    return path


def cmd_build(args) -> int:
    for fmu in build_all(Path(args.out_dir)):
        print(f"built {fmu}")
    return 0


DEFAULT_SCENE = Path(__file__).parent / "scenes" / "closed_loop.toml"


def cmd_closed_loop(args) -> int:
    fmu_dir = Path(args.fmu_dir)
    if not all((fmu_dir / fmu.name).exists() for fmu in (PLANT_FMU, CONTROLLER_FMU, CLOSED_LOOP_FMU)):
        print(f"building the FMUs into {fmu_dir} ...", file=sys.stderr)
        build_all(fmu_dir)
    law = Law.from_label(args.law) if args.law else None
    progress = progress_printer("closed-loop")
    if args.mode == "monolithic":
        values = {"law": int(law or Law.PAPER_CORRECTED), "reference": int(ReferenceKind[args.reference.upper()])}
        H, stop_time = args.H or 0.1, args.stop_time or 200.0
        result = closed_loop.monolithic(fmu_dir / CLOSED_LOOP_FMU.name, values, stop_time, H, progress)
        theta = closed_loop.true_values({})
        title = f"HertzEAClosedLoop: {(law or Law.PAPER_CORRECTED).label}, reference {args.reference}"
        summary = {"mode": "monolithic", "parameters": values, "H": H, "rtol": closed_loop.TOLERANCE,
                   **closed_loop.summarise(result, theta)}
    else:
        try:
            scene = closed_loop.with_law(load_scene(args.scene, fmu_dir).with_settings(
                step=args.H, stop_time=args.stop_time), law)
        except SceneError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        plant = next((spec.parameters for spec in scene.fmus if spec.name == "plant"), {})
        theta = closed_loop.true_values(plant)
        result = closed_loop.cosimulation(scene, progress)
        title = f"co-simulation {Path(args.scene).name}: H = {scene.step:g}, {scene.ordering}"
        summary = {"mode": "cosim", "scene": str(args.scene), "H": scene.step, "ordering": scene.ordering,
                   **closed_loop.summarise(result, theta), "fmu_log": result["log"]}
        if not args.no_study:
            print("convergence study (H = " + ", ".join(f"{h:g}" for h in closed_loop.STUDY_STEPS) + ") ...",
                  file=sys.stderr)
            summary["convergence"] = closed_loop.convergence_study(scene, fmu_dir / CLOSED_LOOP_FMU.name)
    out = Path(args.out)
    closed_loop.write_results(out, result, summary, theta, title)
    print(f"wrote {out}/result.csv, summary.json, tracking.png, errors.png, lyapunov.png, estimates.png")
    if "V_end" in summary:
        print(f"V: {summary['V_start']:.6e} -> {summary['V_end']:.6e}, max increase between outputs "
              f"{summary['max_V_increase']:.3e}; final |e1| = {summary['final_abs_e1']:.3e}, "
              f"|e2| = {summary['final_abs_e2']:.3e}")
    for ordering, rows in summary.get("convergence", {}).get("table", {}).items():
        print(f"{ordering}: " + ", ".join(f"H={r['H']:g}: {r['max_abs_error_x']:.2e}"
                                          + (f" (order {r['order']:.2f})" if "order" in r else "") for r in rows))
    if not result["completed"]:
        print(f"error: the run stopped before the stop time: {result['stop_reason']}", file=sys.stderr)
        return 1
    return 0


def cmd_simulate(args) -> int:
    scene = Scene().with_values(**parse_set(args.set))
    settings = Settings(fidelity=FIDELITIES[args.fidelity], solver=SOLVERS[args.solver], rtol=args.rtol,
                        max_step=args.max_step)
    fmu = ensure_fmu(Path(args.fmu))
    run, summary, _ = simulate(fmu, scene, settings, args.stop_time, args.output_interval, Path(args.out),
                            compare=args.compare, progress=progress_printer("simulate"))
    print(f"wrote {args.out}/result.csv, summary.json, x.png ({len(run.time)} points, "
          f"wall time {run.wall_time:.3f} s)")
    if "error" in summary:
        e = summary["error"]
        print(f"max |x - x_ref| = {e['max_abs_error_x']:.3e}, RMS = {e['rms_error_x']:.3e}; "
              f"max |v - v_ref| = {e['max_abs_error_v']:.3e}")
    if not run.completed:
        print(f"error: the FMU stopped at tau = {run.end_time:g} before the stop time {args.stop_time:g}: "
              f"{run.stop_reason}", file=sys.stderr)
        return 1
    return 0


def cmd_demo(args) -> int:
    return run_demo(Path(args.out))


def cmd_oafm(args) -> int:
    scene = Scene().with_values(**parse_set(args.set))
    settings = OafmSettings(basis=args.basis, order=args.order, tau_star=args.tau_star, tau_end=args.tau_end,
                            grid=Grid(panel=args.panel, nodes=args.nodes))
    orders = range(1, args.study_max_order + 1) if args.study_max_order else ()
    fmu = None if args.no_fmu else ensure_fmu(Path(args.fmu))
    summary = run_oafm(scene, settings, Path(args.out), study_orders=orders, fmu=fmu)
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
    print(f"wrote {args.out}/summary.json, oafm.csv, oafm.png" + (", convergence.png" if orders else ""))
    return 0


def failed(check: dict | None, label: str) -> bool:
    """A check that could not run (an FMU stopped): say why on stderr."""
    if check and "error" in check:
        print(f"error: {label}: {check['error']}", file=sys.stderr)
        return True
    return False


def cmd_stability(args) -> int:
    scene = Scene().with_values(**parse_set(args.set))
    model = averaged(scene)
    lo, hi = (args.omega_range[0], args.omega_range[1]) if args.omega_range else default_range(model)
    n = int(args.omega_range[2]) if args.omega_range else 201
    if not (0 < lo < hi and n >= 3):
        raise ParameterError("omega-range", args.omega_range, "need 0 < LO < HI and N >= 3")
    fmu = None if args.no_fmu else ensure_fmu(Path(args.fmu))

    def progress(label, done, total):
        if done == total or done % max(1, total // 10) == 0:
            print(f"{label}: {done}/{total}", file=sys.stderr, flush=True)

    study = stability_study(scene, (lo, hi), n, fmu=fmu, sweep_points=args.sweep_points, progress=progress)
    write_study(study, Path(args.out))
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
    w, k1 = errors["at_omega_multiplier"], model.omega_e**2
    if w == w and k1 > scene.mu**2 / 4:  # a number (the grid had orbits) and an underdamped linearisation
        period = 2 * math.pi / w
        phase = (w - math.sqrt(k1 - scene.mu**2 / 4) - (w * w - k1) / (2 * w)) * period
        print(f"  (expected far from resonance: the slow flow turns at (omega^2 - k1)/(2 omega) instead of "
              f"omega - sqrt(k1 - mu^2/4); the phase error per period gives |exp(lambda T) - rho| ~ "
              f"exp(-mu T/2) 2|sin(dphi/2)| = {math.exp(-scene.mu * period / 2) * abs(2 * math.sin(phase / 2)):.2e} "
              f"at omega {w:.6g}; see docs/numerics.md)")
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
    print(f"wrote {args.out}/summary.json, frequency_response.png")
    return 0


def cmd_bench(args) -> int:
    from . import extremes

    fmu = ensure_fmu(Path(args.fmu))
    out = Path(args.out)
    summary = bench.run_bench(fmu, out, quick=args.quick, repeats=args.repeats,
                              extreme_rows=lambda quick: extremes.extreme_rows(quick, fmu),
                              progress=lambda line: print(line, file=sys.stderr, flush=True))
    for line in bench.summary_lines(summary):
        print(line)
    print(f"{len(summary['cases'])} cases in {summary['bench']['seconds']:.0f} s; wrote {out}/bench.json, "
          f"{out}/work_precision.png")
    return 0


def cmd_doctor(args) -> int:
    with tempfile.TemporaryDirectory() as work_dir:
        env, result = doctor.check(Path(args.fmu), Path(work_dir))
    print(doctor.export_lines(env))
    if not result.ok:
        print(f"error: {result.message}", file=sys.stderr)
        return 1
    print(f"# ok: {result.message}")
    return 0


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="vibrofmu", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("build", help="build the plant, controller and closed-loop FMUs into build/")
    p.add_argument("--out-dir", default=str(PLANT_FMU.parent))
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("simulate", help="run the plant FMU under FMPy and export the results")
    p.add_argument("--fidelity", choices=list(FIDELITIES), default="exact")
    p.add_argument("--solver", choices=list(SOLVERS), default="adaptive")
    p.add_argument("--rtol", type=float, default=1e-8)
    p.add_argument("--max-step", type=float, default=0.0, help="RK4 step / adaptive ceiling; 0 = automatic")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="scene parameter (mu, Delta, omega, Omega, alpha, beta, gamma, R, x_start, v_start)")
    p.add_argument("--stop-time", type=float, default=200.0)
    p.add_argument("--output-interval", type=float, default=0.1)
    p.add_argument("--compare", action="store_true", help="compare with the DOP853 rtol 1e-12 reference")
    p.add_argument("--fmu", default=str(PLANT_FMU))
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("closed-loop", help="adaptive Lyapunov controller on the plant: monolithic FMU or co-simulation")
    p.add_argument("--mode", choices=["monolithic", "cosim"], default="monolithic")
    p.add_argument("--H", type=float, default=None,
                   help="communication step (cosim; default: the scene's) / output interval (monolithic; default 0.1)")
    p.add_argument("--law", choices=[law.label for law in Law], default=None,
                   help="control law (default paper-corrected; cosim: the scene's)")
    p.add_argument("--reference", choices=[k.name.lower() for k in ReferenceKind], default="errata",
                   help="monolithic: reference trajectory")
    p.add_argument("--scene", default=str(DEFAULT_SCENE), help="cosim: scene file (TOML or JSON)")
    p.add_argument("--stop-time", type=float, default=None, help="default: 200 (monolithic) / the scene's")
    p.add_argument("--no-study", action="store_true", help="cosim: skip the H convergence study")
    p.add_argument("--fmu-dir", default=str(BUILD_DIR), help="where the FMUs are (built when missing)")
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_closed_loop)

    p = sub.add_parser("oafm", help="OAFM analytic solution: fit, compare with the reference, reproduce the paper")
    p.add_argument("--basis", choices=list(FAMILIES), default="harmonic")
    p.add_argument("--order", type=int, default=OafmSettings.order, help="harmonic basis order (1..8)")
    p.add_argument("--tau-star", type=float, default=0.0, help="end of the transient domain; 0 = automatic")
    p.add_argument("--tau-end", type=float, default=0.0, help="end of the steady domain's fit; 0 = automatic")
    p.add_argument("--panel", type=float, default=Grid.panel, help="collocation panel length")
    p.add_argument("--nodes", type=int, default=Grid.nodes, help="Gauss-Legendre nodes per panel")
    p.add_argument("--study-max-order", type=int, default=6, help="convergence study up to this order; 0 = none")
    p.add_argument("--fmu", default=str(PLANT_FMU), help="plant FMU checked at fidelity 4 (built when missing)")
    p.add_argument("--no-fmu", action="store_true", help="skip the FMU check")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="scene parameter")
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_oafm)

    p = sub.add_parser("stability", help="steady vibrations vs omega: slow flow, shooting/Floquet, FMU sweeps")
    p.add_argument("--omega-range", nargs=3, type=float, metavar=("LO", "HI", "N"),
                   help="frequency grid (default: omega_e -+ max(3 mu, 3 |kappa(r_peak)|), 201 points)")
    p.add_argument("--sweep-points", type=int, default=25, help="frequencies per FMU sweep direction")
    p.add_argument("--fmu", default=str(PLANT_FMU), help="plant FMU for the sweeps (built when missing)")
    p.add_argument("--no-fmu", action="store_true", help="skip the FMU sweeps and the fidelity-3 check")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="scene parameter")
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_stability)

    p = sub.add_parser("bench", help="work-precision: error vs wall time of every fidelity, solver and setting, "
                                     "beside solve_ivp and the compiled floor; the speed targets")
    p.add_argument("--quick", action="store_true", help="tau in [0, 200], fewer settings, 1 timed repeat")
    p.add_argument("--repeats", type=int, default=None, help="timed runs per case after the warm-up "
                                                             "(default 3; --quick 1)")
    p.add_argument("--fmu", default=str(PLANT_FMU), help="plant FMU (built when missing)")
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("demo", help="build + simulate + compare on the paper's example (Omega = 2)")
    p.add_argument("--out", default="out/demo")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("doctor", help="print the environment a C host needs for FMU, and check it with a C host")
    p.add_argument("fmu")
    p.set_defaults(func=cmd_doctor)
    from . import container, report, ssp  # light modules: heavy imports happen inside their commands
    ssp.add_parser(sub); container.add_parser(sub); report.add_parser(sub)
    from .study import add_parser as add_study_parser  # issue 16: harness/vibrofmu/study/
    add_study_parser(sub)
    return parser


def main(argv=None) -> int:
    args = make_parser().parse_args(argv)
    try:
        return args.func(args)
    except ParameterError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
