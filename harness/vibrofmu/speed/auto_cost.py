"""What fidelity auto and the error estimates cost at set-up (`vibrofmu bench`, "auto"; docs/rungs.md, Choosing by
tolerance): on the paper scene,

- the plant FMU's set-up (instantiate, setupExperiment, initialisation: fmi2ExitInitializationMode builds the plant)
  under FMPy with fidelity auto at a few tolerances, beside the set-up of each fixed rung: auto's set-up must stay
  within AUTO_SETUP_LIMIT seconds;
- each fixed rung's error estimate (its registry entry's estimator, what error_estimates.attach calls) against the
  whole make_plant that builds the rung with it: the share must stay within ESTIMATE_SHARE_LIMIT.

Both in interleaved rounds after a warm-up round (the first FMPy instance of a process pays for loading; the
first fit or table pays for imports): every round runs every item once, so that a slow phase of a shared machine
falls on all of them; the median over the rounds is the figure, each ratio the median of its per-round ratios
(items measured side by side). No test asserts on these times: they are measured and printed here."""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

from fmpy import extract
from fmpy.fmi1 import FMICallException

from vibromodel import auto, fidelities
from vibromodel.fidelities import AUTO
from vibromodel.parameters import Scene
from vibromodel.plant import Settings, make_plant

from vibrofmu.fmus.kernel import kernel_library
from vibrofmu.hosts.run import FmuInstance, FmuLog, call_failure_reason

AUTO_SETUP_LIMIT = 2.0  # seconds: auto's set-up on the paper scene
ESTIMATE_SHARE_LIMIT = 0.05  # a fixed rung's estimate over its initialisation
AUTO_TOLERANCES = (1e-3, 1e-6, 1e-10)
STOP = 50.0  # the run the set-ups are for (the paper scene's acceptance runs)


def fmu_setup(fmu: Path, unzip_dir: str, start: dict, log: FmuLog) -> tuple[float, float, dict]:
    """(seconds from instantiation to the end of fmi2ExitInitializationMode, seconds of fmi2ExitInitializationMode
    alone, the outputs after it: fidelity_chosen, error_estimate); RuntimeError with the FMU's reason when it
    refuses."""
    started = time.perf_counter()
    instance = FmuInstance(fmu, instance_name="auto-cost", log=log, unzip_dir=unzip_dir)
    try:
        f = instance.fmu
        try:
            f.setupExperiment(startTime=0.0, stopTime=STOP)
            f.enterInitializationMode()
            instance.set(start)
            exiting = time.perf_counter()
            f.exitInitializationMode()
        except FMICallException as error:
            raise RuntimeError(call_failure_reason(error, log)) from None
        finished = time.perf_counter()
        seconds, initialisation = finished - started, finished - exiting
        chosen = f.getInteger(instance.value_references(["fidelity_chosen"]))[0]
        estimate = f.getReal(instance.value_references(["error_estimate"]))[0]
    finally:
        instance.close()
    return seconds, initialisation, {"fidelity_chosen": int(chosen), "error_estimate": float(estimate)}


def setup_record(fmu: Path, rounds: int) -> dict:
    """Auto's set-up at AUTO_TOLERANCES beside every fixed rung's, through the plant FMU under FMPy."""
    items = {f"fidelity {int(level)}": {"fidelity": int(level)} for level in fidelities.REGISTRY}
    items.update({f"auto, tolerance {t:g}": {"fidelity": AUTO, "tolerance": t} for t in AUTO_TOLERANCES})
    runs = {name: [] for name in items}
    inits = {name: [] for name in items}
    outputs = {}
    log = FmuLog()
    with tempfile.TemporaryDirectory(prefix="vibrofmu-auto-cost-") as tmp:
        unzip_dir = extract(str(fmu), str(Path(tmp) / "fmu"))
        names = list(items)
        for r in range(rounds + 1):  # round 0: the warm-up, discarded
            order = names[r % len(names):] + names[:r % len(names)]  # no item always first
            for name in order:
                seconds, initialisation, outputs[name] = fmu_setup(fmu, unzip_dir, items[name], log)
                if r:
                    runs[name].append(seconds)
                    inits[name].append(initialisation)
    rows = []
    for name, start in items.items():
        row = {"item": name, "start_values": start, "seconds_median": statistics.median(runs[name]),
               "seconds_runs": runs[name], "initialisation_seconds_median": statistics.median(inits[name]),
               **outputs[name]}
        if start["fidelity"] == AUTO:
            fixed = runs[f"fidelity {outputs[name]['fidelity_chosen']}"]
            row["over_chosen_rung_setup"] = statistics.median(a / b for a, b in zip(runs[name], fixed))
            row["limit_seconds"], row["met"] = AUTO_SETUP_LIMIT, row["seconds_median"] <= AUTO_SETUP_LIMIT
        rows.append(row)
    return {"rows": rows, "rounds": rounds, "stop_time": STOP,
            "note": "wall time of instantiate + setupExperiment + initialisation of the pythonfmu plant FMU under "
                    "FMPy (an extracted copy), median over interleaved rounds after a warm-up round; auto: "
                    "over_chosen_rung_setup is the median per-round ratio to the set-up of the fixed rung it chose"}


def estimate_record(rounds: int, setup: dict) -> dict:
    """Per fixed rung: the whole make_plant (the compiled kernel where it applies, as in the FMU) and the estimator
    alone on the plant it built, side by side in each round; the estimator's median over the FMU's
    fmi2ExitInitializationMode of that rung (setup: setup_record's), the share the acceptance reads."""
    fmu_init = {row["start_values"]["fidelity"]: row["initialisation_seconds_median"] for row in setup["rows"]
                if row["start_values"]["fidelity"] != AUTO}
    scene, library = Scene(), (kernel_library(), "the bench's kernel")
    levels = list(fidelities.REGISTRY.values())
    runs = {int(e.level): [] for e in levels}
    for r in range(rounds + 1):
        for e in levels[r % len(levels):] + levels[:r % len(levels)]:
            started = time.perf_counter()
            plant = make_plant(scene, Settings(fidelity=int(e.level)), 0.0, STOP, library=library)
            total = time.perf_counter() - started
            inner = getattr(plant, "python", plant)
            started = time.perf_counter()
            e.error_estimate(plant.scene, plant.settings, getattr(inner, "model", None) or e.model(plant.scene),
                             getattr(inner, "solution", None), STOP)
            estimate = time.perf_counter() - started
            if r:
                runs[int(e.level)].append((total, estimate))
    rows = []
    for e in levels:
        pairs = runs[int(e.level)]
        estimate = statistics.median(s for _, s in pairs)
        share = estimate / fmu_init[int(e.level)]
        rows.append({"fidelity": int(e.level), "rung": e.key, "estimate_seconds_median": estimate,
                     "fmu_initialisation_seconds_median": fmu_init[int(e.level)], "share": share,
                     "make_plant_seconds_median": statistics.median(t for t, _ in pairs),
                     "share_of_make_plant": statistics.median(est / total for total, est in pairs),
                     "limit": ESTIMATE_SHARE_LIMIT, "met": share <= ESTIMATE_SHARE_LIMIT})
    return {"rows": rows, "rounds": rounds,
            "note": "estimate: the registry entry's estimator alone on the plant make_plant built, timed right after "
                    "it (median over rounds); share: over the median of the pythonfmu FMU's fmi2ExitInitializationMode "
                    "of that rung (setup); share_of_make_plant: over the bare make_plant in this process (the "
                    "plant's set-up with its estimate, without the FMU's checks, logging and FMI calls), median of "
                    "the per-round ratios"}


def ladder_costs(ladder: dict | None) -> list[dict]:
    """auto.LADDER_COST beside the ratios this bench's ladder measured (C host, interval 0.1, CPU, median of rounds)."""
    measured = {}
    for a in (ladder or {}).get("acceptance", []):
        if (a["host"], a["interval"]) == ("C host", 0.1):
            measured[a["rung"]] = a["ratio"]
    return [{"rung": fidelities.entry(level).rung, "auto_cost": cost,
             "measured": measured.get(fidelities.entry(level).rung)} for level, cost in auto.LADDER_COST.items()]


def auto_record(fmu: Path, rounds: int = 3, ladder: dict | None = None) -> dict:
    setup = setup_record(fmu, rounds)
    return {"setup": setup, "estimate": estimate_record(rounds, setup), "costs": ladder_costs(ladder)}


def auto_lines(record: dict) -> list[str]:
    lines = [f"  fidelity auto and the error estimates (paper scene, tau in [0, {record['setup']['stop_time']:g}], "
             f"median of {record['setup']['rounds']} interleaved rounds):"]
    for row in record["setup"]["rows"]:
        line = (f"    set-up {row['item']:<24} {row['seconds_median']:.3f} s  chose fidelity "
                f"{row['fidelity_chosen']}, estimate {row['error_estimate']:.3g}")
        if "met" in row:
            line += (f"; {row['over_chosen_rung_setup']:.2f}x the chosen rung's set-up (limit {row['limit_seconds']:g}"
                     f" s: {'met' if row['met'] else 'NOT met'})")
        lines.append(line)
    for row in record["estimate"]["rows"]:
        lines.append(f"    estimate / initialisation, fidelity {row['fidelity']} ({row['rung']}): {row['share']:.3f} "
                     f"({1e3 * row['estimate_seconds_median']:.3f} ms of the FMU's "
                     f"{1e3 * row['fmu_initialisation_seconds_median']:.2f} ms; limit {row['limit']:g}: "
                     f"{'met' if row['met'] else 'NOT met'}); of the bare make_plant "
                     f"({1e3 * row['make_plant_seconds_median']:.2f} ms): {row['share_of_make_plant']:.3f}")
    for row in record["costs"]:
        measured = "not measured in this run" if row["measured"] is None else f"{row['measured']:.3g} measured"
        lines.append(f"    auto's cost of {row['rung']}: {row['auto_cost']:g} of exact f0 ({measured})")
    return lines
