"""The rungs' error estimates against the exact model (vibromodel.error_estimates; docs/rungs.md, Error estimates).

- slow_ac_grid(fmu): the paper scene with beta in {0.01, 0.02, 0.03, 0.05, 0.08} x Omega in {0.3, ..., 6} through the
  plant FMU, fidelities 3 and 4 against fidelity 0 over [0, 50]: each cell refused, warned (an fmi2Warning in the
  log) or accepted, with its error / max|x0| and the estimate the FMU logged.
- campaign(rung, n, seed): n random scenes over the documented ranges (slow and fast drives, light damping, near
  contact loss, near pull-in, long runs) of one rung; the rung's estimate against its measured max|x - x_ref| at the
  communication points, x_ref from the compiled exact plant at rtol 1e-12 (in-process, fast). Counts: the estimate
  bounds the measured error (>= 99 % wanted), within 100x of it (>= 90 % wanted).

- pair_costs(scene, stop, tolerance): one pair as the auto campaign measures it, each cost the least of a few rounds:
  every candidate's set-up, loop, error and "met", the oracle and auto's choice (the `pair` command: the paper scene).
- rung_costs(n, seed): the averaged and analytic rungs' set-up and table costs that vibromodel.auto prices, measured
  on the paper scene and n random scenes (the `costs` command; auto's constants are its medians).

Command line: python -m vibrofmu.analyses.error_calibration grid FMU | campaign RUNG [n] [seed] [FILE] | auto [n]
[seed] | pair [stop] [tolerance] [rounds] | costs [n] [seed] (RUNG: exact, rk4, polynomial, polynomial-paper, averaged, analytic; prints progress on stderr and JSON on
stdout, or the campaign's to FILE, rewritten every 25 scenes).
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vibrofmu.analyses.domains import campaign_kernel, run_steps
from vibrofmu.analyses.simulate import logged_estimate
from vibromodel.fidelities import Fidelity
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
         "rk4": {"fidelity": 0, "solver": 1}, "polynomial": {"fidelity": 1},
         "polynomial-paper": {"fidelity": 2}}


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


def campaign(rung: str, n: int = 1000, seed: int = 0, h: float = 0.1, progress=None, checkpoint=None) -> dict:
    """The rung's estimate against its measured error over n random scenes (module docstring); checkpoint(result)
    is called with the result so far every 25 scenes (the command line writes it to its file: a campaign stopped
    early keeps the scenes it measured)."""
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
                     "terms": plant.error_estimate.get("terms", {}),
                     "exact_stopped": exact_stop is not None, "scene": scene.as_dict(),
                     "settings": {"rtol": settings.rtol, "max_step": settings.max_step}})
        if len(rows) % 25 == 0:
            if progress:
                progress(f"{rung}: {len(rows)}/{n} scenes, {time.perf_counter() - started:.0f} s")
            if checkpoint:
                checkpoint({"rung": rung, "seed": seed, "rows": rows, "summary": summary(rows)})
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


# -- fidelity auto against the oracle --------------------------------------------------------------------------------

def _candidate_key(settings) -> tuple:
    return (int(settings.fidelity), settings.rtol if int(settings.fidelity) == 0 else None)


def _timed_run(plant, rebuild, stop: float, h: float) -> tuple[np.ndarray, float]:
    """(x at the communication points, the thread CPU time of the loop): the plant's whole doStep loop in C
    (plant.run, the compiled floor, as the speed ladder's cost per output); a run that ends early (pull-in) raises
    there, and x is then taken step by step from a fresh plant (rebuild())."""
    n = int(round(stop / h))
    started = time.thread_time()
    try:
        x = plant.run(h, n)
        return np.asarray(x, dtype=float), time.thread_time() - started
    except (ParameterError, IntegrationError):
        seconds = time.thread_time() - started
    x, _ = run_steps(rebuild(), stop, h)
    return x, seconds


COST_REPEATS = 3  # auto's choice and each exact candidate's build timed this often, the least taken (both alike)


def _run_error(x: np.ndarray, exact: np.ndarray, tolerance: float) -> tuple[float, bool]:
    """(max|x - x_ref| over the outputs both runs have, whether the run met `tolerance`: within it, and as many
    outputs as the reference, i.e. stopped where it stopped -- pull-in). The auto campaign's rule (its replay's and pair_costs' too)."""
    m = min(len(x), len(exact))
    error = float(np.max(np.abs(x[:m] - exact[:m]))) if m else math.inf
    return error, len(x) == len(exact) and error <= tolerance


def _reference_pairs(n: int, rng, library, h: float, rows: list):
    """The campaigns' draws while rows holds fewer than n pairs: (scene, stop, info, tolerance, the reference's x at
    every communication point, where the reference stopped), the reference DOP853 at rtol 1e-12; a pair whose
    reference is refused is a row of its own (outcome "reference refused"). auto_campaign and auto_replay draw the
    same pairs from the same generator through it."""
    while len(rows) < n:
        scene, stop, info = random_scene(rng)
        tolerance = float(10 ** rng.uniform(-10, -1))
        try:
            exact, exact_stop = run_steps(make_plant(scene, Settings(rtol=1e-12), 0.0, stop, library=library), stop, h)
        except (ParameterError, IntegrationError) as error:
            rows.append({**info, "tolerance": tolerance, "outcome": "reference refused", "message": str(error)[:200]})
            continue
        yield scene, stop, info, tolerance, exact, exact_stop


def auto_campaign(n: int = 500, seed: int = 0, h: float = 0.1, progress=None) -> dict:
    """n random (scene, tolerance) pairs (random_scene; tolerance log-uniform in [1e-10, 1e-1]): fidelity auto's
    chooser (vibromodel.auto.choose) against the oracle, the candidate that really met the tolerance at the least
    measured cost. Every candidate (auto.candidates) is built and run on the compiled kernel at communication step
    h; its error max|x - x_ref| against DOP853 at rtol 1e-12 ("met": within the tolerance, and the run stops where the
    reference stops: pull-in). Two costs, in thread CPU time: `run`, the doStep loop (the cost per output that auto
    ranks its candidates by: the speed ladder's), and `total`, the set-up (make_plant with its error estimate: the
    slow flow's table, the OAFM fit) and the run. Each has its own oracle, the candidate that met the tolerance at the
    least of that cost (for `total`, its own set-up included); auto's total is its whole choice (auto.choose: the
    exact model's estimates, every candidate it built, the chosen plant) and the chosen plant's run. The choice and
    the exact model's builds (a millisecond or less, where a shared machine's noise is largest) are timed
    COST_REPEATS times and the least taken, alike for auto and the oracle; the averaged and analytic builds once."""
    from vibromodel.auto import candidates, choose, describe

    library, rows = campaign_kernel(), []
    rng = np.random.default_rng(seed)
    started = time.perf_counter()
    for scene, stop, info, tolerance, exact, exact_stop in _reference_pairs(n, rng, library, h, rows):
        built, times = {}, {}

        def build(settings, scene=scene, stop=stop, built=built, times=times):
            key = _candidate_key(settings)
            t0 = time.thread_time()
            try:
                plant = make_plant(scene, settings, 0.0, stop, library=library)
            except (ParameterError, IntegrationError) as error:
                times.setdefault(key, []).append(time.thread_time() - t0)
                built[key] = (None, str(error)[:200])
                raise
            times.setdefault(key, []).append(time.thread_time() - t0)
            built[key] = (plant, None)
            return plant

        choice_costs = []
        for _ in range(COST_REPEATS):  # the least of a few: a shared machine's noise, as for every candidate's build
            passed_over = []  # the candidates auto passed over (the pre-check's among them): the same every repeat
            choosing = time.thread_time()
            try:
                _, chosen, _ = choose(scene, Settings(), tolerance, build, span=stop, passed_over=passed_over)
                choice = _candidate_key(chosen)
            except ParameterError:
                choice = None  # auto refused: no candidate's estimate meets the tolerance
            choice_costs.append(time.thread_time() - choosing)  # the estimates, the plants built, the chosen one
        choice_cost = min(choice_costs)
        table = []
        for _, candidate in candidates(Settings()):
            key = _candidate_key(candidate)
            cheap = int(candidate.fidelity) == int(Fidelity.EXACT)  # the exact model's set-up: ~a millisecond
            while len(times.get(key, ())) < (COST_REPEATS if cheap else 1):
                try:
                    build(candidate)
                except (ParameterError, IntegrationError):
                    pass
            (plant, refusal), build_cost = built[key], min(times[key])
            row = {"candidate": describe(candidate), "key": key, "build": build_cost}
            if plant is None:
                table.append({**row, "refused": refusal})
                continue
            x, run_cost = _timed_run(plant, lambda c=candidate: make_plant(scene, c, 0.0, stop, library=library),
                                     stop, h)
            error, met = _run_error(x, exact, tolerance)
            table.append({**row, "run": run_cost, "total": build_cost + run_cost, "error": error,
                          "estimate": plant.error_estimate["estimate"], "met": met, "fitted": _fitted(plant)})
        met = [c for c in table if c.get("met")]
        mine = next((c for c in table if c["key"] == choice), None)
        row = {**info, "tolerance": tolerance, "stop": stop, "exact_stopped": exact_stop is not None,
               "scene": scene.as_dict(), "candidates": table, "chosen": mine["candidate"] if mine else None,
               **_precheck(passed_over, next(c for c in table if c["key"] == (int(Fidelity.AVERAGED), None)),
                           tolerance)}
        if mine is not None:
            row.update(outcome="chosen", met=bool(mine.get("met")), error=mine.get("error"))
        else:
            row.update(outcome="refused", met=not met)  # a refusal is right when no candidate met the tolerance
        for cost in ("run", "total"):
            oracle = min(met, key=lambda c: c[cost]) if met else None
            row[f"oracle_{cost}"] = oracle["candidate"] if oracle else None
            if oracle is not None and mine is not None and cost in mine:
                spent = mine[cost] + (choice_cost - mine["build"] if cost == "total" else 0.0)
                row[f"cost_ratio_{cost}"] = spent / max(oracle[cost], 1e-9)
        rows.append(row)
        if progress and len(rows) % 10 == 0:
            progress(f"auto: {len(rows)}/{n} pairs, {time.perf_counter() - started:.0f} s")
    return {"n": n, "seed": seed, "rows": rows, "summary": auto_summary(rows)}


def _precheck(passed_over: list, averaged: dict | None, tolerance: float) -> dict:
    """A pair's record of the averaged rung's pre-check (vibromodel.auto.averaged_floor): whether auto passed the
    rung over unbuilt by it (precheck_skipped), and then whether its full estimate, built, rejected it too
    (precheck_confirmed: refused, or an estimate not within the tolerance; the pre-check must never skip a rung
    whose estimate meets it). averaged: the averaged candidate's row ("estimate" or "refused"), None unbuilt."""
    skipped = any(name == "AUTO_FLOOR" for name, _ in passed_over)
    if not skipped:
        return {"precheck_skipped": False}
    estimate = averaged.get("estimate", math.nan) if averaged and "refused" not in averaged else math.nan
    return {"precheck_skipped": True, "precheck_confirmed": not (math.isfinite(estimate) and estimate <= tolerance),
            "averaged_estimate": estimate}


def _precheck_counts(pairs: list[dict]) -> dict:
    """The pairs whose averaged rung auto's pre-check passed over, and of them those its full estimate rejects."""
    skipped = [r for r in pairs if r.get("precheck_skipped")]
    return {"precheck_skipped": len(skipped), "precheck_confirmed": sum(r["precheck_confirmed"] for r in skipped)}


def auto_replay(n: int = 500, seed: int = 0, h: float = 0.1) -> dict:
    """What of auto_campaign(n, seed, h) does not depend on the machine, derived again without its timings (for
    `vibrofmu report --check`: ~10 s of CPU for 500 pairs where the campaign takes ~1 s a pair, building and timing
    every candidate). The same pairs (the same draws of the same generator), the same reference, auto's choice
    (vibromodel.auto.choose, as the campaign calls it) and the chosen plant's run (the campaign's _timed_run), so its
    error and "met". The other candidates are built and run only where the campaign's counts need them: where auto
    refused or its choice missed the tolerance, whether some candidate met it (a refusal is then wrong, and a miss
    still has an oracle to be compared with). Rows as auto_campaign's (outcome, chosen, met, error) plus `oracle`
    (some candidate met the tolerance), no costs; the summary's counts as auto_summary's (compared: the pairs with
    both a choice and an oracle), its cost shares and medians nan."""
    from vibromodel.auto import candidates, choose, describe

    library, rows = campaign_kernel(), []
    rng = np.random.default_rng(seed)

    def met_by(candidate, scene, stop, exact, tolerance) -> bool:
        try:
            plant = make_plant(scene, candidate, 0.0, stop, library=library)
        except (ParameterError, IntegrationError):
            return False
        x, _ = _timed_run(plant, lambda: make_plant(scene, candidate, 0.0, stop, library=library), stop, h)
        return _run_error(x, exact, tolerance)[1]

    for scene, stop, info, tolerance, exact, _ in _reference_pairs(n, rng, library, h, rows):
        row, passed_over = {**info, "tolerance": tolerance, "stop": stop}, []
        try:
            plant, chosen, _ = choose(scene, Settings(), tolerance,
                                      lambda s, scene=scene, stop=stop: make_plant(scene, s, 0.0, stop, library=library),
                                      span=stop, passed_over=passed_over)
        except ParameterError:
            chosen = None
        averaged = None  # the averaged rung built, as the campaign builds every candidate: only where its pre-check
        if any(name == "AUTO_FLOOR" for name, _ in passed_over):  # passed it over (the count it reports)
            try:
                averaged = {"estimate": make_plant(scene, Settings(fidelity=int(Fidelity.AVERAGED)), 0.0, stop,
                                                   library=library).error_estimate["estimate"]}
            except (ParameterError, IntegrationError) as error:
                averaged = {"refused": str(error)[:200]}
        row.update(_precheck(passed_over, averaged, tolerance))
        if chosen is not None:
            x, _ = _timed_run(plant, lambda: make_plant(scene, chosen, 0.0, stop, library=library), stop, h)
            error, met = _run_error(x, exact, tolerance)
            row.update(outcome="chosen", chosen=describe(chosen), met=met, error=error)
        oracle = chosen is not None and row["met"] or any(
            met_by(candidate, scene, stop, exact, tolerance) for _, candidate in candidates(Settings())
            if chosen is None or _candidate_key(candidate) != _candidate_key(chosen))
        if chosen is None:
            row.update(outcome="refused", chosen=None, met=not oracle)
        rows.append({**row, "oracle": oracle})
    pairs = [r for r in rows if "met" in r]
    compared = sum(r["outcome"] == "chosen" and r["oracle"] for r in pairs)
    summary = {"pairs": len(pairs), "met_share": sum(r["met"] for r in pairs) / len(pairs) if pairs else math.nan,
               "refused": sum(r["outcome"] == "refused" for r in pairs), **_precheck_counts(pairs)}
    for cost in ("run", "total"):
        summary.update({f"compared_{cost}": compared, f"within_2x_{cost}_share": math.nan,
                        f"cost_ratio_{cost}_median": math.nan})
    return {"n": n, "seed": seed, "rows": rows, "summary": summary, "replay": True}


def pair_costs(scene: Scene, stop: float, tolerance: float, rounds: int = 5, h: float = 0.1) -> dict:
    """One (scene, tolerance) pair measured as the auto campaign measures its pairs, each cost the least of `rounds`
    interleaved rounds (a millisecond's set-up on a shared machine is noisy): every candidate's set-up (make_plant with
    its error estimate) and doStep loop in thread CPU on the compiled kernel, its error against DOP853 at rtol 1e-12
    and whether it met the tolerance; the oracle (the candidate that met it at the least set-up + loop) and auto's
    choice (auto.choose, its own cost included). A refused candidate is kept with the refusal."""
    from vibromodel.auto import candidates, choose, describe

    library = campaign_kernel()
    exact, _ = run_steps(make_plant(scene, Settings(rtol=1e-12), 0.0, stop, library=library), stop, h)
    table: dict = {}
    choice = None
    choice_costs = []
    for _ in range(rounds):
        for _, candidate in candidates(Settings()):
            name = describe(candidate)
            started = time.thread_time()
            try:
                plant = make_plant(scene, candidate, 0.0, stop, library=library)
            except (ParameterError, IntegrationError) as error:
                table[name] = {"candidate": name, "refused": str(error)[:200]}
                continue
            build = time.thread_time() - started
            x, run = _timed_run(plant, lambda c=candidate: make_plant(scene, c, 0.0, stop, library=library), stop, h)
            error, met = _run_error(x, exact, tolerance)
            row = table.setdefault(name, {"candidate": name, "build": math.inf, "run": math.inf, "error": error,
                                          "estimate": plant.error_estimate["estimate"], "met": met})
            row["build"], row["run"] = min(row["build"], build), min(row["run"], run)
        started = time.thread_time()
        try:
            _, chosen, _ = choose(scene, Settings(), tolerance, lambda s: make_plant(scene, s, 0.0, stop,
                                                                                     library=library), span=stop)
            choice = describe(chosen)
        except ParameterError:
            choice = None
        choice_costs.append(time.thread_time() - started)
    rows = list(table.values())
    for row in rows:
        if "build" in row:
            row["total"] = row["build"] + row["run"]
    met = [row for row in rows if row.get("met")]
    oracle = min(met, key=lambda row: row["total"]) if met else None
    return {"scene": scene.as_dict(), "stop": stop, "tolerance": tolerance, "rounds": rounds, "candidates": rows,
            "oracle": oracle["candidate"] if oracle else None, "chosen": choice, "choice_cost": min(choice_costs)}


def _least_thread_time(work, rounds: int):
    """(the least thread CPU time of `rounds` calls of work(), the last call's result)."""
    best, result = math.inf, None
    for _ in range(rounds):
        started = time.thread_time()
        result = work()
        best = min(best, time.thread_time() - started)
    return best, result


@contextlib.contextmanager
def _fresh_oafm_cache():
    """The user's OAFM cache (analytic.user_cache_dir) an empty temporary folder for the block's duration."""
    previous = os.environ.get("VIBROFMU_CACHE_DIR")
    with tempfile.TemporaryDirectory() as cache:
        os.environ["VIBROFMU_CACHE_DIR"] = cache
        try:
            yield
        finally:
            if previous is None:
                del os.environ["VIBROFMU_CACHE_DIR"]
            else:
                os.environ["VIBROFMU_CACHE_DIR"] = previous


COST_KEYS = ("averaged_fixed", "averaged_table_per_tau", "averaged_extension_per_tau", "analytic_fitted_per_tau",
             "analytic_cached_per_tau")


def rung_costs(n: int = 24, seed: int = 0, rounds: int = 3, h: float = 0.1) -> dict:
    """What vibromodel.auto's cost model prices, measured on the paper scene and n random scenes (random_scene), each
    cost the least of `rounds` in thread CPU on the compiled kernel, in the model's unit: one output of the scene's
    exact model at rtol 1e-8 (its doStep loop over [0, slowflow.CHUNK] at interval h, per output):
    - averaged: its set-up (make_plant with its estimate) at stop times CHUNK and WINDOW, whose difference is the
      table of WINDOW - CHUNK more tau ("averaged_table_per_tau"), the rest of the set-up at CHUNK the fixed part
      ("averaged_fixed"); and the table its doSteps extend beyond WINDOW, a run of WINDOW + 3 CHUNK, per tau beyond
      WINDOW, its lookups included ("averaged_extension_per_tau");
    - analytic: its set-up per unit of its fit span (analytic.covering's tau_end at stop time CHUNK), fitted in an
      empty cache ("analytic_fitted_per_tau", after a first fit that pays SciPy's imports) and then read from the
      cache it wrote ("analytic_cached_per_tau").
    A rung that refuses a scene leaves that scene out of its medians."""
    from vibromodel.analytic import OafmSettings, covering
    from vibromodel.slowflow import CHUNK, WINDOW

    library, rng, rows = campaign_kernel(), np.random.default_rng(seed), []
    scenes = [("paper", Scene())] + [(info["kind"], scene) for scene, _, info in
                                     (random_scene(rng) for _ in range(n))]
    outputs, long_stop = int(round(CHUNK / h)), WINDOW + 3 * CHUNK

    def looped(settings, stop):
        plant = make_plant(scene, settings, 0.0, stop, library=library)
        started = time.thread_time()
        plant.run(h, int(round(stop / h)))
        return time.thread_time() - started

    def built(fidelity, stop):
        return _least_thread_time(lambda: make_plant(scene, Settings(fidelity=fidelity), 0.0, stop,
                                                     library=library), rounds)

    with _fresh_oafm_cache():
        make_plant(Scene(), Settings(fidelity=4), 0.0, CHUNK, library=library)  # SciPy's imports, paid once
    for kind, scene in scenes:
        row = {"kind": kind, "scene": scene.as_dict()}
        try:
            unit = min(looped(Settings(rtol=1e-8), CHUNK) for _ in range(rounds)) / outputs
        except (ParameterError, IntegrationError) as error:
            rows.append({**row, "exact_refused": str(error)[:120]})
            continue
        row["exact_output_seconds"] = unit
        try:
            (short, plant), (long, _) = built(3, CHUNK), built(3, WINDOW)
            per_tau = (long - short) / (WINDOW - CHUNK)
            extension = min(looped(Settings(fidelity=3), long_stop) for _ in range(rounds))
            row.update(averaged_spacing=plant.python.solution.spacing, averaged_table_per_tau=per_tau / unit,
                       averaged_fixed=(short - CHUNK * per_tau) / unit,
                       averaged_extension_per_tau=extension / (long_stop - WINDOW) / unit)
        except (ParameterError, IntegrationError) as error:
            row["averaged_refused"] = str(error)[:120]
        try:
            span = covering(scene, OafmSettings(), CHUNK, strict=True).tau_end
            with _fresh_oafm_cache():
                fitted, _ = _least_thread_time(lambda: make_plant(scene, Settings(fidelity=4), 0.0, CHUNK,
                                                                  library=library), 1)
                cached, _ = built(4, CHUNK)
            row.update(analytic_fit_span=span, analytic_fitted_per_tau=fitted / span / unit,
                       analytic_cached_per_tau=cached / span / unit)
        except (ParameterError, IntegrationError) as error:
            row["analytic_refused"] = str(error)[:120]
        rows.append(row)
    medians = {k: float(np.median([r[k] for r in rows if k in r])) for k in COST_KEYS if any(k in r for r in rows)}
    return {"n": n, "seed": seed, "rounds": rounds, "rows": rows, "medians": medians,
            "paper": {k: rows[0].get(k) for k in COST_KEYS}}


def costs_table(result: dict) -> list[str]:
    """rung_costs's medians beside vibromodel.auto's constants (outputs of the exact model at rtol 1e-8)."""
    from vibromodel.auto import FIT_COST, SETUP_COST, TABLE_COST

    mine = {"averaged_fixed": SETUP_COST[Fidelity.AVERAGED], "averaged_table_per_tau": TABLE_COST,
            "averaged_extension_per_tau": TABLE_COST, "analytic_fitted_per_tau": FIT_COST["fitted"],
            "analytic_cached_per_tau": FIT_COST["cached"]}
    labels = {"averaged_fixed": "fidelity 3: fixed set-up", "averaged_table_per_tau":
              "fidelity 3: table per τ, at set-up (stop 1000 against 200)", "averaged_extension_per_tau":
              "fidelity 3: table per τ, the doSteps' beyond the set-up window (lookups included)",
              "analytic_fitted_per_tau": "fidelity 4: fit per τ of its fit span, fitted",
              "analytic_cached_per_tau": "fidelity 4: fit per τ of its fit span, read from the cache"}
    counted = {k: sum(k in r for r in result["rows"]) for k in COST_KEYS}
    lines = [f"| cost (outputs of the exact model at rtol 10⁻⁸) | auto's | median over {result['n'] + 1} scenes "
             "(scenes measured) | the paper scene |", "|---|---|---|---|"]
    for key in COST_KEYS:
        if key in result["medians"]:
            paper = result["paper"].get(key)
            lines.append(f"| {labels[key]} | {mine[key]:,.4g} | {result['medians'][key]:,.1f} ({counted[key]}) | "
                         f"{'refused' if paper is None else f'{paper:,.1f}'} |")
    return lines


def pair_table(result: dict) -> list[str]:
    """pair_costs's candidates as a table, milliseconds of thread CPU."""
    lines = [f"tau in [0, {result['stop']:g}], tolerance {result['tolerance']:g}, least of {result['rounds']} rounds: "
             f"the oracle {result['oracle']}, auto chose {result['chosen']} (its choice {result['choice_cost'] * 1e3:.2f} ms)",
             "| candidate | set-up ms | loop ms | set-up + loop ms | error | estimate | met |", "|---|---|---|---|---|---|---|"]
    for row in result["candidates"]:
        if "refused" in row:
            lines.append(f"| {row['candidate']} | refused: {row['refused'][:60]} | | | | | |")
            continue
        lines.append(f"| {row['candidate']} | {row['build'] * 1e3:.2f} | {row['run'] * 1e3:.2f} | "
                     f"{row['total'] * 1e3:.2f} | {row['error']:.2e} | {row['estimate']:.2e} | {row['met']} |")
    return lines


def auto_summary(rows: list[dict]) -> dict:
    """Shares over the pairs: auto met the tolerance (or refused where no candidate met it); its cost within 2x the
    oracle's, over the pairs that have both an oracle and a choice, per cost (run: the doStep loop; total: with the
    set-up of its choice and of the candidates it built to choose)."""
    pairs = [r for r in rows if "met" in r]

    def share(hits, total):
        return hits / total if total else math.nan

    result = {"pairs": len(pairs), "met_share": share(sum(r["met"] for r in pairs), len(pairs)),
              "refused": sum(r["outcome"] == "refused" for r in pairs), **_precheck_counts(pairs)}
    for cost in ("run", "total"):
        ratios = [r[f"cost_ratio_{cost}"] for r in pairs if f"cost_ratio_{cost}" in r]
        result[f"compared_{cost}"] = len(ratios)
        result[f"within_2x_{cost}_share"] = share(sum(v <= 2.0 for v in ratios), len(ratios))
        result[f"cost_ratio_{cost}_median"] = float(np.median(ratios)) if ratios else math.nan
    return result


# -- tables (docs/rungs.md's report blocks, vibrofmu bench) ---------------------------------------------------------

RUNG_LABELS = {"exact": "fidelity 0, DOP853 at rtol 10⁻¹⁰ … 10⁻³", "rk4": "fidelity 0, RK4 at h = 0.003 … 0.2",
               "polynomial": "fidelity 1 (polynomial), DOP853 at 10⁻⁸", "polynomial-paper":
               "fidelity 2 (printed coefficients), DOP853 at 10⁻⁸", "averaged": "fidelity 3 (averaged)",
               "analytic": "fidelity 4 (analytic)"}


def _percent(share: float) -> str:
    return f"{100.0 * share:.1f} %"


def _ratio(value: float) -> str:
    return f"{value:.0f}" if 100.0 <= value < 1e5 else f"{value:.2g}"


TABLE_ORDER = ("exact", "rk4", "polynomial", "polynomial-paper", "averaged", "analytic")  # by fidelity


# (rung, seed) of the campaigns docs/rungs.md's calibration block reports (tests/docs check the block's commands)
DOCUMENTED_CAMPAIGNS = (("exact", 7), ("rk4", 7), ("polynomial", 7), ("polynomial-paper", 7), ("averaged", 7),
                        ("analytic", 7), ("analytic", 8))
DOCUMENTED_AUTO = (500, 7)  # (pairs, seed) of the auto campaign docs/rungs.md's auto block reports
REPLAYED_SCENES = 3  # per campaign: ~10 s of CPU in all (fidelity 4's fits the most)


def replay_table(scenes: int = REPLAYED_SCENES) -> list[str]:
    """Markdown rows: the first `scenes` scenes of each documented campaign run again (the campaigns' random
    scenes come from their seed alone), estimate / measured error per scene. Deterministic on one machine: a
    change of an estimate or of the model changes these rows, which `vibrofmu report --check` compares."""
    lines = ["| campaign (seed) | " + " | ".join(f"scene {i + 1}: estimate / measured" for i in range(scenes)) + " |",
             "|---|" + "---|" * scenes]
    for rung, seed in DOCUMENTED_CAMPAIGNS:
        cells = [f"{row['estimate']:.3g} / {row['measured']:.3g}" if "measured" in row else "refused"
                 for row in campaign(rung, scenes, seed)["rows"]]
        lines.append(f"| {RUNG_LABELS.get(rung, rung)} ({seed}) | " + " | ".join(cells) + " |")
    return lines


def calibration_table(results: list[dict]) -> list[str]:
    """Markdown rows of the campaigns' summaries (campaign's output), in RUNGS order."""
    order = list(TABLE_ORDER)
    lines = ["| rung | scenes (seed) | estimated | bounded | within 100× | estimate / measured: min, median, max |",
             "|---|---|---|---|---|---|"]
    for r in sorted(results, key=lambda r: (order.index(r["rung"]) if r["rung"] in order else len(order), r["seed"])):
        s = r["summary"]
        lines.append(f"| {RUNG_LABELS.get(r['rung'], r['rung'])} | {s['scenes']:,} ({r['seed']}) | {s['estimated']:,} | "
                     f"{_percent(s['bounded_share'])} | {_percent(s['within_100x_share'])} | "
                     f"{_ratio(s['ratio_min'])}, {_ratio(s['ratio_median'])}, {_ratio(s['ratio_max'])} |")
    return lines


def auto_table(result: dict, costs: dict | None = None) -> list[str]:
    """Markdown rows of an auto campaign (auto_campaign's output): the shares, then what auto and the oracle chose,
    then auto's costs beside the measured ones (costs: measured_costs(result) unless given)."""
    s = result["summary"]
    lines = ["| pairs (seed) | met | refused | cost: | compared | ≤ 2× the oracle's | median / the oracle's |",
             "|---|---|---|---|---|---|---|"]
    for cost, label in (("run", "doStep loop"), ("total", "set-up + loop")):
        lines.append(f"| {s['pairs']:,} ({result['seed']}) | {_percent(s['met_share'])} | {s['refused']} | {label} | "
                     f"{s[f'compared_{cost}']} | {_percent(s[f'within_2x_{cost}_share'])} | "
                     f"{s[f'cost_ratio_{cost}_median']:.2f} |")
    if "precheck_skipped" in s:  # campaigns before the averaged rung's pre-check have not these counts
        lines += ["", f"The averaged rung's pre-check (its estimate's floor above the tolerance) passed it over "
                  f"unbuilt in {s['precheck_skipped']} of the pairs; built, its estimate rejected "
                  f"{s['precheck_confirmed']} of them."]
    chosen: dict = {}
    for r in result["rows"]:
        if "met" in r:
            row = chosen.setdefault(r.get("chosen") or "refused", [0, 0, 0, 0, 0])
            row[0] += 1
            row[1] += bool(r["met"])
            row[2] += r.get("oracle_total") == r.get("chosen")
            row[3] += r.get("cost_ratio_total", math.inf) <= 2.0
            row[4] += r.get("cost_ratio_run", math.inf) <= 2.0
    lines += ["", "| auto chose | pairs | met | the oracle itself (set-up + loop) | ≤ 2× the oracle's: set-up + loop | "
              "loop |", "|---|---|---|---|---|---|"]
    lines += [f"| {name} | {n} | {met} | {same} | {within} | {loop} |"
              for name, (n, met, same, within, loop) in sorted(chosen.items(), key=lambda kv: -kv[1][0])]
    costs = measured_costs(result) if costs is None else costs
    if costs:
        lines += ["", "The costs auto ranks by (vibromodel.auto) beside this campaign's medians over its pairs (the "
                  "doStep loop per output relative to the exact model's at rtol 10⁻⁸; the set-up in outputs of "
                  "that loop, auto's as it models each pair's: its span, the analytic rung's fit span, fitted or "
                  "read from the cache as the campaign's build was):", "",
                  "| candidate | loop per output: auto's, measured | set-up: auto's, measured |",
                  "|---|---|---|"]
        lines += [f"| {name} | {mine:.3g}, {loop:.3g} | {setup_mine:.3g}, {setup:.3g} |"
                  for name, (mine, loop, setup_mine, setup) in costs.items()]
    return lines


def _fitted(plant) -> bool:
    """Whether an analytic plant fitted its solution (not read from a cache): its OAFM note says "(fitted)"."""
    notes = list(getattr(plant, "notes", ())) + list(getattr(getattr(plant, "python", None), "notes", ()))
    return any(note.startswith("OAFM") and note.endswith("(fitted)") for note in notes)


def measured_costs(result: dict) -> dict:
    """candidate -> (auto's cost per output, the campaign's median, auto's modelled set-up, the campaign's median):
    per pair, each candidate's loop and build against the loop per output of the exact model at rtol 1e-8, and the
    set-up auto.setup_cost models for that pair (its span; the analytic rung's fit span, analytic.covering, fitted
    or cached as the campaign's build was); medians over the pairs."""
    from vibromodel.analytic import OafmSettings, covering
    from vibromodel.auto import candidates, describe, setup_cost
    from vibromodel.fidelities import Fidelity

    samples: dict = {}
    for r in result["rows"]:
        table = {tuple(c["key"]): c for c in r.get("candidates", [])}
        unit = table.get((int(Fidelity.EXACT), 1e-8), {}).get("run")
        if not unit:
            continue
        unit /= r["stop"] / 0.1  # the campaign's communication step
        for c in table.values():
            if "run" not in c:
                continue
            level = Fidelity(int(c["key"][0]))
            fit_span = None
            if level == Fidelity.ANALYTIC:
                try:
                    fit_span = covering(Scene(**r["scene"]), OafmSettings(), r["stop"]).tau_end
                except ParameterError:
                    continue
            modelled = setup_cost(level, r["stop"], fit_span, cached=not c.get("fitted", True))
            samples.setdefault(c["candidate"], []).append((c["run"] / (r["stop"] / 0.1) / unit, c["build"] / unit,
                                                           modelled))
    out = {}
    for cost, candidate in candidates(Settings()):
        name = describe(candidate)
        if name in samples:
            values = np.array(samples[name])
            out[name] = (cost, float(np.median(values[:, 0])), float(np.median(values[:, 2])),
                         float(np.median(values[:, 1])))
    return out


def main(argv: list[str]) -> None:
    def progress(text):
        print(text, file=sys.stderr, flush=True)

    if argv[:1] == ["grid"] and len(argv) == 2:
        print(json.dumps(slow_ac_grid(argv[1], progress=progress), indent=1))
    elif argv[:1] == ["campaign"] and len(argv) in (2, 3, 4, 5) and argv[1] in RUNGS:
        n = int(argv[2]) if len(argv) > 2 else 1000
        seed = int(argv[3]) if len(argv) > 3 else 0
        out = Path(argv[4]) if len(argv) > 4 else None

        def write(result):  # to a temporary name, then renamed: the file is always a whole result
            partial = out.with_name(out.name + ".partial")
            partial.write_text(json.dumps(result, indent=1))
            partial.replace(out)

        result = campaign(argv[1], n, seed, progress=progress, checkpoint=write if out else None)
        if out:
            write(result)
        else:
            print(json.dumps(result, indent=1))
        progress(json.dumps(result["summary"]))
    elif argv[:1] == ["auto"] and len(argv) in (1, 2, 3):
        n = int(argv[1]) if len(argv) > 1 else 500
        seed = int(argv[2]) if len(argv) > 2 else 0
        result = auto_campaign(n, seed, progress=progress)
        print(json.dumps(result, indent=1))
        progress(json.dumps(result["summary"]))
    elif argv[:1] == ["costs"] and len(argv) in (1, 2, 3):
        try:
            n, seed = int(argv[1]) if len(argv) > 1 else 24, int(argv[2]) if len(argv) > 2 else 0
            if n < 0 or seed < 0:
                raise ValueError
        except ValueError:
            print(f"error: costs wants a number of scenes and a seed (non-negative integers), not "
                  f"{' '.join(argv[1:])}", file=sys.stderr)
            raise SystemExit(2) from None
        result = rung_costs(n, seed)
        print(json.dumps(result, indent=1))
        progress(json.dumps({"medians": result["medians"], "paper": result["paper"]}))
    elif argv[:1] == ["pair"] and len(argv) in (1, 2, 3, 4):
        try:
            stop, tolerance, rounds = float(argv[1]) if len(argv) > 1 else 200.0, float(argv[2]) if len(argv) > 2 \
                else 1e-3, int(argv[3]) if len(argv) > 3 else 5
            if not (stop > 0.0 and tolerance > 0.0 and rounds > 0):
                raise ValueError
        except ValueError:
            print(f"error: pair wants a positive stop time, tolerance and number of rounds, not {' '.join(argv[1:])}",
                  file=sys.stderr)
            raise SystemExit(2) from None
        result = pair_costs(Scene(), stop, tolerance, rounds)
        print(json.dumps(result, indent=1))
        progress("\n".join(pair_table(result)))
    else:
        print(f"error: usage: python -m vibrofmu.analyses.error_calibration grid FMU | campaign "
              f"{{{','.join(RUNGS)}}} [n] [seed] [FILE] | auto [n] [seed] | pair [stop] [tolerance] [rounds] | "
              f"costs [n] [seed]",
              file=sys.stderr)
        raise SystemExit(2)


if __name__ == "__main__":
    main(sys.argv[1:])
