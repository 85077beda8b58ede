"""The `vibrofmu` command: build, simulate, closed-loop, demo, oafm, stability, bench, doctor.

`vibrofmu --help` stays fast: this module imports only the standard library and vibromodel.parameters at the
top; each command imports what it needs (numpy, scipy, matplotlib, FMPy, the bench) when it runs, and the
options of a sub-command are only defined when that sub-command is on the command line (make_parser). A
module adding a sub-command hooks in with one call in make_parser and keeps its imports inside its command.

A user mistake (a bad option value, a missing or wrong file, an output folder that cannot be made) ends the
command with one line `error: ...` on stderr and exit code 2, before anything long runs; a run that stops
early (pull-in, a failing FMU) exits with 1.
"""
from __future__ import annotations

import argparse
import math
import os
import shlex
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree

from vibromodel.parameters import ParameterError

from vibrofmu import paths

PLANT_NAME = "HertzEAOscillator.fmu"
CONTROLLER_NAME = "AdaptiveLyapunovController.fmu"
CLOSED_LOOP_NAME = "HertzEAClosedLoop.fmu"
PLANT_MODEL = "HertzEAOscillator"
DEFAULT_SCENE = paths.SCENES_DIR / "closed_loop.toml"


class UserError(Exception):
    """A mistake in the command line or its files: printed as one line, exit code 2."""


# -- option types: each rejects a bad value with a one-line reason ------------------------------------------
def _number(kind, test, condition):
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
        if not (math.isfinite(value) and test(value)):
            raise argparse.ArgumentTypeError(f"must be {condition}, got {text}")
        return value

    parse.__name__ = kind.__name__
    return parse


positive = _number(float, lambda v: v > 0, "a finite number > 0")
non_negative = _number(float, lambda v: v >= 0, "a finite number >= 0")
count = _number(int, lambda v: v >= 1, "an integer >= 1")
non_negative_int = _number(int, lambda v: v >= 0, "an integer >= 0")


class HelpFormatter(argparse.HelpFormatter):
    """Appends "(default: X)" to an option's help unless the help already says its default or the option is
    a flag (off by default)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if ("default" in text or not action.option_strings or action.default is None or action.default is False
                or action.default == [] or action.default is argparse.SUPPRESS):
            return text
        return f"{text} (default: %(default)s)"


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit code 2) and HelpFormatter; sub-commands use the same class."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message):
        self.exit(2, f"error: {self.prog}: {message} (see {self.prog} --help)\n")


# -- checks of user-given paths --------------------------------------------------------------------------
def checked_fmu(path: Path, model: str | None = None) -> Path:
    """`path` if it is an FMU file (a zip archive with modelDescription.xml) of `model` (its modelName; None:
    any); UserError otherwise."""
    if not path.exists():
        raise UserError(f"no FMU at {path}")
    if not path.is_file():
        raise UserError(f"{path} is not a file (an FMU is a .fmu file)")
    try:
        with zipfile.ZipFile(path) as archive:
            name = ElementTree.fromstring(archive.read("modelDescription.xml")).get("modelName")
    except (zipfile.BadZipFile, KeyError, ElementTree.ParseError):
        raise UserError(f"{path} is not an FMU (no zip archive with a modelDescription.xml)") from None
    except OSError as error:
        raise UserError(f"cannot read {path}: {error.strerror}") from None
    if model is not None and name != model:
        raise UserError(f"{path} is the FMU of {name}; this command needs {model}")
    return path


def plant_fmu(given: str | None) -> Path:
    """The plant FMU the user named (checked now: it must exist and be the plant's), or the default
    ./build/HertzEAOscillator.fmu (built_plant builds it when missing, once the other checks passed)."""
    if given is not None:
        return checked_fmu(Path(given), PLANT_MODEL)
    return paths.build_dir() / PLANT_NAME


def built_plant(path: Path) -> Path:
    """`path` (from plant_fmu), built first when it is the missing default."""
    if not path.exists():
        from vibrofmu.fmus.build import build_plant

        print(f"building {path} ...", file=sys.stderr)
        _say_compiled_parts()
        build_plant(path.parent)
    return checked_fmu(path, PLANT_MODEL)


def _say_compiled_parts() -> None:
    from vibrofmu.fmus.build import compiled_parts

    line = compiled_parts()
    if line:
        print(line, file=sys.stderr)


def writable_folder(path: str) -> Path:
    """`path` if the output folder exists or can be created there (nothing is created); UserError otherwise."""
    folder = Path(path)
    for parent in (folder, *folder.parents):
        if parent.exists():
            if parent == folder and not folder.is_dir():
                raise UserError(f"cannot use {folder} as the output folder: a file of that name exists")
            if not parent.is_dir():
                raise UserError(f"cannot create the output folder {folder}: {parent} is not a folder")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise UserError(f"cannot create the output folder {folder}: {parent} is not writable")
            break
    return folder


def out_folder(path: str) -> Path:
    """The output folder, created now (a folder that cannot be made is a UserError before anything runs)."""
    folder = Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise UserError(f"cannot use {folder} as the output folder: a file of that name exists") from None
    except OSError as error:
        raise UserError(f"cannot create the output folder {folder}: {error.strerror}") from None
    return folder


def parse_set(items: list[str]) -> dict[str, float]:
    """NAME=VALUE pairs -> {name: float}; a missing '=', unknown names and non-numbers raise UserError."""
    from vibromodel.parameters import Scene

    values = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep:
            raise UserError(f"--set {item}: expected NAME=VALUE, e.g. --set R=2")
        try:
            values[name.strip()] = float(text)
        except ValueError:
            raise ParameterError(name.strip(), text, "not a number") from None
    Scene().with_values(**values)  # unknown names fail here (ParameterError)
    return values


def progress_printer(label: str):
    """Print progress every 10 % on stderr for long runs."""
    state = {"next": 10}

    def progress(done: int, total: int):
        if total >= 20000 and 100 * done >= state["next"] * total:
            print(f"{label}: {state['next']} %", file=sys.stderr, flush=True)
            state["next"] += 10

    return progress


def cmd_build(args) -> int:
    from vibrofmu.fmus.build import build_all

    _say_compiled_parts()
    for fmu in build_all(out_folder(args.out_dir)):
        print(f"built {fmu}")
    return 0


def cmd_closed_loop(args) -> int:
    from vibromodel.control import Law
    from vibromodel.tracking import ReferenceKind

    from vibrofmu.analyses import closed_loop
    from vibrofmu.fmus.build import build_all
    from vibrofmu.hosts.cosim import SceneError, load_scene

    fmu_dir = Path(args.fmu_dir) if args.fmu_dir else paths.build_dir()
    if fmu_dir.exists() and not fmu_dir.is_dir():
        raise UserError(f"--fmu-dir {fmu_dir} is not a folder")
    if args.mode == "cosim" and not Path(args.scene).is_file():
        raise UserError(f"no scene file at {args.scene}")
    H, stop_time = args.H or 0.1, args.stop_time or 200.0  # monolithic; a cosim takes the scene's defaults
    if args.mode == "monolithic" and H > stop_time:
        raise UserError(f"--H {H:g} is longer than the stop time {stop_time:g}")
    out = out_folder(args.out)
    if not all((fmu_dir / name).exists() for name in (PLANT_NAME, CONTROLLER_NAME, CLOSED_LOOP_NAME)):
        print(f"building the FMUs into {fmu_dir} ...", file=sys.stderr)
        _say_compiled_parts()
        build_all(fmu_dir)
    law = Law.from_label(args.law) if args.law else None
    progress = progress_printer("closed-loop")
    if args.mode == "monolithic":
        values = {"law": int(law or Law.PAPER_CORRECTED), "reference": int(ReferenceKind[args.reference.upper()])}
        fmu = checked_fmu(fmu_dir / CLOSED_LOOP_NAME, "HertzEAClosedLoop")
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
    print(f"wrote {out}/result.csv, summary.json, tracking.png, errors.png, lyapunov.png, estimates.png")
    if "V_end" in summary:
        print(f"V: {summary['V_start']:.6e} -> {summary['V_end']:.6e}, max increase between outputs "
              f"{summary['max_V_increase']:.3e}; final |e1| = {summary['final_abs_e1']:.3e}, "
              f"|e2| = {summary['final_abs_e2']:.3e}")
    for ordering, rows in summary.get("convergence", {}).get("table", {}).items():
        print(f"{ordering}: " + ", ".join(_study_cell(row) for row in rows))
    if not result["completed"]:
        print(f"error: the run stopped before the stop time: {result['stop_reason']}", file=sys.stderr)
        return 1
    return 0


def _study_cell(row: dict) -> str:
    """One H of the convergence study: the error (and order), or that the run stopped and where."""
    if not row["completed"]:
        return f"H={row['H']:g}: stopped ({row['stop_reason']})"
    order = f" (order {row['order']:.2f})" if "order" in row else ""
    return f"H={row['H']:g}: {row['max_abs_error_x']:.2e}{order}"


def cmd_simulate(args) -> int:
    from vibromodel.parameters import Scene
    from vibromodel.plant import Settings

    from vibrofmu.analyses.simulate import FIDELITIES, SOLVERS, check_inputs, simulate

    scene = Scene().with_values(**parse_set(args.set))
    settings = Settings(fidelity=FIDELITIES[args.fidelity], solver=SOLVERS[args.solver], rtol=args.rtol,
                        max_step=args.max_step)
    fmu = plant_fmu(args.fmu)
    writable_folder(args.out)
    if 0 < args.stop_time < args.output_interval:
        raise UserError(f"--output-interval {args.output_interval:g} is longer than --stop-time {args.stop_time:g}")
    # bad values raise ParameterError now; the last check (it may print the one-time note on the scene)
    check_inputs(scene, settings, args.stop_time, args.output_interval)
    out = out_folder(args.out)
    run, summary, _ = simulate(built_plant(fmu), scene, settings, args.stop_time, args.output_interval, out,
                               compare=args.compare, progress=progress_printer("simulate"))
    print(f"wrote {out}/result.csv, summary.json, x.png ({len(run.time)} points, "
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
    from vibrofmu.analyses.demo import run_demo

    fmu = plant_fmu(args.fmu)
    out = out_folder(args.out)
    return run_demo(out, built_plant(fmu))


def cmd_oafm(args) -> int:
    from vibromodel.analytic import OafmSettings
    from vibromodel.oafm import Grid
    from vibromodel.parameters import Scene, validate

    from vibrofmu.analyses.oafm_study import run_oafm

    scene = Scene().with_values(**parse_set(args.set))
    validate(scene)
    settings = OafmSettings(basis=args.basis, order=args.order, tau_star=args.tau_star, tau_end=args.tau_end,
                            grid=Grid(panel=args.panel, nodes=args.nodes))
    orders = range(1, args.study_max_order + 1) if args.study_max_order else ()
    fmu = None if args.no_fmu else plant_fmu(args.fmu)
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


def failed(check: dict | None, label: str) -> bool:
    """A check that could not run (an FMU stopped): say why on stderr."""
    if check and "error" in check:
        print(f"error: {label}: {check['error']}", file=sys.stderr)
        return True
    return False


def cmd_stability(args) -> int:
    from vibromodel.averaging import averaged, steady_states
    from vibromodel.parameters import Scene, validate

    from vibrofmu.analyses.stability import default_range, stability_study, write_study

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
    print(f"wrote {out}/summary.json, frequency_response.png")
    return 0


def cmd_bench(args) -> int:
    from vibrofmu.speed import bench
    from vibrofmu.analyses import extremes

    fmu = plant_fmu(args.fmu)
    out = out_folder(args.out)
    fmu = built_plant(fmu)
    say = lambda line: print(line, file=sys.stderr, flush=True)  # noqa: E731
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


def cmd_doctor(args) -> int:
    import tempfile

    from vibrofmu.hosts import doctor

    if args.env_file:
        try:
            record = doctor.write_env_file(Path(args.env_file), args.python,
                                           checked_fmu(Path(args.fmu)) if args.fmu else None)
        except (RuntimeError, OSError) as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        print(f"wrote {args.env_file} (Python {record['python_version']} at {record['home']}); a C host uses it with")
        print(f"export {doctor.ENV_VARIABLE}={shlex.quote(str(Path(args.env_file).resolve()))}")
        return 0
    if not args.fmu:
        raise UserError("give an FMU to check, or --env-file FILE")
    fmu = checked_fmu(Path(args.fmu))
    with tempfile.TemporaryDirectory() as work_dir:
        env, result = doctor.check(fmu, Path(work_dir))
    print(doctor.export_lines(env))
    if not result.ok:
        print(f"error: {result.message}", file=sys.stderr)
        return 1
    print(f"# ok: {result.message}")
    return 0


# -- the options of each sub-command ------------------------------------------------------------------------
FMU_HELP = f"plant FMU (default: ./build/{PLANT_NAME}, built when missing)"
SET_HELP = ("scene parameter, repeatable: mu, Delta, omega, Omega, alpha, beta, gamma, R, x_start, v_start "
            "(default: the paper's example)")


def build_options(p):
    p.add_argument("--out-dir", default="build", help="folder the FMUs are written to")


def simulate_options(p):
    from vibromodel import solvers

    from vibrofmu.analyses.simulate import FIDELITIES, SOLVERS

    p.add_argument("--fidelity", choices=list(FIDELITIES), default="exact", help="plant model")
    p.add_argument("--solver", choices=list(SOLVERS), default="adaptive",
                   help=" or ".join(f"{entry.option}: {entry.description}" for entry in solvers.SOLVERS.values()))
    # rtol, stop time and output interval are checked with the scene (simulate.check_inputs: ParameterError)
    p.add_argument("--rtol", type=float, default=1e-8, help="relative tolerance of the adaptive solver")
    p.add_argument("--max-step", type=non_negative, default=0.0, help="RK4 step / adaptive ceiling; 0 = automatic")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    p.add_argument("--stop-time", type=float, default=200.0, help="end of the run, tau")
    p.add_argument("--output-interval", type=float, default=0.1, help="communication step (doStep size)")
    p.add_argument("--compare", action="store_true", help="compare with the DOP853 rtol 1e-12 reference")
    p.add_argument("--fmu", default=None, help=FMU_HELP)
    p.add_argument("--out", required=True, help="output folder (result.csv, summary.json, x.png)")


def closed_loop_options(p):
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
    p.add_argument("--scene", default=str(DEFAULT_SCENE),
                   help=f"cosim: scene file (TOML or JSON; default: the {DEFAULT_SCENE.name} shipped with vibrofmu)")
    p.add_argument("--stop-time", type=positive, default=None, help="end of the run (default: 200 monolithic, "
                                                                    "the scene's for cosim)")
    p.add_argument("--no-study", action="store_true", help="cosim: skip the H convergence study")
    p.add_argument("--fmu-dir", default=None, help="where the three FMUs are (default: ./build; built when missing)")
    p.add_argument("--out", required=True, help="output folder (result.csv, summary.json, plots)")


def oafm_options(p):
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
    p.add_argument("--fmu", default=None, help=FMU_HELP + ", checked at fidelity 4")
    p.add_argument("--no-fmu", action="store_true", help="skip the FMU check")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    p.add_argument("--out", required=True, help="output folder (summary.json, oafm.csv, plots)")


def stability_options(p):
    p.add_argument("--omega-range", nargs=3, type=positive, metavar=("LO", "HI", "N"),
                   help="frequency grid (default: omega_e -+ max(3 mu, 3 |kappa(r_peak)|), 201 points)")
    p.add_argument("--sweep-points", type=count, default=25, help="frequencies per FMU sweep direction")
    p.add_argument("--fmu", default=None, help=FMU_HELP + ", for the sweeps")
    p.add_argument("--no-fmu", action="store_true", help="skip the FMU sweeps and the fidelity-3 check")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    p.add_argument("--out", required=True, help="output folder (summary.json, frequency_response.png)")


def bench_options(p):
    p.add_argument("--quick", action="store_true", help="tau in [0, 200], fewer settings, 1 timed repeat")
    p.add_argument("--repeats", type=count, default=None, help="timed runs per case after the warm-up "
                                                               "(default: 3; --quick 1)")
    p.add_argument("--ladder-rounds", type=count, default=None,
                   help="interleaved rounds of the speed-accuracy ladder (default: 3)")
    p.add_argument("--ladder-only", action="store_true",
                   help="only the speed-accuracy ladder (tau in [0, 200]; a few minutes): bench.json, ladder.png")
    p.add_argument("--no-instructions", action="store_true",
                   help="skip the ladder's instruction counts (valgrind's callgrind, a few minutes)")
    p.add_argument("--fmu", default=None, help=FMU_HELP)
    p.add_argument("--out", required=True, help="output folder (bench.json, work_precision.png, ladder.png)")


def demo_options(p):
    p.add_argument("--out", default="out/demo", help="output folder (result.csv, summary.json, x.png)")
    p.add_argument("--fmu", default=None, help=FMU_HELP)


def doctor_options(p):
    p.add_argument("fmu", nargs="?", help="the FMU to check (not needed with --env-file)")
    p.add_argument("--env-file", help="write the file VIBROFMU_PYTHON_ENV names (the Python a pythonfmu FMU uses) "
                                      "instead of checking (default: check)")
    p.add_argument("--python", help="with --env-file: the Python to describe (default: this one)")


COMMANDS = {  # name: (help, options, command)
    "build": ("build the plant, controller and closed-loop FMUs into ./build", build_options, cmd_build),
    "simulate": ("run the plant FMU under FMPy and export the results", simulate_options, cmd_simulate),
    "closed-loop": ("adaptive Lyapunov controller on the plant: monolithic FMU or co-simulation",
                    closed_loop_options, cmd_closed_loop),
    "oafm": ("OAFM analytic solution: fit, compare with the reference, reproduce the paper", oafm_options, cmd_oafm),
    "stability": ("steady vibrations vs omega: slow flow, shooting/Floquet, FMU sweeps", stability_options,
                  cmd_stability),
    "bench": ("work-precision: error vs wall time of every fidelity, solver and setting, beside solve_ivp and "
              "the compiled floor; the speed targets", bench_options, cmd_bench),
    "demo": ("simulate and compare on the paper's example (Omega = 2); builds the plant FMU when missing",
             demo_options, cmd_demo),
    "doctor": ("check that a C host started with an empty environment runs an FMU as FMPy does; --env-file: "
               "write the Python environment file for another machine or Python", doctor_options, cmd_doctor),
}


def make_parser(commands=None) -> argparse.ArgumentParser:
    """The parser; `commands` names the sub-commands whose options are defined (None: all). The options import
    the model (choices, defaults), so `vibrofmu --help` defines none."""
    parser = Parser(prog="vibrofmu", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (text, options, command) in COMMANDS.items():
        p = sub.add_parser(name, help=text, description=text)
        p.set_defaults(func=command)
        if commands is None or name in commands:
            options(p)
    # Sub-commands of other modules hook in here, one call each (e.g. `study.add_parser(sub)`), with their
    # heavy imports inside their command.
    from vibrofmu.hosts import container
    from vibrofmu.output import report
    from vibrofmu.hosts import ssp  # light modules: heavy imports happen inside their commands
    ssp.add_parser(sub); container.add_parser(sub); report.add_parser(sub)
    from vibrofmu.study import add_parser as add_study_parser  # issue 16: harness/vibrofmu/study/
    add_study_parser(sub)
    return parser


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((arg for arg in argv if not arg.startswith("-")), None)
    try:
        args = make_parser({command}).parse_args(argv)
    except SystemExit as stop:  # --help (0) or a bad command line (2, one line printed by Parser.error)
        return stop.code
    try:
        return args.func(args)
    except (UserError, ParameterError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except paths.NoCompiler as error:
        print(f"error: {error} (set $CC or install gcc)", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
