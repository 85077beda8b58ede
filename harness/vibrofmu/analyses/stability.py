"""Which steady vibrations exist at each forcing frequency, which are stable, where the jumps are, and how
far the averaged prediction can be trusted (issue 4).

Three independent methods on one frequency grid:
- the averaged slow flow (vibromodel.averaging, docs/model.md, Averaging and slow flow): every branch, its type, the fold frequencies;
- shooting with Floquet multipliers (shooting.py): each slow-flow steady state is shot from its own
  prediction, and the branch is continued by pseudo-arclength through the folds;
- brute-force FMU sweeps up and down in omega (sweep.py): the measured amplitudes and jumps.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vibromodel import averaging as av
from vibromodel.averaging_printed import printed_averaged, printed_classification, subcase_1a_check
from vibromodel.parameters import Scene
from vibromodel.plant import Plant, Settings

from vibrofmu.output import export

from vibrofmu.analyses import shooting
from vibrofmu.hosts.run import run_fmu
from vibrofmu.analyses.simulate import start_values
from vibrofmu.analyses.sweep import MAX_PERIODS, SETTLE_TOLERANCE, WINDOW_PERIODS, Sweep, hysteresis_jumps, sweep

FOLD_MARGIN = 4.0  # grid points within this many fold-location uncertainties of a fold are "at a fold"


def default_range(model: av.Averaged) -> tuple[float, float]:
    """omega_e -+ max(3 mu, 3 |kappa(r_peak)|): the resonance peak and its bend, with tails on both sides
    (at 3 mu from the linear peak the amplitude is 1/6 of it)."""
    s = model.scene
    r_peak = min(s.Delta / max(s.mu * model.omega_e, 1e-300), model.r_max)
    half = max(3 * s.mu, 3 * abs(model.backbone.kappa(r_peak)), 1e-3)
    return model.omega_e - half, model.omega_e + half


def state_record(state: av.SteadyState, omega: float) -> dict:
    return {"r": state.r, "A": state.A, "B": state.B, "kind": state.kind, "det_J": state.det,
            "eigenvalues": [[z.real, z.imag] for z in state.eigenvalues],
            "exp_lambda_T": [[z.real, z.imag] for z in state.multipliers(omega)]}


@dataclass
class GridPoint:
    omega: float
    slow: list  # SteadyState, by increasing r
    orbits: list  # shooting.Orbit started from each slow-flow state (None where Newton failed)


def shoot_predictions(model: av.Averaged, periodic: shooting.PeriodicModel, omega: float) -> GridPoint:
    """Slow-flow steady states at omega and the periodic orbit shot from each: x(0) = x_e + A, x'(0) = omega B."""
    states = av.steady_states(model.flow(omega), model.r_max)
    orbits = []
    for s in states:
        try:
            orbits.append(shooting.shoot(periodic, omega, [model.eq.x_e + s.A, omega * s.B]))
        except shooting.ShootingError:
            orbits.append(None)
    return GridPoint(omega, states, orbits)


def same_orbit(state: av.SteadyState, orbit, rel: float = 0.05) -> bool:
    """Newton landed on the orbit the slow flow predicted (not on a neighbouring branch)."""
    return orbit is not None and abs(orbit.r - state.r) <= rel * state.r


def floquet_type(orbit) -> str:
    return "stable" if orbit.stable else orbit.kind


def agreement(points: list[GridPoint], fold_omegas: list[float], margin: float) -> dict:
    """Classification by the slow flow against Floquet at every grid point farther than margin from a fold."""
    compared = agreed = 0
    disagreements = []
    for p in points:
        if any(abs(p.omega - w) <= margin for w in fold_omegas):
            continue
        compared += 1
        found = all(same_orbit(s, o) for s, o in zip(p.slow, p.orbits))
        match = found and all(s.stable == o.stable for s, o in zip(p.slow, p.orbits))
        agreed += match
        if not match:
            disagreements.append({"omega": p.omega, "slow_flow": [s.kind for s in p.slow],
                                  "floquet": [None if o is None else floquet_type(o) for o in p.orbits]})
    return {"points_compared": compared, "points_agreeing": agreed,
            "fraction": agreed / compared if compared else math.nan, "excluded_margin": margin,
            "disagreements": disagreements[:20]}


def branch_errors(points: list[GridPoint]) -> dict:
    """Largest relative amplitude error of the slow flow against shooting, and |exp(lambda T) - rho|."""
    r_err, rho_err = [(math.nan, math.nan)], [(math.nan, math.nan)]
    for p in points:
        for s, o in zip(p.slow, p.orbits):
            if same_orbit(s, o):
                r_err.append((abs(s.r - o.r) / o.r, p.omega))
                predicted = sorted(s.multipliers(p.omega), key=lambda z: (abs(z), z.imag))
                measured = sorted(o.multipliers, key=lambda z: (abs(z), z.imag))
                rho_err.append((max(abs(a - b) for a, b in zip(predicted, measured)), p.omega))
    (r_max, r_at), (rho_max, rho_at) = (max(e, key=lambda pair: -math.inf if math.isnan(pair[0]) else pair[0])
                                        for e in (r_err, rho_err))
    return {"max_relative_r_error": r_max, "at_omega": r_at, "max_multiplier_error": rho_max, "at_omega_multiplier": rho_at}


def sweep_grid(model: av.Averaged, folds: list, lo: float, hi: float, n: int) -> np.ndarray:
    """Sweep frequencies: around the predicted hysteresis interval when there is one (the slow flow only
    says where to look; the FMU measures), else the whole range."""
    if len(folds) >= 2:
        width = folds[-1].omega - folds[0].omega
        lo, hi = folds[0].omega - width, folds[-1].omega + width
    return np.linspace(lo, hi, n)


def sweep_tolerance(model: av.Averaged, fold: av.Fold, sweep_step: float) -> float:
    """A sweep's fold is placed within half a step of where its branch ends, and a branch can outlive its
    fold by the ghost margin of the sweep's longest wait (MAX_PERIODS): one step plus that margin."""
    return sweep_step + av.ghost_margin(model, fold, MAX_PERIODS * 2 * math.pi / fold.omega)


def sweep_summary(sweeps: list[Sweep], model: av.Averaged, folds: list, sweep_step: float) -> dict:
    """Measured amplitudes against the slow flow's nearest branch, at the settled points farther than the
    sweep tolerance from a fold (nearer, a settled-looking point may still creep past the fold's ghost)."""
    near = [(fold.omega, sweep_tolerance(model, fold, sweep_step)) for fold in folds]
    summary = {}
    for s in sweeps:
        errors = []
        for p in s.points:
            if not p.settled or any(abs(p.omega - w) <= margin for w, margin in near):
                continue
            predicted = [st.r for st in av.steady_states(model.flow(p.omega), model.r_max)]
            nearest = min(predicted, key=lambda r: abs(r - p.r))
            errors.append(abs(p.r - nearest) / nearest)
        summary[s.direction] = {
            "omega": s.omega.tolist(), "r": s.r.tolist(), "settled": [p.settled for p in s.points],
            "periods": [p.periods for p in s.points], "stop_reason": s.stop_reason,
            "points_compared": len(errors),
            "max_relative_difference_to_slow_flow": max(errors, default=math.nan)}
    return summary


def fold_agreement(model: av.Averaged, slow: list, continuation: list, sweeps: list[Sweep], sweep_step: float) -> dict:
    """Fold frequencies by each method, paired in increasing omega; sweep folds with `sweep_tolerance`."""
    jumps = hysteresis_jumps(*sweeps) if len(sweeps) == 2 else []
    sweep_folds = [jump["omega"] for jump in jumps]
    rows = []
    for i, fold in enumerate(slow):
        row = {"slow_flow": fold.omega, "r_slow_flow": fold.r}
        if i < len(continuation):
            row["continuation"] = continuation[i].omega
            row["continuation_minus_slow_flow"] = continuation[i].omega - fold.omega
        if len(sweep_folds) == len(slow):
            row["fmu_sweep"] = sweep_folds[i]
            row["fmu_sweep_minus_continuation"] = sweep_folds[i] - row.get("continuation", math.nan)
            row["sweep_tolerance"] = sweep_tolerance(model, fold, sweep_step)
        rows.append(row)
    return {"folds": rows, "sweep_jumps": jumps, "sweep_step": sweep_step,
            "sweep_folds_within_tolerance": bool(rows) and all(
                abs(r.get("fmu_sweep_minus_continuation", math.inf)) <= r.get("sweep_tolerance", 0.0) for r in rows)}


def model_cost(scene: Scene, fidelity: int, stop_time: float, interval: float, repeats: int = 3) -> dict:
    """Seconds for the model alone (vibromodel.Plant, no FMI, no output forces), minimum of repeats:
    total = initialisation + Plant.advance on the output grid; integration = the time integration of the
    model's equations only (Eq. 3 by DOP853 steps; the slow flow by SciPy's DOP853), without evaluating
    outputs (fidelity 0: dense output and x''; fidelity 3: the Hermite table and the reconstruction of x)."""
    times = [(i + 1) * interval for i in range(int(round(stop_time / interval)))]
    total = integration = math.inf
    for _ in range(repeats):
        started = time.perf_counter()
        plant = Plant(scene, Settings(fidelity=fidelity), 0.0, stop_time)
        for t in times:
            plant.advance(t)
        total = min(total, time.perf_counter() - started)
        if plant.solution is not None:
            integration = min(integration, plant.solution.integration_seconds)
        else:
            started = time.perf_counter()
            integrator = Plant(scene, Settings(fidelity=fidelity), 0.0, stop_time).integrator
            for t in times:
                integrator.advance(t)
            integration = min(integration, time.perf_counter() - started)
    return {"total": total, "integration": integration}


def fidelity3_stop_time(scene: Scene) -> float:
    """Long enough that the transient has decayed to 1e-4 (e^(-mu t/2)) by half time; 400 at least, 20000 at most."""
    return min(max(400.0, 4 * math.log(1e4) / max(scene.mu, 1e-300)), 20000.0)


def fidelity3_check(fmu, scene: Scene, stop_time: float = 400.0, interval: float = 0.1) -> dict:
    """Fidelity 3 (averaged) against fidelity 0 (exact, adaptive DOP853, rtol 1e-8) through the FMU, side by
    side: the error after the transient (the second half of the run, where e^(-mu t/2) of the first half
    has decayed) and the speed-up, end to end under FMPy and in the model alone."""
    runs = {f: run_fmu(fmu, start_values(scene, Settings(fidelity=f)), stop_time, interval) for f in (0, 3)}
    for f, run in runs.items():
        if not run.completed:
            return {"error": f"fidelity {f} stopped at tau = {run.end_time:g}: {run.stop_reason}"}
    x0, x3 = runs[0].outputs["x"], runs[3].outputs["x"]
    late = runs[0].time >= stop_time / 2
    amplitude = 0.5 * (x0[late].max() - x0[late].min())
    end_to_end = {f: run.wall_time + run.instantiate_time for f, run in runs.items()}
    model = {f: model_cost(scene, f, stop_time, interval) for f in (0, 3)}
    return {
        "stop_time": stop_time, "output_interval": interval,
        "max_abs_error_after_transient": float(np.max(np.abs(x3 - x0)[late])),
        "relative_to_amplitude": float(np.max(np.abs(x3 - x0)[late]) / amplitude),
        "max_abs_error_whole_run": float(np.max(np.abs(x3 - x0))),
        "transient_decay_at_half_time": math.exp(-scene.mu * stop_time / 4),
        "end_to_end_seconds": {"fidelity_0": end_to_end[0], "fidelity_3": end_to_end[3]},
        "end_to_end_speedup": end_to_end[0] / end_to_end[3],
        "instantiate_seconds": {"fidelity_0": runs[0].instantiate_time, "fidelity_3": runs[3].instantiate_time},
        "model_seconds": {"fidelity_0": model[0], "fidelity_3": model[3]},
        "model_speedup": model[0]["total"] / model[3]["total"],
        "integration_speedup": model[0]["integration"] / model[3]["integration"],
        "fmu_log_fidelity_3": runs[3].log[:4],
    }


def paper_mode(scene: Scene, omega: float) -> dict:
    """PAPER §5 as printed at omega, next to the corrected result (docs/model.md, Averaging and slow flow)."""
    model = av.averaged(scene)
    printed = printed_averaged(scene)
    flow, printed_flow = model.flow(omega), printed.flow(omega)
    return {
        "omega": omega,
        "corrected": [{"r": s.r, "kind": s.kind} for s in av.steady_states(flow, model.r_max)],
        "printed_flow": [{"r": s.r, "kind_by_printed_rules": printed_classification(printed_flow.mu, s.det)}
                         for s in av.steady_states(printed_flow, printed.r_max)],
        "backbone": {"corrected_lindstedt": [model.backbone.kappa2, model.backbone.kappa4],
                     "first_order": [av.backbone(model.eq, "first-order").kappa2,
                                     av.backbone(model.eq, "first-order").kappa4],
                     "printed_eq59_60": [printed.backbone.kappa2, printed.backbone.kappa4]},
        "trace_J": {"printed_eq68": scene.mu, "corrected": -scene.mu},
        "subcase_1a": subcase_1a_check(),
    }


def response_curve(model: av.Averaged, samples: int = 400) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(omega, r, stable) along the slow flow's whole frequency-response curve: up the left side of the
    backbone to the peak and down the right side, traced by amplitude (av.frequency_on_curve)."""
    s = model.scene
    r_peak = min(s.Delta / (s.mu * model.omega_e), model.r_max) if s.mu > 0 else model.r_max
    radii = np.geomspace(1e-3 * r_peak, r_peak * (1 - 1e-12), samples)
    points = []
    for side, rs in ((-1, radii), (1, radii[::-1])):
        for r in rs:
            omega = av.frequency_on_curve(model, r, side)
            if omega is not None:
                points.append((omega, r, av.steady_state(model.flow(omega), r).det > 0.0))
    omega, r, stable = (np.array(column) for column in zip(*points))
    return omega, r, stable


def stability_study(scene: Scene, omega_range: tuple[float, float] | None = None, n: int = 201,
                    fmu=None, sweep_points: int = 25, settings: Settings = Settings(), progress=None) -> dict:
    """Everything `vibrofmu stability` reports; fmu=None skips the FMU sweeps."""
    model = av.averaged(scene)
    lo, hi = omega_range or default_range(model)
    periodic = shooting.PeriodicModel(scene)
    timings = {}

    started = time.perf_counter()
    slow_folds = av.folds(model)
    grid = np.linspace(lo, hi, n)
    timings["slow_flow_s"] = time.perf_counter() - started

    started = time.perf_counter()
    points = []
    for i, omega in enumerate(grid):
        points.append(shoot_predictions(model, periodic, omega))
        if progress:
            progress("shooting", i + 1, n)
    response = shooting.frequency_response(periodic, lo, hi, max_step=0.008)
    continuation_folds = sorted(response.folds, key=lambda fold: fold.omega)
    timings["shooting_and_continuation_s"] = time.perf_counter() - started

    fold_uncertainty = max([abs(c.omega - s.omega) for s, c in zip(slow_folds, continuation_folds)], default=0.0)
    margin = FOLD_MARGIN * fold_uncertainty + (hi - lo) / (n - 1)
    summary = {
        "scene": scene.as_dict(),
        "omega_range": [lo, hi], "grid_points": n,
        "equilibrium": {"x_e": model.eq.x_e, "omega_e": model.omega_e, "A": list(model.eq.A),
                        "k": list(model.eq.k)},
        "backbone": {"kind": model.backbone.kind, "kappa2": model.backbone.kappa2, "kappa4": model.backbone.kappa4},
        "validity_notes": av.validity_notes(model),
        "shooting_model": "Eq. 3 with the AC drive at its mean (no T-periodic orbit exists with it on)",
        "slow_flow": [{"omega": p.omega, "states": [state_record(s, p.omega) for s in p.slow]} for p in points],
        "floquet": [{"omega": p.omega, "orbits": [None if o is None else {
            "r": o.r, "kind": floquet_type(o), "multipliers": [[z.real, z.imag] for z in o.multipliers],
            "liouville_error": o.liouville_error} for o in p.orbits]} for p in points],
        "continuation": {"points": len(response.omega), "folds": [
            {"omega": f.omega, "omega_multiplier_one": f.omega_multiplier, "r": f.r} for f in continuation_folds],
            "max_liouville_error": float(np.max(response.liouville_error))},
        "classification_agreement": agreement(points, [f.omega for f in slow_folds + continuation_folds], margin),
        "slow_flow_vs_shooting": branch_errors(points),
        "paper_mode": paper_mode(scene, scene.omega),
        "timings": timings,
    }
    sweeps = []
    if fmu is not None:
        started = time.perf_counter()
        omegas = sweep_grid(model, slow_folds, lo, hi, sweep_points)
        step = float(omegas[1] - omegas[0]) if len(omegas) > 1 else math.nan
        for order, label in ((omegas, "up"), (omegas[::-1], "down")):
            sweeps.append(sweep(fmu, scene.with_values(omega=order[0]), order, settings,
                                progress=(lambda i, k, label=label: progress(f"FMU sweep {label}", i, k))
                                if progress else None))
        timings["fmu_sweeps_s"] = time.perf_counter() - started
        summary["fmu_sweeps"] = {
            "criterion": f"complex first harmonic settled to {SETTLE_TOLERANCE:g} relative, windows of "
                         f"{WINDOW_PERIODS} periods (sweep.py)", **sweep_summary(sweeps, model, slow_folds, step)}
        summary["fidelity_3"] = fidelity3_check(fmu, scene, stop_time=fidelity3_stop_time(scene))
    else:
        step = math.nan
    summary["fold_frequencies"] = fold_agreement(model, slow_folds, continuation_folds, sweeps, step)
    return {"summary": summary, "model": model, "points": points, "response": response, "sweeps": sweeps,
            "folds": [f.omega for f in slow_folds]}


def write_study(study: dict, out_dir: Path) -> None:
    """DIR/summary.json and DIR/frequency_response.png."""
    out_dir.mkdir(parents=True, exist_ok=True)
    export.write_json(out_dir / "summary.json", study["summary"])
    response = study["response"]
    s = study["model"].scene
    export.plot_frequency_response(
        out_dir / "frequency_response.png", response_curve(study["model"]),
        (response.omega, response.r, response.stable), study["sweeps"], study["folds"], study["summary"]["omega_range"],
        "frequency response: " + export.scene_text({name: getattr(s, name) for name in
                                                    ("mu", "Delta", "alpha", "beta", "gamma", "Omega")}))


def multiplier_error_note(scene: Scene, model: av.Averaged, omega: float) -> str | None:
    """Why the slow flow's multipliers miss Floquet's far from resonance (docs/numerics.md): the slow flow turns at
    (omega^2 - k1)/(2 omega) instead of omega - sqrt(k1 - mu^2/4), and that phase error per period gives
    |exp(lambda T) - rho| ~ exp(-mu T/2) 2|sin(dphi/2)|. None when omega is not a number (no orbits on the grid)
    or the linearisation is not underdamped."""
    k1 = model.omega_e**2
    if not (omega == omega and k1 > scene.mu**2 / 4):
        return None
    period = 2 * math.pi / omega
    phase = (omega - math.sqrt(k1 - scene.mu**2 / 4) - (omega * omega - k1) / (2 * omega)) * period
    return (f"  (expected far from resonance: the slow flow turns at (omega^2 - k1)/(2 omega) instead of "
            f"omega - sqrt(k1 - mu^2/4); the phase error per period gives |exp(lambda T) - rho| ~ "
            f"exp(-mu T/2) 2|sin(dphi/2)| = {math.exp(-scene.mu * period / 2) * abs(2 * math.sin(phase / 2)):.2e} "
            f"at omega {omega:.6g}; see docs/numerics.md)")
