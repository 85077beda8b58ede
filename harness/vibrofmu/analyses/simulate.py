"""Simulate the plant FMU for a scene, optionally compare with the reference, export the results."""
from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np

from vibromodel import fidelities, solvers
from vibromodel.analytic import covering
from vibromodel.parameters import ParameterError, Scene, consistency_warning, validate
from vibromodel.plant import MAX_STEPS_PER_DOSTEP, Plant, Settings, checked_settings

from vibrofmu.output import export
from vibrofmu.analyses.compare import errors
from vibrofmu.analyses.reference import REFERENCE_ATOL, REFERENCE_RTOL, Reference, reference_solution
from vibrofmu.hosts.run import RunResult, run_fmu

FIDELITIES = fidelities.keys()  # command-line names -> levels (the registry)
SOLVERS = {entry.option: entry.value for entry in solvers.SOLVERS.values()}  # command-line names -> settings (the registry)


def plant_run(scene: Scene, settings: Settings, stop_time: float, interval: float) -> tuple[np.ndarray, np.ndarray, Plant]:
    """The FMU's run on vibromodel.Plant directly (the code inside the FMU, no FMI): (times, (x, v) at them from
    the plant's initial outputs on, the plant)."""
    plant = Plant(scene, settings, 0.0, stop_time)
    n = int(round(stop_time / interval))
    states = np.empty((2, n + 1))
    first = plant.outputs()
    states[:, 0] = first.x, first.v
    for i in range(n):
        out = plant.do_step(i * interval, interval, 0.0)
        states[:, i + 1] = out.x, out.v
    return np.arange(n + 1) * interval, states, plant


def start_values(scene: Scene, settings: Settings) -> dict:
    """FMU start values (the names in docs/fmu-reference.md) of a scene and settings."""
    oafm = settings.oafm
    return {**scene.as_dict(), "fidelity": settings.fidelity, "solver": settings.solver, "rtol": settings.rtol,
            "max_step": settings.max_step, "oafm_order": oafm.order, "tau_star": oafm.tau_star,
            "oafm_tau_end": oafm.tau_end}


def fmu_settings(settings: Settings, output_interval: float) -> Settings:
    """The settings the FMU is given: a fixed-step solver's step longer than the output interval becomes the
    interval. Every doStep is then one step of the interval either way (the same result bit for bit), and the
    FMU's set-up, which cannot know the communication step, checks and logs the step RK4 really takes instead of
    warning about one it never takes (max_step = 5 at an interval of 0.1 logged "wrong by more than 1000%")."""
    solver = solvers.solver_entry(settings.solver)
    if (solver.fixed_step and fidelities.entry(settings.fidelity).integrated
            and solver.step(settings.max_step) > output_interval):
        return dataclasses.replace(settings, max_step=output_interval)
    return settings


def run_title(settings: Settings, output_interval: float) -> str:
    """x.png's title: the fidelity and the settings it reads (fidelities and solvers registries), nothing it does
    not: an integrated level's solver and its rtol or RK4 step, the slow flow's rtol, the OAFM fit's order."""
    level = fidelities.entry(settings.fidelity)
    words = [f"fidelity {level.key}"]
    if level.integrated:
        solver = solvers.solver_entry(settings.solver)
        words.append(f"solver {solver.option}")
        if "rtol" in dict(solver.parameters):
            words.append(f"rtol {settings.rtol:g}")
        else:
            words.append(f"step {min(solver.step(settings.max_step), output_interval):g}")
    elif level.uses_rtol:
        words.append(f"slow-flow rtol {settings.rtol:g}")
    elif level.oafm_settings:
        words.append(f"OAFM {settings.oafm.basis} basis" + (f", order {settings.oafm.order}"
                                                            if settings.oafm.basis == "harmonic" else ""))
    return "HertzEAOscillator: " + ", ".join(words)


NOTED: set[str] = set()  # notes already printed in this process

# What a run keeps per output point: time and the plant's 6 outputs (x, v, a, F_contact, F_electrostatic,
# in_contact), 8 bytes each in memory (hosts.run preallocates them) and at most 25 characters each in result.csv
# (%.17g: sign, 17 digits, point, e-XXX; the separator).
POINT_COLUMNS = 7
MEMORY_BYTES_PER_POINT = 8 * POINT_COLUMNS
CSV_BYTES_PER_POINT = 25 * POINT_COLUMNS
MAX_OUTPUT_MB = 500.0  # the default of simulate --max-output-mb


def output_size(stop_time: float, output_interval: float, columns: int = POINT_COLUMNS) -> tuple[int, float]:
    """(output points, the larger of their memory and result.csv sizes in MB) of a run with `columns` per point."""
    points = int(round(stop_time / output_interval)) + 1
    return points, points * columns * max(MEMORY_BYTES_PER_POINT, CSV_BYTES_PER_POINT) / POINT_COLUMNS / 1e6


def check_output_size(stop_time: float, output_interval: float, max_mb: float, columns: int = POINT_COLUMNS,
                      interval_option: str = "--output-interval") -> None:
    """ParameterError naming the estimate and the option that raises the limit when a run's output (every output
    point, kept in memory and written to result.csv) would exceed max_mb megabytes. `columns`: the values per
    output point; `interval_option`: how the command line names the output interval (closed-loop: --H)."""
    points, mb = output_size(stop_time, output_interval, columns)
    if mb > max_mb:
        memory = points * columns * MEMORY_BYTES_PER_POINT / POINT_COLUMNS / 1e6
        raise ParameterError("stop-time", stop_time,
                             f"with {interval_option} {output_interval:g} the run has {points:,} output points, "
                             f"about {mb:,.0f} MB of results (result.csv; {memory:,.0f} MB in memory), over "
                             f"--max-output-mb {max_mb:g}: raise --max-output-mb, lengthen {interval_option} or "
                             "shorten --stop-time")


def check_inputs(scene: Scene, settings: Settings, stop_time: float, output_interval: float) -> list[str]:
    """Raise ParameterError for bad input (before anything runs), named as the command line names it; return
    warnings (the FMU logs the settings' ones too: rtol clamped, an RK4 step that does not resolve the forcing)."""
    validate(scene)
    for name, value in (("stop-time", stop_time), ("output-interval", output_interval)):
        if not (np.isfinite(value) and value > 0):
            raise ParameterError(name, value, "must be a finite number > 0")
    checked, warnings = checked_settings(scene, settings, interval=output_interval)  # the RK4 step really taken
    level = fidelities.entry(settings.fidelity)
    if level.integrated:  # the FMU's doStep refuses this (settings.check_step), naming communicationStepSize
        step = solvers.solver_entry(checked.solver).step(checked.max_step)
        if output_interval / step > MAX_STEPS_PER_DOSTEP:
            raise ParameterError("output-interval", output_interval,
                                 f"needs more than {MAX_STEPS_PER_DOSTEP} steps of --max-step {step:g} per output; "
                                 "shorten --output-interval or raise --max-step")
    if level.key == "analytic":  # the FMU's own check, before it is started
        covering(scene, settings.oafm, stop_time, strict=True)
    return warnings


def print_note(scene: Scene) -> None:
    """A parameter set no voltages can produce (beta^2 != 8 alpha gamma): an explanation, not a problem, printed
    once per process as a note when the run starts (never before an error)."""
    note = consistency_warning(scene)
    if note and note not in NOTED:
        NOTED.add(note)
        print(f"note: {note}", file=sys.stderr)


INITIALISATION_OUTPUTS = ("error_estimate", "fidelity_chosen")  # the plant FMU's outputs set once, at initialisation
ESTIMATE_NOTE = "error estimate: max|x - x_exact| ~ "  # vibromodel.error_estimates.attach's log line


def logged_estimate(log: list[str]) -> float | None:
    """The plant's estimate of max|x - x_exact| over the run, from its log line (None: not logged, or not a number,
    as a rung that cannot estimate logs nan)."""
    for message in log:
        if ESTIMATE_NOTE in message:
            try:
                value = float(message.split(ESTIMATE_NOTE, 1)[1].split()[0])
            except (IndexError, ValueError):
                return None
            return value if math.isfinite(value) else None
    return None


def published_estimate(run: RunResult) -> float | None:
    """The FMU's error_estimate output (None: -1, none), or its log line for an FMU without the output."""
    values = run.outputs.get("error_estimate")
    if values is not None and len(values):
        return float(values[-1]) if values[-1] >= 0.0 else None
    return logged_estimate(run.log)


AUTO_CHOICE = "fidelity auto chose "  # the start of the plant FMU's log line of its choice (vibromodel.messages)


def auto_summary(run: RunResult, tolerance: float) -> dict:
    """summary.json's entries on fidelity auto's choice, read from the FMU: its fidelity_chosen output as the name
    --fidelity accepts (None: it chose nothing, refused), its log line of the choice, the tolerance."""
    names = {level: key for key, level in FIDELITIES.items()}
    chosen = run.outputs.get("fidelity_chosen")
    level = int(chosen[-1]) if chosen is not None and len(chosen) else None
    if level is None and run.after_failure and "fidelity_chosen" in run.after_failure:
        level = int(run.after_failure["fidelity_chosen"])
    choice = next((m.split(AUTO_CHOICE, 1)[1] for m in run.log if AUTO_CHOICE in m), None)
    return {"tolerance": tolerance, "fidelity_chosen": names.get(level),
            "auto_choice": AUTO_CHOICE + choice if choice is not None else None}


def simulate(fmu: Path, scene: Scene, settings: Settings, stop_time: float, output_interval: float,
             out_dir: Path, compare: bool = False, progress=None,
             summary_extra: dict | None = None,
             auto_tolerance: float | None = None) -> tuple[RunResult, dict, Reference | None]:
    """Run the FMU, write out_dir/result.csv, summary.json and x.png; return the run, the summary
    and the reference (None without compare). summary_extra: entries added to the summary. auto_tolerance: fidelity
    auto (`settings` then the exact model's, which every candidate's forces are, for the checks and the reference):
    the FMU gets fidelity = -1 and this tolerance and chooses; the summary reads its choice (auto_summary)."""
    warnings = check_inputs(scene, settings, stop_time, output_interval)
    print_note(scene)
    for warning in warnings:
        print(f"warning: {warning}", file=sys.stderr)
    given = fmu_settings(settings, output_interval)
    values = start_values(scene, given)
    if auto_tolerance is not None:
        values.update(fidelity=fidelities.AUTO, tolerance=auto_tolerance)
    run = run_fmu(fmu, values, stop_time, output_interval, progress=progress)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = {
        "fmu": str(fmu),
        "parameters": scene.as_dict(),
        "settings": {**dataclasses.asdict(settings), "stop_time": stop_time, "output_interval": output_interval,
                     **({"fmu_max_step": given.max_step} if given != settings else {}),
                     **({"fidelity": fidelities.AUTO} if auto_tolerance is not None else {})},
        "warnings": warnings,
        "notes": [note for note in [consistency_warning(scene)] if note],
        "completed": run.completed,
        "end_time": run.end_time,
        "stop_reason": run.stop_reason,
        "wall_time_s": run.wall_time,
        "instantiate_time_s": run.instantiate_time,
        "fmu_log": run.log[-20:],
        "error_estimate": published_estimate(run),
        **(auto_summary(run, auto_tolerance) if auto_tolerance is not None else {}),
        **(summary_extra or {}),
    }
    reference = reference_x = None
    if compare and len(run.time):
        reference = reference_solution(scene, settings.fidelity, run.end_time)
        reference_x = reference(run.time)[0]
        summary["reference"] = {"method": "solve_ivp DOP853", "rtol": REFERENCE_RTOL, "atol": REFERENCE_ATOL,
                                "stop_event": reference.stop_event,
                                "contact_changes_tau": reference.contact_changes}
        summary["error"] = errors(run.time, run.outputs["x"], run.outputs["v"], reference)
        summary["estimate_and_measured"] = {"error_estimate": summary["error_estimate"],  # side by side
                                            "max_abs_error_x": summary["error"]["max_abs_error_x"]}
    export.write_csv(out_dir / "result.csv", run.time,  # fixed at initialisation: in summary.json
                     {name: values for name, values in run.outputs.items() if name not in INITIALISATION_OUTPUTS})
    export.write_json(out_dir / "summary.json", summary)
    if len(run.time) >= 2:  # an FMU that failed before its first step has nothing to plot: no empty figure
        title = run_title(given, output_interval)
        if auto_tolerance is not None:
            title = f"HertzEAOscillator: fidelity auto, tolerance {auto_tolerance:g}: {summary['fidelity_chosen']}"
        export.plot_x(out_dir / "x.png", run.time, run.outputs["x"], title,
                      reference_x=reference_x, in_contact=run.outputs.get("in_contact"),
                      stop=None if run.completed else (run.end_time, run.stop_reason))
    return run, summary, reference
