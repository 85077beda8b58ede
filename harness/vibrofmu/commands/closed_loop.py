"""`vibrofmu closed-loop`: the adaptive controller on the plant, as one FMU or as three co-simulated."""
import sys
from pathlib import Path

from vibrofmu import paths
from vibrofmu.commands.common import (CLOSED_LOOP_NAME, Command, Unused, UserError, built_all, checked_fmu,
                                      out_folder, positive, progress_printer)


# values per output point: bounds of result.csv's columns (measured 19 and 30, with room for a few new outputs;
# tests/harness/test_cli.py checks they bound the real ones)
COLUMNS = {"monolithic": 25, "cosim": 40}
MAX_OUTPUT_MB = 500.0  # as simulate's


def options(p):
    from vibromodel.control import Law
    from vibromodel.tracking import ReferenceKind

    p.add_argument("--mode", choices=["monolithic", "cosim"], default="monolithic",
                   help="one closed-loop FMU, or the plant, controller and reference FMUs co-simulated")
    p.add_argument("--H", type=positive, default=None,
                   help="communication step (cosim; default: the scene's) / output interval (monolithic; default 0.1)")
    p.add_argument("--law", choices=[law.label for law in Law], default=None,
                   help="control law (default: paper-corrected; cosim: the scene's)")
    p.add_argument("--reference", choices=[k.name.lower() for k in ReferenceKind], default="errata",
                   help="monolithic: reference trajectory")
    p.add_argument("--scene", default=str(paths.DEFAULT_SCENE),
                   help=f"cosim: scene file (TOML or JSON; default: the {paths.DEFAULT_SCENE.name} shipped with "
                        "vibrofmu)")
    p.add_argument("--stop-time", type=positive, default=None, help="end of the run (default: 200 monolithic, "
                                                                    "the scene's for cosim)")
    p.add_argument("--no-study", action="store_true", help="cosim: skip the H convergence study")
    p.add_argument("--max-output-mb", type=positive, default=MAX_OUTPUT_MB,
                   help="refuse a run whose results (in memory and result.csv) would exceed this many MB "
                        f"(default: {MAX_OUTPUT_MB:g})")
    p.add_argument("--fmu-dir", default=None, help="where the three FMUs are (default: ./build; built when missing)")
    p.add_argument("--out", required=True, help="output folder (result.csv, summary.json, plots)")


def run(args) -> int:
    from vibromodel.control import Law
    from vibromodel.tracking import ReferenceKind

    from vibrofmu.analyses import closed_loop
    from vibrofmu.analyses.simulate import check_output_size
    from vibrofmu.hosts.cosim import SceneError, load_scene

    fmu_dir = Path(args.fmu_dir) if args.fmu_dir else paths.build_dir()
    if fmu_dir.exists() and not fmu_dir.is_dir():
        raise UserError(f"--fmu-dir {fmu_dir} is not a folder")
    if args.mode == "cosim" and not Path(args.scene).is_file():
        raise UserError(f"no scene file at {args.scene}")
    H, stop_time = args.H or 0.1, args.stop_time or 200.0  # monolithic; a cosim takes the scene's defaults
    if args.mode == "monolithic" and H > stop_time:
        raise UserError(f"--H {H:g} is longer than the stop time {stop_time:g}")
    if args.mode == "monolithic":  # before anything runs (a cosim: once its scene gives H and the stop time)
        check_output_size(stop_time, H, args.max_output_mb, COLUMNS["monolithic"], "--H")
    out = out_folder(args.out)
    built_all(fmu_dir)
    law = Law.from_label(args.law) if args.law else None
    progress = progress_printer("closed-loop")
    if args.mode == "monolithic":
        values = {"law": int(law or Law.PAPER_CORRECTED), "reference": int(ReferenceKind[args.reference.upper()])}
        fmu = checked_fmu(fmu_dir / CLOSED_LOOP_NAME, "HertzEAClosedLoop", fmi2_cs=True)
        result = closed_loop.monolithic(fmu, values, stop_time, H, progress)
        theta = closed_loop.true_values({})
        title = f"HertzEAClosedLoop: {(law or Law.PAPER_CORRECTED).label}, reference {args.reference}"
        summary = {"mode": "monolithic", "parameters": values, "H": H, "rtol": closed_loop.TOLERANCE,
                   **closed_loop.summarise(result, theta)}
    else:
        try:
            scene = closed_loop.with_law(load_scene(args.scene, fmu_dir).with_settings(
                step=args.H, stop_time=args.stop_time), law)
        except SceneError as error:
            raise UserError(str(error)) from None
        if scene.step > scene.stop_time:
            raise UserError(f"the communication step H = {scene.step:g} is longer than the stop time "
                            f"{scene.stop_time:g}")
        check_output_size(scene.stop_time, scene.step, args.max_output_mb, COLUMNS["cosim"], "--H")
        plant = next((spec.parameters for spec in scene.fmus if spec.name == "plant"), {})
        theta = closed_loop.true_values(plant)
        result = closed_loop.cosimulation(scene, progress)
        title = f"co-simulation {Path(args.scene).name}: H = {scene.step:g}, {scene.ordering}"
        summary = {"mode": "cosim", "scene": str(args.scene), "H": scene.step, "ordering": scene.ordering,
                   **closed_loop.summarise(result, theta), "fmu_log": result["log"]}
        if not args.no_study:
            print("convergence study (H = " + ", ".join(f"{h:g}" for h in closed_loop.STUDY_STEPS) + ") ...",
                  file=sys.stderr)
            summary["convergence"] = closed_loop.convergence_study(scene, fmu_dir / CLOSED_LOOP_NAME)
    closed_loop.write_results(out, result, summary, theta, title)
    plots = [name for name in ("tracking.png", "errors.png", "lyapunov.png", "estimates.png") if (out / name).exists()]
    print(f"wrote {out}/" + ", ".join(["result.csv", "summary.json", *plots])
          + ("" if plots else " (no plots: the run stopped before its second output)"))
    if "V_end" in summary:
        print(f"V: {summary['V_start']:.6e} -> {summary['V_end']:.6e}, max increase between outputs "
              f"{summary['max_V_increase']:.3e}; final |e1| = {summary['final_abs_e1']:.3e}, "
              f"|e2| = {summary['final_abs_e2']:.3e}")
    for ordering, rows in summary.get("convergence", {}).get("table", {}).items():
        print(f"{ordering}: " + ", ".join(study_cell(row) for row in rows))
    if not result["completed"]:
        print(f"error: the run stopped before the stop time: {result['stop_reason']}", file=sys.stderr)
        return 1
    return 0


def study_cell(row: dict) -> str:
    """One H of the convergence study: the error (and order), or that the run stopped and where."""
    if not row["completed"]:
        return f"H={row['H']:g}: stopped ({row['stop_reason']})"
    order = f" (order {row['order']:.2f})" if "order" in row else ""
    return f"H={row['H']:g}: {row['max_abs_error_x']:.2e}{order}"


def unused(args) -> list[Unused]:
    """The options of the other mode."""
    if args.mode == "cosim":
        return [Unused("reference", "only --mode monolithic reads it (a co-simulation's reference is the scene "
                                    "file's reference FMU); leave it out")]
    return [Unused(dest, "only --mode cosim reads it; add --mode cosim or leave it out")
            for dest in ("scene", "no_study")]


COMMAND = Command("closed-loop", "adaptive Lyapunov controller on the plant: monolithic FMU or co-simulation",
                  options, run, unused)
