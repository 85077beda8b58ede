"""`vibrofmu oafm`: fit the OAFM solution, measure it against the reference, reproduce the paper's numbers.

Errors are max |x~ - x_ref| on a uniform grid of spacing <= ERROR_SPACING over each domain, against the
DOP853 rtol 1e-12 reference of the exact Eq. 3.
"""
from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import linprog

from vibromodel.analytic import OafmSettings, domains, solve
from vibromodel.oafm_bases import paper_transient_basis
from vibromodel.oafm_printed import C1_C4, TAU_STAR, printed_solution
from vibromodel.parameters import Scene, consistency_warning

from vibrofmu.output import export
from vibrofmu.analyses.reference import reference_solution
from vibrofmu.hosts.run import run_fmu

ERROR_SPACING = 0.02  # 300+ points per forcing period
BREAKDOWN_FRACTION = 0.01  # error above 1 % of the domain's amplitude: not a valid approximation there
EXTRAPOLATION_FACTOR = 1.5  # extrapolation is checked on [tau_end, 1.5 tau_end]
PAPER_END = 200.0  # the paper's figures end at tau = 200


def uniform(start: float, end: float) -> np.ndarray:
    return np.linspace(start, end, int(np.ceil((end - start) / ERROR_SPACING)) + 1)


def domain_error(solution, reference, start: float, end: float) -> dict:
    tau = uniform(start, end)
    x_ref = reference(tau)[0]
    error = np.abs(solution(tau)[0] - x_ref)
    amplitude = float(np.max(np.abs(x_ref)))
    worst = int(np.argmax(error))
    return {"interval": [start, end], "max_abs_error": float(error[worst]), "tau_of_max_error": float(tau[worst]),
            "amplitude": amplitude, "relative_to_amplitude": float(error[worst]) / amplitude,
            "valid": bool(error[worst] <= BREAKDOWN_FRACTION * amplitude)}


def describe(solution, reference, extrapolate_to: float | None) -> dict:
    """Per domain: C_i, residual norms, fit cost, error and verdict; plus continuity and the start."""
    first = solution.pieces[0]
    x0, v0, _ = solution.state(first.start)
    report = {"domains": [], "start": {"x": x0, "v": v0}}
    for piece in solution.pieces:
        report["domains"].append({
            "basis": piece.basis_name, "interval": [piece.start, piece.end], "C": list(piece.C),
            "residual_rms": piece.residual_rms, "residual_max": piece.residual_max, "fit": piece.fit,
            "error": domain_error(solution, reference, piece.start, piece.end)})
    for left, right in zip(solution.pieces, solution.pieces[1:]):
        jump = right.evaluate(0.0) - left.evaluate(right.start - left.start)
        report.setdefault("continuity", []).append({"tau": right.start, "jump_x": jump[0], "jump_v": jump[1]})
    if extrapolate_to is not None:
        report["extrapolation"] = domain_error(solution, reference, solution.pieces[-1].end, extrapolate_to)
    return report


def max_errors(report: dict) -> list[float]:
    return [d["error"]["max_abs_error"] for d in report["domains"]]


def grid_check(scene: Scene, settings: OafmSettings, reference, errors: list[float]) -> dict:
    """The same fit on a grid with twice the points: the relative change of each domain's error."""
    doubled = dataclasses.replace(settings, grid=settings.grid.doubled())
    new = max_errors(describe(solve(scene, doubled), reference, None))
    change = [abs(b - a) / a for a, b in zip(errors, new)]
    return {"grid": dataclasses.asdict(doubled.grid), "max_abs_error": new, "relative_change": change,
            "converged": bool(max(change) < 0.01)}


def convergence_study(scene: Scene, settings: OafmSettings, reference, orders) -> list[dict]:
    rows = []
    for order in orders:
        print(f"oafm: convergence study, order {order} ...", file=sys.stderr, flush=True)
        clock = time.perf_counter()
        solution = solve(scene, dataclasses.replace(settings, basis="harmonic", order=order))
        report = describe(solution, reference, None)
        rows.append({"order": order, "unknowns": [len(p.C) for p in solution.pieces],
                     "max_abs_error": max_errors(report),
                     "residual_rms": [p.residual_rms for p in solution.pieces],
                     "seconds": time.perf_counter() - clock})
    return rows


def paper_reproduction(scene: Scene, reference) -> dict:
    """docs/model.md, The paper's example reproduced's table: the printed formulas and constants, and what the paper's basis can do at best."""
    if scene != Scene():
        return {"note": "the printed C1..C7 belong to the paper's example; not evaluated for this scene"}
    printed = printed_solution(scene)
    basis = paper_transient_basis(scene, 0.0, scene.x_start, scene.v_start)
    tau = uniform(0.0, TAU_STAR)
    target = reference(tau)[0] - basis.x0(tau)
    Y = np.column_stack([f(tau) for f in basis.functions])
    l2 = np.linalg.lstsq(Y, target, rcond=None)[0]
    minimax = _minimax_fit(Y, target)
    optimal = solve(scene, OafmSettings(basis="paper", tau_star=TAU_STAR, tau_end=PAPER_END))
    optimal_errors = max_errors(describe(optimal, reference, None))

    def transient_error(x_of_tau) -> float:
        return float(np.max(np.abs(x_of_tau(tau) - reference(tau)[0])))

    x_start, v_start, _ = printed.state(0.0)
    return {
        "printed_eq30": {"error_0_50": domain_error(printed, reference, 0.0, TAU_STAR)["max_abs_error"],
                         "x0": x_start, "v0": v_start},
        "eq29_bracket_corrected_M_printed_C": transient_error(basis.solution(C1_C4)),
        "x0_alone_eq15": transient_error(basis.x0),
        "best_L2_fit_C1_C4": {"C": l2.tolist(), "error_0_50": float(np.max(np.abs(Y @ l2 - target)))},
        "best_minimax_fit_C1_C4": {"C": minimax.tolist(), "error_0_50": float(np.max(np.abs(Y @ minimax - target)))},
        "oafm_optimal_paper_basis": {"C": optimal.C, "error_0_50": optimal_errors[0],
                                     "error_50_200": optimal_errors[1]},
        "printed_steady_eq33_35": {
            "error_50_200": domain_error(printed, reference, TAU_STAR, PAPER_END)["max_abs_error"]},
    }


def _minimax_fit(Y: np.ndarray, target: np.ndarray) -> np.ndarray:
    """C minimising max |Y C - target| (linear program: min t with -t <= Y C - target <= t)."""
    n, ones = Y.shape[1], np.ones((len(target), 1))
    result = linprog(np.r_[np.zeros(n), 1.0], A_ub=np.block([[Y, -ones], [-Y, -ones]]),
                     b_ub=np.r_[target, -target], bounds=[(None, None)] * n + [(0, None)], method="highs")
    return result.x[:n]


def fmu_check(fmu: Path, scene: Scene, settings: OafmSettings, solution, tau_end: float) -> dict:
    """The plant FMU at fidelity 4 with the same settings against this fit, and its cost per doStep
    against fidelity 0 (adaptive DOP853, rtol 1e-8) on the same grid (output interval 0.1), side by side."""
    tau_star = solution.pieces[1].start
    values = {**scene.as_dict(), "oafm_order": settings.order, "tau_star": tau_star, "oafm_tau_end": tau_end}
    runs = {fidelity: run_fmu(fmu, {**values, "fidelity": fidelity}, tau_end, 0.1) for fidelity in (4, 0)}
    analytic = runs[4]
    if not analytic.completed:
        return {"error": f"the FMU stopped at tau = {analytic.end_time:g}: {analytic.stop_reason}"}
    steps = {fidelity: len(run.time) - 1 for fidelity, run in runs.items()}
    per_step = {fidelity: run.wall_time / max(steps[fidelity], 1) for fidelity, run in runs.items()}
    x, v, _ = solution(analytic.time)
    return {"fmu": str(fmu), "steps": steps[4], "log": analytic.log[:3],
            "max_abs_difference_x": float(np.max(np.abs(analytic.outputs["x"] - x))),
            "max_abs_difference_v": float(np.max(np.abs(analytic.outputs["v"] - v))),
            "seconds_per_step_fidelity_4": per_step[4], "seconds_per_step_fidelity_0": per_step[0],
            "cost_ratio_4_over_0": per_step[4] / per_step[0],
            "instantiate_seconds_fidelity_4": analytic.instantiate_time}


def run_oafm(scene: Scene, settings: OafmSettings, out_dir: Path, study_orders=range(1, 7),
             fmu: Path | None = None) -> dict:
    """Fit, compare, study (and check the FMU when given one); write out_dir/summary.json, oafm.csv,
    oafm.png and convergence.png."""
    settings.validate()
    tau_star, tau_end = domains(scene, settings)
    extrapolate_to = EXTRAPOLATION_FACTOR * tau_end
    print(f"oafm: reference on [0, {extrapolate_to:g}] ...", file=sys.stderr, flush=True)
    reference = reference_solution(scene, 0, extrapolate_to)
    print(f"oafm: fitting {settings.basis} basis, tau* = {tau_star:.6g}, tau_end = {tau_end:.6g} ...",
          file=sys.stderr, flush=True)
    clock = time.perf_counter()
    solution = solve(scene, settings)
    seconds = time.perf_counter() - clock
    report = describe(solution, reference, extrapolate_to)
    warning = consistency_warning(scene)
    summary = {
        "parameters": scene.as_dict(),
        "notes": [warning] if warning else [],
        "basis": settings.basis, "order": settings.order if settings.basis == "harmonic" else None,
        "tau_star": tau_star, "tau_end": tau_end,
        "functional": "J(C) = (1/T) * integral over the domain of R^2, R = x~'' - accel(tau, x~, x~') of Eq. 3; "
                      f"composite Gauss-Legendre, {settings.grid.nodes} nodes per panel of length "
                      f"<= {settings.grid.panel:g}; scipy.optimize.least_squares (Levenberg-Marquardt)",
        "seconds": seconds,
        **report,
    }
    summary["verdict"] = verdict(summary)
    summary["grid_check"] = grid_check(scene, settings, reference, max_errors(report))
    if study_orders:
        summary["convergence"] = convergence_study(scene, settings, reference, list(study_orders))
    summary["paper_reproduction"] = paper_reproduction(scene, reference)
    if fmu is not None and settings.basis == "harmonic":
        print(f"oafm: running {fmu} at fidelity 4 and 0 ...", file=sys.stderr, flush=True)
        summary["fmu_check"] = fmu_check(fmu, scene, settings, solution, tau_end)
    write_outputs(out_dir, summary, solution, reference, extrapolate_to)
    return summary


def verdict(summary: dict) -> str:
    bad = [d for d in summary["domains"] if not d["error"]["valid"]]
    if bad:
        where = ", ".join(f"[{d['interval'][0]:g}, {d['interval'][1]:g}] "
                          f"({100 * d['error']['relative_to_amplitude']:.2g} % of the amplitude)" for d in bad)
        return f"OAFM breaks down on {where}: do not use this approximation there"
    text = "OAFM valid on both domains (error below 1 % of the amplitude)"
    extrapolation = summary["extrapolation"]
    if not extrapolation["valid"]:
        text += (f"; beyond tau_end = {summary['tau_end']:g} it breaks down "
                 f"({100 * extrapolation['relative_to_amplitude']:.2g} % of the amplitude): fit a longer tau_end")
    return text


def write_outputs(out_dir: Path, summary: dict, solution, reference, extrapolate_to: float) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    tau = np.arange(0.0, extrapolate_to + 1e-9, 0.1)
    x, v, a = solution(tau)
    x_ref, v_ref = reference(tau)
    export.write_csv(out_dir / "oafm.csv", tau, {"x_oafm": x, "v_oafm": v, "a_oafm": a, "x_ref": x_ref,
                                                 "v_ref": v_ref, "abs_error_x": np.abs(x - x_ref)})
    export.write_json(out_dir / "summary.json", summary)
    fine = uniform(0.0, extrapolate_to)
    export.plot_analytic(out_dir / "oafm.png", fine, solution(fine)[0], reference(fine)[0],
                         [summary["tau_star"], summary["tau_end"]], f"OAFM ({summary['basis']}) vs numerical")
    if "convergence" in summary:
        export.plot_convergence(out_dir / "convergence.png", summary["convergence"])
