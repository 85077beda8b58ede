"""What fidelity auto and the error estimates cost at set-up (`vibrofmu bench`, "auto"; docs/rungs.md, Choosing by
tolerance): on the paper scene,

- the plant FMU's set-up (instantiate, setupExperiment, initialisation: fmi2ExitInitializationMode builds the plant)
  under FMPy with fidelity auto at a few tolerances, beside the set-up of each fixed rung: auto's set-up must stay
  within AUTO_SETUP_LIMIT seconds;
- each fixed rung's error estimate (its registry entry's estimator, what error_estimates.attach calls), timed in
  the same round right after the rung's FMU set-up, against that set-up's fmi2ExitInitializationMode: the median of
  the per-round shares must stay within ESTIMATE_SHARE_LIMIT (and against the bare make_plant, for reference).

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


def _estimate_alone(level) -> tuple[float, float]:
    """(seconds of the bare make_plant of fidelity `level` on the paper scene over [0, STOP], seconds of its
    registry entry's estimator alone on the plant it built, as error_estimates.attach calls it)."""
    e = fidelities.entry(level)
    library = (kernel_library(), "the bench's kernel")
    started = time.perf_counter()
    plant = make_plant(Scene(), Settings(fidelity=int(e.level)), 0.0, STOP, library=library)
    total = time.perf_counter() - started
    inner = getattr(plant, "python", plant)
    started = time.perf_counter()
    e.error_estimate(plant.scene, plant.settings, getattr(inner, "model", None) or e.model(plant.scene),
                     getattr(inner, "solution", None), STOP)
    return total, time.perf_counter() - started


def setup_record(fmu: Path, rounds: int) -> dict:
    """Auto's set-up at AUTO_TOLERANCES beside every fixed rung's, through the plant FMU under FMPy; after each fixed
    rung's FMU set-up, in the same round, its estimate alone (_estimate_alone: estimate_record pairs the two)."""
    items = {f"fidelity {int(level)}": {"fidelity": int(level)} for level in fidelities.REGISTRY}
    items.update({f"auto, tolerance {t:g}": {"fidelity": AUTO, "tolerance": t} for t in AUTO_TOLERANCES})
    runs = {name: [] for name in items}
    inits = {name: [] for name in items}
    alone = {name: [] for name in items}
    outputs = {}
    log = FmuLog()
    with tempfile.TemporaryDirectory(prefix="vibrofmu-auto-cost-") as tmp:
        unzip_dir = extract(str(fmu), str(Path(tmp) / "fmu"))
        names = list(items)
        for r in range(rounds + 1):  # round 0: the warm-up, discarded
            order = names[r % len(names):] + names[:r % len(names)]  # no item always first
            for name in order:
                seconds, initialisation, outputs[name] = fmu_setup(fmu, unzip_dir, items[name], log)
                estimate = _estimate_alone(items[name]["fidelity"]) if items[name]["fidelity"] != AUTO else None
                if r:
                    runs[name].append(seconds)
                    inits[name].append(initialisation)
                    if estimate is not None:
                        alone[name].append(estimate)
    rows = []
    for name, start in items.items():
        row = {"item": name, "start_values": start, "seconds_median": statistics.median(runs[name]),
               "seconds_runs": runs[name], "initialisation_seconds_median": statistics.median(inits[name]),
               "initialisation_seconds_runs": inits[name], **outputs[name]}
        if alone[name]:
            row["make_plant_seconds_runs"] = [total for total, _ in alone[name]]
            row["estimate_seconds_runs"] = [estimate for _, estimate in alone[name]]
        if start["fidelity"] == AUTO:
            fixed = runs[f"fidelity {outputs[name]['fidelity_chosen']}"]
            row["over_chosen_rung_setup"] = statistics.median(a / b for a, b in zip(runs[name], fixed))
            row["limit_seconds"], row["met"] = AUTO_SETUP_LIMIT, row["seconds_median"] <= AUTO_SETUP_LIMIT
        rows.append(row)
    return {"rows": rows, "rounds": rounds, "stop_time": STOP,
            "note": "wall time of instantiate + setupExperiment + initialisation of the pythonfmu plant FMU under "
                    "FMPy (an extracted copy), median over interleaved rounds after a warm-up round; auto: "
                    "over_chosen_rung_setup is the median per-round ratio to the set-up of the fixed rung it chose; "
                    "a fixed rung's estimate alone (make_plant, then its estimator) right after its FMU set-up"}


def estimate_record(rounds: int, setup: dict) -> dict:
    """Per fixed rung: its estimator's time (setup_record's, right after the rung's FMU set-up in each round) over
    that round's fmi2ExitInitializationMode of the FMU, the median of these per-round shares the acceptance reads;
    and over the bare make_plant it ran on (the plant's set-up with its estimate, without the FMU's checks, logging
    and FMI calls)."""
    rows = []
    for e in fidelities.REGISTRY.values():
        row = next(r for r in setup["rows"] if r["start_values"] == {"fidelity": int(e.level)})
        estimates, inits, totals = row["estimate_seconds_runs"], row["initialisation_seconds_runs"], \
            row["make_plant_seconds_runs"]
        share = statistics.median(est / init for est, init in zip(estimates, inits))
        rows.append({"fidelity": int(e.level), "rung": e.key, "estimate_seconds_median": statistics.median(estimates),
                     "fmu_initialisation_seconds_median": statistics.median(inits), "share": share,
                     "make_plant_seconds_median": statistics.median(totals),
                     "share_of_make_plant": statistics.median(est / total for est, total in zip(estimates, totals)),
                     "limit": ESTIMATE_SHARE_LIMIT, "met": share <= ESTIMATE_SHARE_LIMIT})
    return {"rows": rows, "rounds": rounds,
            "note": "estimate: the registry entry's estimator alone on the plant make_plant built, timed right after "
                    "the rung's FMU set-up in each round; share: the median over the rounds of the estimate over that "
                    "round's fmi2ExitInitializationMode of the pythonfmu FMU of that rung; share_of_make_plant: over "
                    "the bare make_plant in this process (the plant's set-up with its estimate, without the FMU's "
                    "checks, logging and FMI calls), median of the per-round ratios"}


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
                     f"(median of the rounds' shares; medians: {1e3 * row['estimate_seconds_median']:.3f} ms of the "
                     f"FMU's {1e3 * row['fmu_initialisation_seconds_median']:.2f} ms; limit {row['limit']:g}: "
                     f"{'met' if row['met'] else 'NOT met'}); of the bare make_plant "
                     f"({1e3 * row['make_plant_seconds_median']:.2f} ms): {row['share_of_make_plant']:.3f}")
    for row in record["costs"]:
        measured = "not measured in this run" if row["measured"] is None else f"{row['measured']:.3g} measured"
        lines.append(f"    auto's cost of {row['rung']}: {row['auto_cost']:g} of exact f0 ({measured})")
    return lines
