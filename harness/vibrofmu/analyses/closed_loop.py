"""`vibrofmu closed-loop`: the adaptive controller on the plant, monolithic (one FMU) or as a co-simulation of
three FMUs; CSV, summary.json, plots, and for cosim the convergence study against the monolithic loop."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from vibromodel.closedloop import ERRATA_SCENE
from vibromodel.control import ESTIMATE_NAMES, THETA_NAMES, Law, true_theta
from vibromodel.parameters import Scene, scene_names
from vibromodel.tracking import ReferenceKind

from vibrofmu.output import export
from vibrofmu.hosts.cosim import CosimScene, run_cosim
from vibrofmu.hosts.run import run_fmu

TOLERANCE = 1e-10  # rtol of the plant's integrator (docs/model.md, Adaptive controller simulation)
STUDY_STEPS = (0.5, 0.2, 0.1, 0.05, 0.02)
STUDY_EVERY = 1.0  # errors are compared at tau = 0, 1, 2, ...: a multiple of every H of the study
ROLES = ("reference", "plant", "controller")  # FMU names the study maps onto the monolithic FMU's parameters


def monolithic(fmu: Path, start_values: dict, stop_time: float, step: float, progress=None) -> dict:
    """Run the closed-loop FMU; the columns named as in a cosim's plant/controller."""
    run = run_fmu(fmu, start_values, stop_time, step, tolerance=TOLERANCE, progress=progress)
    return {"time": run.time, "series": run.outputs, "completed": run.completed, "stop_reason": run.stop_reason,
            "wall_time_s": run.wall_time, "log": run.log[-20:]}


def cosimulation(scene: CosimScene, progress=None) -> dict:
    """Run a cosim scene; series under the monolithic names (plant x, v; reference x as x_ref; controller's rest)."""
    run = run_cosim(scene, progress=progress)
    out = run.outputs
    series = {name: out[f"controller.{name}"] for name in ("U", "e1", "e2", "V", *ESTIMATE_NAMES)
              if f"controller.{name}" in out}
    series.update({"x": out.get("plant.x"), "v": out.get("plant.v"), "x_ref": out.get("reference.x")})
    return {"time": run.time, "series": {k: v for k, v in series.items() if v is not None}, "all_outputs": out,
            "completed": run.completed, "stop_reason": run.stop_reason, "wall_time_s": run.wall_time,
            "log": {name: messages[-10:] for name, messages in run.log.items()}}


def with_law(scene: CosimScene, law: Law | None) -> CosimScene:
    """The law set on every FMU of the scene that has a `law` parameter (the controller)."""
    if law is None:
        return scene
    fmus = tuple(replace(spec, parameters={**spec.parameters, "law": int(law)}) if spec.name == "controller"
                 else spec for spec in scene.fmus)
    return replace(scene, fmus=fmus)


def monolithic_equivalent(scene: CosimScene) -> dict:
    """Start values of the closed-loop FMU that describe the same loop as a scene with FMUs named
    reference (plant FMU at fidelity 4), plant and controller: OAFM reference from the reference's initial state."""
    specs = {spec.name: spec.parameters for spec in scene.fmus}
    missing = [role for role in ROLES if role not in specs]
    if missing:
        raise ValueError(f"the convergence study needs FMUs named {', '.join(ROLES)}; missing {', '.join(missing)}")
    reference, plant, controller = (specs[role] for role in ROLES)
    values = {**controller, **plant, "reference": int(ReferenceKind.OAFM)}
    values["x_ref_start"] = reference.get("x_start", Scene().x_start)
    values["v_ref_start"] = reference.get("v_start", Scene().v_start)
    values.pop("U", None)
    return values


def convergence_study(scene: CosimScene, closed_loop_fmu: Path, steps=STUDY_STEPS, progress=None) -> dict:
    """max |x_cosim - x_mono| at tau = 0, 1, 2, ... for each H and ordering; order between successive H."""
    mono = monolithic(closed_loop_fmu, monolithic_equivalent(scene), scene.stop_time, STUDY_EVERY)
    table = {}
    for ordering in ("gauss-seidel", "jacobi"):
        rows = []
        for H in steps:
            run = cosimulation(scene.with_settings(step=H, ordering=ordering), progress)
            every = int(round(STUDY_EVERY / H))
            n = min(len(run["time"][::every]), len(mono["time"]))
            x = run["series"]["x"][::every][:n]
            error = float(np.max(np.abs(x - mono["series"]["x"][:n]))) if run["completed"] else None
            rows.append({"H": H, "max_abs_error_x": error, "wall_time_s": run["wall_time_s"],
                         "completed": run["completed"], "stop_reason": run["stop_reason"]})
        for coarse, fine in zip(rows, rows[1:]):
            if coarse["completed"] and fine["completed"]:
                fine["order"] = math.log(coarse["max_abs_error_x"] / fine["max_abs_error_x"]) / math.log(
                    coarse["H"] / fine["H"])
        table[ordering] = rows
    return {"reference": "monolithic HertzEAClosedLoop.fmu, same parameters, OAFM reference, rtol 1e-10",
            "compared_at": f"tau = 0, {STUDY_EVERY:g}, ..., {scene.stop_time:g}", "table": table}


def summarise(result: dict, theta: dict) -> dict:
    s, t = result["series"], result["time"]
    summary = {"completed": result["completed"], "stop_reason": result["stop_reason"],
               "end_time": float(t[-1]) if len(t) else math.nan, "wall_time_s": result["wall_time_s"]}
    if len(t) > 1:
        V = s["V"]
        summary.update({
            "final_abs_e1": abs(float(s["e1"][-1])), "final_abs_e2": abs(float(s["e2"][-1])),
            "max_abs_e1_second_half": float(np.max(np.abs(s["e1"][t >= t[-1] / 2]))),
            "V_start": float(V[0]), "V_end": float(V[-1]), "max_V_increase": float(np.max(np.diff(V))),
            "estimates": {name: {"final": float(s[f"{name}_hat"][-1]), "true": true,
                                 "error": float(s[f"{name}_hat"][-1]) - true} for name, true in theta.items()},
        })
    if "V_rate" in s:
        summary["max_abs_V_rate_minus_promised"] = float(np.max(np.abs(s["V_rate"] - s["V_rate_promised"])))
    return summary


def write_results(out_dir: Path, result: dict, summary: dict, theta: dict, title: str) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    export.write_csv(out_dir / "result.csv", result["time"], result.get("all_outputs", result["series"]))
    export.write_json(out_dir / "summary.json", summary)
    if len(result["time"]) > 1:
        export.plot_closed_loop(out_dir, result["time"], result["series"], theta, title)


def true_values(parameters: dict) -> dict:
    """True theta (Eq. 73) of the plant parameters given (defaults elsewhere)."""
    scene = Scene(**{name: float(parameters.get(name, getattr(ERRATA_SCENE, name))) for name in scene_names()})
    return dict(zip(THETA_NAMES, map(float, true_theta(scene))))
