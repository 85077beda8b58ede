"""The rungs' error estimates against the exact model (vibromodel.error_estimates; docs/rungs.md, Error estimates).

- slow_ac_grid(fmu): the paper scene with beta in {0.01, 0.02, 0.03, 0.05, 0.08} x Omega in {0.3, ..., 6} through the
  plant FMU, fidelities 3 and 4 against fidelity 0 over [0, 50]: each cell refused, warned (an fmi2Warning in the
  log) or accepted, with its error / max|x0| and the estimate the FMU logged.
- campaign(rung, n, seed): n random scenes over the documented ranges (slow and fast drives, light damping, near
  contact loss, near pull-in, long runs) of one rung; the rung's estimate against its measured max|x - x_ref| at the
  communication points, x_ref from the compiled exact plant at rtol 1e-12 (in-process, fast). Counts: the estimate
  bounds the measured error (>= 99 % wanted), within 100x of it (>= 90 % wanted).

Command line: python -m vibrofmu.analyses.error_calibration grid FMU | campaign RUNG [n] [seed]
(RUNG: averaged, analytic, exact, rk4, polynomial; prints progress on stderr and JSON on stdout).
"""
from __future__ import annotations

import json
import math
import sys
import tempfile
import time

import numpy as np

from vibrofmu.analyses.domains import campaign_kernel, run_steps
from vibrofmu.analyses.simulate import logged_estimate
from vibromodel.integrate import IntegrationError
from vibromodel.parameters import ParameterError, Scene
from vibromodel.plant import Settings, make_plant

BETAS = (0.01, 0.02, 0.03, 0.05, 0.08)
OMEGAS = (0.3, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0, 6.0)
SHARE = 0.05  # the acceptance: within 5 % of max|x0|, else warned or refused


def _fmu_run(fmu, unzip_dir, values: dict, stop: float, h: float) -> dict:
    """One run of the plant FMU from an extracted copy: x at the communication points, the log, the estimate."""
    from fmpy.fmi1 import FMICallException

    from vibrofmu.hosts.run import FmuInstance

    instance = FmuInstance(fmu, unzip_dir=unzip_dir)
    xs, refused = [], None
    try:
        instance.set(values)
        instance.fmu.setupExperiment(startTime=0.0, stopTime=stop)
        try:
            instance.fmu.enterInitializationMode()
            instance.fmu.exitInitializationMode()
        except FMICallException as error:
            refused = str(error)
        x_ref = instance.value_references(["x"])
        if refused is None:
            for i in range(int(round(stop / h))):
                try:
                    instance.fmu.doStep(i * h, h)
                except FMICallException:
                    break
                xs.append(instance.fmu.getReal([x_ref[0]])[0])
        log = list(instance.log.messages)
    finally:
        instance.close()
    estimate = logged_estimate(log)
    return {"x": np.array(xs), "refused": refused, "log": log, "estimate": math.nan if estimate is None else estimate}


def slow_ac_grid(fmu, fidelities=(3, 4), stop: float = 50.0, h: float = 0.1, betas=BETAS, omegas=OMEGAS,
                 progress=None) -> dict:
    """The slow-AC grid through the plant FMU (module docstring)."""
    from fmpy import extract

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        unzip_dir = extract(str(fmu), unzipdir=tmp)
        for beta in betas:
            for Omega in omegas:
                exact = _fmu_run(fmu, unzip_dir, {"beta": beta, "Omega": Omega, "fidelity": 0}, stop, h)["x"]
                for fidelity in fidelities:
                    run = _fmu_run(fmu, unzip_dir, {"beta": beta, "Omega": Omega, "fidelity": fidelity}, stop, h)
                    n = min(len(run["x"]), len(exact))
                    error = float(np.max(np.abs(run["x"][:n] - exact[:n]))) if n else math.nan
                    warned = [m for m in run["log"] if m.startswith("[warning]")]
                    outcome = "refused" if run["refused"] else "warned" if warned else "accepted"
                    relative = error / float(np.max(np.abs(exact[:n]))) if n else math.nan
                    rows.append({"beta": beta, "Omega": Omega, "fidelity": fidelity, "outcome": outcome,
                                 "relative_error": relative, "estimate": run["estimate"], "steps": n,
                                 "exact_steps": len(exact), "warnings": warned})
                    if progress:
                        progress(f"beta {beta:g} Omega {Omega:g} fidelity {fidelity}: {outcome}, error {relative:.3g}"
                                 f" of max|x0|, estimate {run['estimate']:.3g}")
    silent_wrong = [r for r in rows if r["outcome"] == "accepted" and not r["relative_error"] <= SHARE]
    return {"rows": rows, "summary": {"cells": len(rows), "refused": sum(r["outcome"] == "refused" for r in rows),
                                      "warned": sum(r["outcome"] == "warned" for r in rows),
                                      "accepted": sum(r["outcome"] == "accepted" for r in rows),
                                      "accepted_beyond_share": len(silent_wrong)}}


# -- the calibration campaign ----------------------------------------------------------------------------------------

RUNGS = {"averaged": {"fidelity": 3}, "analytic": {"fidelity": 4}, "exact": {"fidelity": 0},
         "rk4": {"fidelity": 0, "solver": 1}, "polynomial": {"fidelity": 1}}


def random_scene(rng: np.random.Generator) -> tuple[Scene, float, dict]:
    """(scene, stop time, rung settings' extras) over the documented ranges: one of five kinds of scene."""
    kind = rng.choice(["slow_ac", "fast_ac", "light_damping", "near_contact_loss", "near_pull_in", "long"])
    mu = float(10 ** rng.uniform(-2, -0.3))
    Delta = float(10 ** rng.uniform(-4, -1.5))
    omega = float(rng.uniform(0.85, 1.15))
    beta = float(10 ** rng.uniform(-4, -1.2))
    Omega = float(10 ** rng.uniform(math.log10(2.0), 1.0))
    gamma = float(10 ** rng.uniform(-4, -2))
    alpha = float(10 ** rng.uniform(-4, -1.5))
    R = 1.0
    x_start = float(rng.uniform(-0.1, 0.1))
    stop = float(rng.uniform(20.0, 100.0))
    if kind == "slow_ac":
        Omega = float(rng.uniform(0.2, 2.0))
    elif kind == "light_damping":
        mu = float(10 ** rng.uniform(-3, -2))
    elif kind == "near_contact_loss":
        Delta = float(10 ** rng.uniform(-2, -1)) * mu
        x_start = float(rng.uniform(-0.6, 0.6))
    elif kind == "near_pull_in":
        R = float(rng.uniform(0.3, 1.0))
        alpha = float(rng.uniform(0.02, 0.1)) * R
        x_start = float(rng.uniform(-0.2, 0.2)) * R
    elif kind == "long":
        stop = float(rng.uniform(200.0, 600.0))
    scene = Scene(mu=mu, Delta=Delta, omega=omega, Omega=Omega, alpha=alpha, beta=beta, gamma=gamma, R=R,
                  x_start=x_start)
    return scene, stop, {"kind": str(kind)}


def _settings(rung: str, rng: np.random.Generator) -> Settings:
    extras = dict(RUNGS[rung])
    if rung == "exact":
        extras["rtol"] = float(10 ** rng.uniform(-10, -3))
    if rung == "rk4":
        extras["max_step"] = float(10 ** rng.uniform(-2.5, -0.7))
    return Settings(**extras)


def campaign(rung: str, n: int = 1000, seed: int = 0, h: float = 0.1, progress=None) -> dict:
    """The rung's estimate against its measured error over n random scenes (module docstring)."""
    library, rows = campaign_kernel(), []
    rng = np.random.default_rng(seed)
    started = time.perf_counter()
    while len(rows) < n:
        scene, stop, info = random_scene(rng)
        settings = _settings(rung, rng)
        try:
            reference = make_plant(scene, Settings(rtol=1e-12), 0.0, stop, library=library)
            exact, exact_stop = run_steps(reference, stop, h)
            plant = make_plant(scene, settings, 0.0, stop, library=library)
        except (ParameterError, IntegrationError) as error:
            rows.append({**info, "outcome": "refused", "message": str(error)[:200]})
            continue
        x, _ = run_steps(plant, stop, h)
        m = min(len(x), len(exact))
        if m == 0:
            rows.append({**info, "outcome": "refused", "message": "no step"})
            continue
        measured = float(np.max(np.abs(x[:m] - exact[:m])))
        estimate = plant.error_estimate["estimate"]
        rows.append({**info, "outcome": "warned" if plant.warnings else "accepted", "measured": measured,
                     "estimate": estimate, "amplitude": float(np.max(np.abs(exact[:m]))), "stop": stop,
                     "exact_stopped": exact_stop is not None, "scene": scene.as_dict(),
                     "settings": {"rtol": settings.rtol, "max_step": settings.max_step}})
        if progress and len(rows) % 25 == 0:
            progress(f"{rung}: {len(rows)}/{n} scenes, {time.perf_counter() - started:.0f} s")
    return {"rung": rung, "seed": seed, "rows": rows, "summary": summary(rows)}


# Measured errors below this share of the amplitude are round-off of the reference itself (rtol 1e-12, the
# communication points' sums): such a scene counts as bounded, and within 100x when the estimate is below 100 times
# the floor.
REFERENCE_FLOOR = 1e-11


def summary(rows: list[dict]) -> dict:
    estimated = [r for r in rows if "measured" in r]
    bounded = within = 0
    for r in estimated:
        floor = REFERENCE_FLOOR * r["amplitude"]
        measured = max(r["measured"], floor)
        bounded += r["estimate"] >= r["measured"] or r["measured"] <= floor
        within += measured / 100.0 <= r["estimate"] <= 100.0 * measured
    ratios = [r["estimate"] / r["measured"] for r in estimated if r["measured"] > 0.0]
    count = len(estimated)
    return {"scenes": len(rows), "estimated": count, "refused": len(rows) - count,
            "warned": sum(r["outcome"] == "warned" for r in rows),
            "bounded_share": bounded / count if count else math.nan,
            "within_100x_share": within / count if count else math.nan,
            "ratio_min": min(ratios, default=math.nan), "ratio_median": float(np.median(ratios)) if ratios else math.nan,
            "ratio_max": max(ratios, default=math.nan)}


def main(argv: list[str]) -> None:
    def progress(text):
        print(text, file=sys.stderr, flush=True)

    if argv[:1] == ["grid"] and len(argv) == 2:
        print(json.dumps(slow_ac_grid(argv[1], progress=progress), indent=1))
    elif argv[:1] == ["campaign"] and len(argv) in (2, 3, 4) and argv[1] in RUNGS:
        n = int(argv[2]) if len(argv) > 2 else 1000
        seed = int(argv[3]) if len(argv) > 3 else 0
        result = campaign(argv[1], n, seed, progress=progress)
        print(json.dumps(result, indent=1))
        progress(json.dumps(result["summary"]))
    else:
        print(f"error: usage: python -m vibrofmu.analyses.error_calibration grid FMU | campaign "
              f"{{{','.join(RUNGS)}}} [n] [seed]", file=sys.stderr)
        raise SystemExit(2)


if __name__ == "__main__":
    main(sys.argv[1:])
