"""Campaigns of issue 25 (right or refused), one function each; each returns plain rows and a summary.

- rung_grid: fidelities 3 and 4 against fidelity 0 on the paper scene with one parameter changed (the evidence of the
  thresholds in docs/rungs.md, Domains): each scene accepted, warned or refused, its set-up time and its error.
- extreme_grid: every scene parameter and rtol, max_step at NaN, +-inf, 0, -1, 1e308, 1e-308 and 1e4 (huge
  forcing) x fidelities 0-4 through the plant FMU, each (parameter, value) in its own process with a time limit: a
  crash or a hang is seen as such. Counted: crashes, hangs, outputs returned with fmi2OK at |x| >= 3R/2 (or, at
  fidelities 3 and 4, at x <= -3/2), fidelity 3 or 4 set-ups longer than 2 s that were not refused, refusals whose
  message names no parameter.
- graze_campaign: long lightly damped runs that graze contact loss (tau up to 5,000, mu down to 1e-3, R = 3 so that
  the electrodes at +-4.5 lie beyond the contact edge at x = -3/2) with the adaptive solver at rtol 1e-3 ... 1e-8:
  the error of x at the communication points against the same plant at rtol 1e-12 with steps of at most 0.3 rad of
  the fastest drive, counted against 100 rtol max|x|, with the drive's step ceiling (max_step = 0) and without it
  (max_step = 1000), and with the ceiling but the solver at the rtol asked ("as_asked": the tolerance factor of
  models.tolerance_factor switched off).
- turn_campaign: the drive's step ceiling at several turns (max_step = turn / the fastest drive): random contact-loss
  scenes, the same with fast drives, and grazing runs, every run at every turn against an independent reference (the
  evidence of models.DRIVE_STEP_TURN).

Command line: python -m vibrofmu.analyses.domains grid | extremes FMU | graze [n] [seed] | turns [n] [seed]
[--summary]  (prints JSON).
"""
from __future__ import annotations

import contextlib
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from vibromodel.integrate import IntegrationError
from vibromodel.parameters import ParameterError, Scene
from vibromodel.plant import Settings, make_plant

SETUP_LIMIT = 2.0  # seconds: fidelity 3 and 4 set-up, else refused up front (issue 25)
EXTREME_VALUES = (math.nan, math.inf, -math.inf, 0.0, -1.0, 1e308, 1e-308, 1e4)
EXTREME_PARAMETERS = ("mu", "Delta", "omega", "Omega", "alpha", "beta", "gamma", "R", "x_start", "v_start", "rtol",
                      "max_step")
GRID = ([{"Delta": d} for d in (0.001, 0.01, 0.03, 0.05, 0.1, 0.15, 0.2, 0.3, 1.0, 3.0)]
        + [{"beta": b} for b in (0.01, 0.03, 0.1, 0.3, 1.0, 3.0)] + [{"gamma": g} for g in (0.01, 0.1, 1.0, 3.0)]
        + [{"alpha": 3.0}] + [{"omega": w} for w in (0.5, 0.9, 1.2, 2.0, 5.0, 1000.0)]
        + [{"mu": m} for m in (0.001, 0.01, 1.0)] + [{"x_start": x} for x in (-1.0, -0.5, 0.5, 1.0)]
        + [{"R": r} for r in (0.1, 0.3, 3.0)])


def campaign_kernel():
    """(the kernel library, what it is) for a campaign's compiled plants."""
    from vibrofmu.fmus.kernel import kernel_library  # compiled once per source version
    return kernel_library(), "the campaign's kernel"


def run_steps(plant, stop: float, h: float) -> tuple[np.ndarray, str | None]:
    """x at every communication point until stop or the first error (its message)."""
    xs = []
    for i in range(int(round(stop / h))):
        try:
            xs.append(plant.do_step(i * h, h, 0.0).x)
        except (IntegrationError, ParameterError) as error:
            return np.array(xs), str(error)
    return np.array(xs), None


def rung_grid(stop: float = 50.0, h: float = 0.1) -> dict:
    """Fidelities 3 and 4 against fidelity 0 over GRID (module docstring)."""
    library, rows = campaign_kernel(), []
    for values in GRID:
        scene = Scene(**values)
        exact, exact_stop = run_steps(make_plant(scene, Settings(), 0.0, stop, library=library), stop, h)
        for fidelity in (3, 4):
            row = {"values": values, "fidelity": fidelity, "fidelity_0_stop": exact_stop}
            started = time.perf_counter()
            try:
                plant = make_plant(scene, Settings(fidelity=fidelity), 0.0, stop, library=library)
            except (ParameterError, IntegrationError) as error:
                rows.append({**row, "outcome": "refused", "setup_seconds": time.perf_counter() - started,
                             "message": str(error)})
                continue
            setup = time.perf_counter() - started
            x, stopped = run_steps(plant, stop, h)
            n = min(len(x), len(exact))
            error = float(np.max(np.abs(x[:n] - exact[:n]))) if n else math.nan
            rows.append({**row, "outcome": "warned" if plant.warnings else "accepted", "setup_seconds": setup,
                         "stopped": stopped, "max_abs_error_x": error,
                         "relative_error": error / float(np.max(np.abs(exact[:n]))) if n else math.nan,
                         "message": plant.warnings[0] if plant.warnings else None})
    confident = [r for r in rows if r["outcome"] == "accepted"]
    return {"rows": rows, "summary": {
        "cases": len(rows), "refused": sum(r["outcome"] == "refused" for r in rows),
        "warned": sum(r["outcome"] == "warned" for r in rows), "accepted": len(confident),
        "worst_accepted_relative_error": max((r["relative_error"] for r in confident), default=None),
        "slowest_setup_seconds": max(r["setup_seconds"] for r in rows)}}


# -- the extreme-input grid through the FMU ------------------------------------------------------------------------

# One FMU run per process: a pythonfmu FMU run after another in the same process resolves its lazy imports against
# the first run's deleted extraction (fidelity 3: "No module named 'vibromodel.averaging'"), which is not the case
# under test here.
CHILD = r"""
import json, math, sys, time
from vibrofmu.hosts.run import run_fmu
fmu, name, value, stop, fidelity = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
cpu = time.process_time()
run = run_fmu(fmu, {name: value, "fidelity": fidelity}, stop, 0.1)
cpu = time.process_time() - cpu
x = run.outputs.get("x", [])
print(json.dumps({"fidelity": fidelity, "completed": run.completed, "status": run.status,
                  "reason": run.stop_reason, "init_seconds": run.instantiate_time, "run_cpu_seconds": cpu,
                  "max_abs_x": max((abs(v) for v in x), default=0.0),
                  "min_x": min(x, default=0.0), "ok_points": len(x)}), flush=True)
"""


def _extreme_case(fmu: Path, name: str, value: float, fidelity: int, stop: float, limit: float):
    """("row", row) | ("crash", why) | ("hang", None) of one FMU run in its own process."""
    try:
        done = subprocess.run([sys.executable, "-c", CHILD, str(fmu), name, repr(value), repr(stop), str(fidelity)],
                              capture_output=True, text=True, timeout=limit)
    except subprocess.TimeoutExpired:
        return "hang", None
    found = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or len(found) != 1:
        return "crash", (done.returncode, done.stderr[-300:])
    return "row", found[0]


def extreme_grid(fmu: Path, stop: float = 20.0, limit: float = 120.0, parameters=EXTREME_PARAMETERS,
                 values=EXTREME_VALUES, workers: int = 2, fidelities=range(5)) -> dict:
    """The extreme-input grid (module docstring); `limit` seconds per run (one process each, `workers` at a time).
    Set-up time: the wall time of instantiation and initialisation (init_seconds) and, robust to a loaded machine,
    the process's CPU time over the whole run (run_cpu_seconds: at fidelities 3 and 4 mostly the set-up, the doSteps
    being table lookups or closed-form sums)."""
    from concurrent.futures import ThreadPoolExecutor

    cases = [(name, value, fidelity) for name in parameters for value in values for fidelity in fidelities]
    with ThreadPoolExecutor(workers) as pool:
        results = list(pool.map(lambda case: _extreme_case(fmu, *case, stop, limit), cases))
    rows, crashes, hangs = [], [], []
    for (name, value, fidelity), (kind, found) in zip(cases, results):
        if kind == "row":
            rows.append({"parameter": name, "value": value, **found})
        else:
            (crashes if kind == "crash" else hangs).append((name, value, fidelity, found))
    R = Scene().R

    def escaped(row):
        R_row = row["value"] if row["parameter"] == "R" else R
        if not (isinstance(R_row, float) and math.isfinite(R_row) and R_row > 0.0):
            return row["ok_points"] > 0  # R itself out of range: no output may be returned at all
        return row["max_abs_x"] >= 1.5 * R_row or (row["fidelity"] >= 3 and row["min_x"] <= -1.5)

    return {"rows": rows, "summary": {
        "cases": len(rows), "crashes": len(crashes), "hangs": len(hangs), "crash_cases": crashes, "hang_cases": hangs,
        "outside_the_domain_with_fmi2OK": sum(escaped(r) for r in rows),
        "slow_setups_not_refused": sum(r["fidelity"] >= 3 and r["init_seconds"] > SETUP_LIMIT and r["ok_points"] > 0
                                       for r in rows),
        "slow_setups_not_refused_by_cpu_time": sum(r["fidelity"] >= 3 and r["run_cpu_seconds"] > SETUP_LIMIT
                                                   and r["ok_points"] > 0 for r in rows),
        "largest_run_cpu_seconds_fidelity_3_4": max((r["run_cpu_seconds"] for r in rows if r["fidelity"] >= 3),
                                                    default=None),
        "refusals_naming_no_parameter": sum(r["ok_points"] == 0 and "parameter " not in (r["reason"] or "")
                                            for r in rows),
        "refused_at_initialisation": sum(r["ok_points"] == 0 for r in rows),
        "slowest_init_seconds": max((r["init_seconds"] for r in rows), default=None)}}


# -- long lightly damped grazing runs ------------------------------------------------------------------------------

def graze_scene(rng: np.random.Generator) -> tuple[Scene, float, float]:
    """(scene, stop time, rtol): mu log-uniform in [1e-3, 2e-2], Omega in [2, 10] with beta and gamma on or off, a
    load near resonance whose linear amplitude Delta/|a1 - omega^2 + i mu omega| is 1.2 ... 1.8 (x reaches or nearly
    reaches the contact edge at -3/2), R = 3; tau in [500, 5000], rtol 10^-3 ... 10^-8."""
    mu = float(10.0 ** rng.uniform(-3.0, math.log10(0.02)))
    omega = float(rng.uniform(0.97, 1.03))
    gain = 1.0 / abs(complex(1.0 - omega * omega, mu * omega))
    scene = Scene(mu=mu, omega=omega, Omega=float(rng.uniform(2.0, 10.0)), R=3.0, x_start=0.0,
                  Delta=float(rng.uniform(1.2, 1.8)) / gain,
                  beta=float(rng.choice([0.0, 1e-3])), gamma=float(rng.choice([0.0, 2e-3])), alpha=0.001)
    return scene, float(rng.uniform(500.0, 5000.0)), float(10.0 ** -rng.integers(3, 9))


def fastest_drive(scene: Scene) -> float:
    return max(scene.omega, scene.Omega if scene.beta else 0.0, 2.0 * scene.Omega if scene.gamma else 0.0)


def graze_campaign(n: int = 100, seed: int = 0, h: float = 1.0) -> dict:
    """The grazing runs (module docstring), each with and without the drive's ceiling."""
    library, rng, rows = campaign_kernel(), np.random.default_rng(seed), []
    for _ in range(n):
        scene, stop, rtol = graze_scene(rng)
        reference, ref_stop = run_steps(make_plant(scene, Settings(rtol=1e-12, max_step=0.3 / fastest_drive(scene)), 0.0,
                                                stop, library=library), stop, h)
        row = {"scene": scene.as_dict(), "stop": stop, "rtol": rtol, "reference_stop": ref_stop}
        scale = 100.0 * rtol * float(np.max(np.abs(reference))) if len(reference) else math.nan
        for label, max_step, factor in (("ceiling", 0.0, True), ("none", 1000.0, True), ("as_asked", 0.0, False)):
            with contextlib.nullcontext() if factor else _tolerance_factor_off():
                plant = make_plant(scene, Settings(rtol=rtol, max_step=max_step), 0.0, stop, library=library)
            x, stopped = run_steps(plant, stop, h)
            k = min(len(x), len(reference))
            error = float(np.max(np.abs(x[:k] - reference[:k]))) if k else math.nan
            row[label] = {"error_over_bound": error / scale, "stopped": stopped, "rhs_calls": plant.nfev,
                          "agrees_on_stop": (stopped is None) == (ref_stop is None)}
        rows.append(row)

    def within(label):
        return sum(r[label]["error_over_bound"] <= 1.0 and r[label]["agrees_on_stop"] for r in rows)

    return {"rows": rows, "summary": {
        "runs": n, "within_100_rtol_max_x_with_ceiling": within("ceiling"),
        "within_100_rtol_max_x_without": within("none"),
        "within_100_rtol_max_x_rtol_as_asked": within("as_asked"),
        "worst_error_over_bound_with_ceiling": max(r["ceiling"]["error_over_bound"] for r in rows),
        "worst_error_over_bound_without": max(r["none"]["error_over_bound"] for r in rows),
        "worst_error_over_bound_rtol_as_asked": max(r["as_asked"]["error_over_bound"] for r in rows),
        "rhs_calls_with_ceiling": sum(r["ceiling"]["rhs_calls"] for r in rows),
        "rhs_calls_without": sum(r["none"]["rhs_calls"] for r in rows),
        "rhs_calls_rtol_as_asked": sum(r["as_asked"]["rhs_calls"] for r in rows)}}


# -- the drive's step ceiling: how far a step may turn the fastest drive -------------------------------------------

TURNS = (2.25, 3.0, 3.5, 4.0, 5.0, math.inf)  # candidate models.DRIVE_STEP_TURN values (inf: no ceiling)


def fast_drive_scene(rng: np.random.Generator) -> Scene:
    """A contact-loss scene (campaigns.random_contact_loss_scene) whose drives run fast: omega and Omega
    log-uniform in [0.3, 100], mu in [0.01, 0.2]; the electrostatic drives up to 0.05, the load up to 0.2."""
    from vibrofmu.analyses.campaigns import random_contact_loss_scene

    base = random_contact_loss_scene(rng)
    return base.with_values(mu=float(rng.uniform(0.01, 0.2)), Delta=float(rng.uniform(0.0, 0.2)),
                            omega=float(10.0 ** rng.uniform(math.log10(0.3), 2.0)),
                            Omega=float(10.0 ** rng.uniform(math.log10(0.3), 2.0)))


def _contact_exits(x: np.ndarray) -> int:
    """Changes between in contact (x > -3/2) and out of it along the output grid."""
    out = x <= -1.5
    return int(np.count_nonzero(out[1:] != out[:-1]))


def turn_campaign(n: int = 100, seed: int = 0, turns=TURNS, kinds=("contact loss", "fast drive", "graze")) -> dict:
    """The drive's step ceiling at several turns K (max_step = K / the fastest drive term switched on,
    models.drive_step_ceiling with DRIVE_STEP_TURN = K), n runs of each kind, every run at every K:
    - "contact loss": campaigns.random_contact_loss_scene (the mass leaves the contact and hits it again; drives
      up to 3, 2 Omega up to 6), rtol log-uniform in [1e-10, 1e-3], tau in [0, 10], outputs every 0.1, against
      reference.reference_solution (solve_ivp, contact phases integrated apart) at rtol min(1e-12, rtol / 1000);
    - "fast drive": fast_drive_scene (omega and Omega up to 100), the same way;
    - "graze": graze_scene (long lightly damped runs, Omega up to 10, tau up to 5,000), outputs every 1, against the
      plant at rtol 1e-12 with steps of at most 0.3 rad of the fastest drive (graze_campaign's reference).
    Per run and K: the error max|x - x_ref| over the bound 100 rtol max|x_ref|, whether the run stopped where the
    reference did (pull-in), the RHS calls, and whether the contact changes along the output grid are the reference's
    (an impact lost or invented by a long step would change their count)."""
    from vibromodel.models import DRIVE_STEP_TURN, drive_step_ceiling

    from vibrofmu.analyses.campaigns import random_contact_loss_scene
    from vibrofmu.analyses.reference import reference_solution

    library, rng, rows = campaign_kernel(), np.random.default_rng(seed), []
    for kind in kinds:
        for _ in range(n):
            if kind == "graze":
                scene, stop, rtol = graze_scene(rng)
                h = 1.0
                reference, ref_stop = run_steps(make_plant(scene, Settings(rtol=1e-12, max_step=0.3 / fastest_drive(scene)),
                                                           0.0, stop, library=library), stop, h)
            else:
                scene = random_contact_loss_scene(rng) if kind == "contact loss" else fast_drive_scene(rng)
                stop, h, rtol = 10.0, 0.1, float(10.0 ** rng.uniform(-10.0, -3.0))
                solution = reference_solution(scene, 0, stop, rtol=min(1e-12, rtol / 1000.0), atol=min(1e-14, rtol / 1e5))
                times = h * np.arange(1, int(round(stop / h)) + 1)
                inside = times <= solution.t_end
                reference = solution(times[inside])[0]
                ref_stop = None if solution.stop_event is None else solution.stop_event
            row = {"kind": kind, "scene": scene.as_dict(), "stop": stop, "rtol": rtol, "reference_stop": ref_stop}
            scale = 100.0 * rtol * max(float(np.max(np.abs(reference))), 1e-300) if len(reference) else math.nan
            ceiling = drive_step_ceiling(scene)
            for turn in turns:
                max_step = min(1000.0, ceiling * (turn / DRIVE_STEP_TURN)) if math.isfinite(ceiling) else 1000.0
                plant = make_plant(scene, Settings(rtol=rtol, max_step=max_step), 0.0, stop, library=library)
                x, stopped = run_steps(plant, stop, h)
                k = min(len(x), len(reference))
                row[repr(turn)] = {
                    "error_over_bound": float(np.max(np.abs(x[:k] - reference[:k]))) / scale if k else math.nan,
                    "agrees_on_stop": (stopped is None) == (ref_stop is None), "rhs_calls": plant.nfev,
                    "contact_changes": _contact_exits(x[:k]), "reference_contact_changes": _contact_exits(reference[:k])}
            rows.append(row)
    summary = {}
    for kind in kinds:
        mine = [r for r in rows if r["kind"] == kind]
        for turn in turns:
            cells = [r[repr(turn)] for r in mine]
            summary[f"{kind}, turn {turn:g}"] = {
                "runs": len(cells),
                "within_100_rtol_max_x": sum(c["error_over_bound"] <= 1.0 and c["agrees_on_stop"] for c in cells),
                "worst_error_over_bound": max((c["error_over_bound"] for c in cells), default=None),
                "stops_disagreeing": sum(not c["agrees_on_stop"] for c in cells),
                "contact_changes_differing": sum(c["contact_changes"] != c["reference_contact_changes"] for c in cells),
                "contact_changes": sum(c["contact_changes"] for c in cells),
                "rhs_calls": sum(c["rhs_calls"] for c in cells)}
    return {"rows": rows, "summary": summary}


@contextlib.contextmanager
def _tolerance_factor_off():
    """Plants made inside run their solver at the rtol asked (models.tolerance_factor = 1): the campaign's measure of
    what the factor does."""
    from vibromodel import models

    saved = models.ERROR_MEMORY_REFERENCE
    models.ERROR_MEMORY_REFERENCE = math.inf
    try:
        yield
    finally:
        models.ERROR_MEMORY_REFERENCE = saved


def main(argv: list[str]) -> None:
    if argv and argv[0] == "grid":
        result = rung_grid()
    elif argv and argv[0] == "extremes":
        result = extreme_grid(Path(argv[1]))
    elif argv and argv[0] == "turns":
        result = turn_campaign(*(int(a) for a in argv[1:3]))
        result = {"summary": result["summary"]} if "--summary" in argv else result
    else:
        result = graze_campaign(*(int(a) for a in argv[1:3]))
    print(json.dumps(result, indent=1, default=str))


if __name__ == "__main__":
    main(sys.argv[1:])
