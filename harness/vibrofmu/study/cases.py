"""The cases of each kind (made identically on every run, so that --resume can skip by case id) and how a
worker runs one case into its Parquet rows.

A case is a dict with its id `case` and what the worker needs; `run_case` returns one row per point:
- monte-carlo: one sample of the toleranced parameters, settled from the scene's start state; 1 row;
- basins: one initial state (x0, v0) at the bistable point, settled; 1 row with the averaged prediction.
  `branch` is the stable state the last window's first harmonic is at (branch_of), also for a run that
  reached MAX_PERIODS unsettled: with Omega = 2 near 2 omega the AC drive beats the settled vibration by
  ~0.5 % (sweep.py), more than the settling bound at mu = 0.002 allows, yet the run is at its attractor;
- response-map: one sweep of omega at one Delta, up or down, each point continued from the previous point's
  end state (as sweep.py does); one row per frequency. The settling bound uses the slowest decay rate of
  the slow flow's stable states there (settling_rate), not mu/2: near a fold a node decays slower.
"""
from __future__ import annotations

import math
import os
import socket

import numpy as np

from vibromodel import averaging as av
from vibromodel.parameters import Scene

from vibrofmu.study.spec import Spec


def basins_omega(spec: Spec) -> float:
    """omega = omega_e + sigma unless the spec sets omega."""
    scene = spec.base_scene()
    if "omega" in spec.scene:
        return scene.omega
    return av.averaged(scene).omega_e + spec.settings["sigma"]


def make_cases(spec: Spec) -> list[dict]:
    if spec.kind == "monte-carlo":
        return monte_carlo_samples(spec)
    if spec.kind == "basins":
        omega = basins_omega(spec)
        return [{"case": i * len(spec.axis("v0")) + j, "i": i, "j": j, "x0": x0, "v0": v0, "omega": omega}
                for i, x0 in enumerate(spec.axis("x0")) for j, v0 in enumerate(spec.axis("v0"))]
    omega_e = av.averaged(spec.base_scene()).omega_e
    omegas = [omega_e + offset for offset in spec.axis("omega_offset")]
    cases = []
    for j, delta in enumerate(spec.axis("Delta")):
        for d, direction in enumerate(("up", "down")):
            cases.append({"case": 2 * j + d, "Delta_index": j, "Delta": delta, "direction": direction,
                          "omegas": omegas if direction == "up" else omegas[::-1]})
    return cases


def monte_carlo_samples(spec: Spec) -> list[dict]:
    """N draws of every toleranced parameter around the base scene: uniform on nominal (1 -+ relative), or
    normal with standard deviation relative * nominal (drawn in sorted parameter order, so reproducible)."""
    base = spec.base_scene().as_dict()
    rng = np.random.default_rng(int(spec.settings["seed"]))
    n = int(spec.settings["samples"])
    draws = {}
    for name in sorted(spec.tolerances):
        tolerance, nominal = spec.tolerances[name], base[name]
        rel = tolerance["relative"]
        if tolerance["distribution"] == "uniform":
            draws[name] = nominal * (1.0 + rng.uniform(-rel, rel, n))
        else:
            draws[name] = nominal * (1.0 + rel * rng.standard_normal(n))
    return [{"case": i, "params": {name: float(values[i]) for name, values in draws.items()}} for i in range(n)]


def _worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _row(case: dict, point: int, scene: Scene, engine, outcome) -> dict:
    return {"case": case["case"], "point": point, "engine": engine.name, "worker": _worker_name(),
            **scene.as_dict(), **outcome.row()}


def run_case(spec: Spec, engine, case: dict) -> list[dict]:
    base = spec.base_scene()
    if spec.kind == "monte-carlo":
        scene = base.with_values(**case["params"])
        return [_row(case, 0, scene, engine, engine.settle(scene))]
    if spec.kind == "basins":
        scene = base.with_values(omega=case["omega"], x_start=case["x0"], v_start=case["v0"])
        stable = stable_states(scene)
        outcome = engine.settle(scene, accept=lambda c: branch_of(c.real, -c.imag, stable) >= 0)
        row = _row(case, 0, scene, engine, outcome)
        row.update(i=case["i"], j=case["j"], branch=branch_of(outcome.A, outcome.B, stable),
                   **predicted_attractor(scene, stable))
        return [row]
    rows, scene = [], base.with_values(Delta=case["Delta"])
    stopped = ""
    for point, omega in enumerate(case["omegas"]):
        scene = scene.with_values(omega=omega)
        start = scene  # this point's start state (the previous point's end state)
        if stopped:
            from vibrofmu.study.engines import Outcome

            outcome = Outcome(failed=True, message=f"not run: {stopped}")
        else:
            outcome = engine.settle(scene, rate=settling_rate(scene))
            if outcome.pull_in or outcome.failed:
                stopped = f"the sweep stopped at omega = {omega:.8g}: {outcome.message}"
            else:
                scene = scene.with_values(x_start=outcome.x_end, v_start=outcome.v_end)  # continuation
        row = _row(case, point, start, engine, outcome)
        row.update(direction=case["direction"], Delta_index=case["Delta_index"],
                   omega_index=point if case["direction"] == "up" else len(case["omegas"]) - 1 - point)
        rows.append(row)
    return rows


BRANCH_MATCH = 0.10  # a first harmonic within 0.1 r_k of stable state k (in the (A, B) plane) is on it


def stable_states(scene: Scene) -> list:
    """The slow flow's stable steady states at the scene, by increasing amplitude."""
    model = av.averaged(scene)
    return [s for s in av.steady_states(model.flow(), model.r_max) if s.stable]


def branch_of(A: float, B: float, stable: list) -> int:
    """Index of the stable steady state (A_k, B_k) within BRANCH_MATCH r_k of (A, B), else -1. At the basins'
    default point the stable states and the saddle are >= 0.18 apart, > 0.1 r_k for every k."""
    for k, state in enumerate(stable):
        if math.hypot(A - state.A, B - state.B) <= BRANCH_MATCH * state.r:
            return k
    return -1


def settling_rate(scene: Scene) -> float:
    """The slowest decay rate -Re lambda over the slow flow's stable steady states at the scene (docs/model.md, Averaging and slow flow),
    at least mu/20: mu/2 at a focus, less at a node near a fold, where the settling bound of sweep.py with
    mu/2 would stop a run while a transient of several per cent is left (seen at Delta = 0.0004 in the
    response map: 7 % off). The floor keeps the wait at a fold finite (MAX_PERIODS caps it anyway)."""
    rates = [min(-lam.real for lam in s.eigenvalues) for s in stable_states(scene)]
    return max(min(rates, default=scene.mu / 2), scene.mu / 20)


PREDICTION_TIME = 20.0  # slow-flow run length in units of 2/mu (the slow decay time): e^-20 of the transient left


def predicted_attractor(scene: Scene, stable: list) -> dict:
    """The averaged model's end state from (x_start, v_start): the slow flow (A, B) from the state whose
    reconstructed x, x' equal the initial state (slowflow.SlowFlowSolution, the model of fidelity 3), run
    for PREDICTION_TIME slow decay times; the stable steady state it ends at (branch_of)."""
    from vibromodel.slowflow import SlowFlowSolution

    model = av.averaged(scene)
    t_end = PREDICTION_TIME * 2.0 / scene.mu
    solution = SlowFlowSolution(model, 0.0, scene.x_start, scene.v_start, 1e-8, t_end=t_end)
    A, B = (float(value) for value in solution.Z_end)
    return {"predicted_A": A, "predicted_B": B, "predicted_r": math.hypot(A, B), "predicted_branch": branch_of(A, B, stable)}
