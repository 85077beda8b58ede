"""Fidelity "auto": the cheapest rung and setting whose error estimate meets a tolerance on max|x - x_exact|
(vibromodel.error_estimates; docs/rungs.md, Choosing by tolerance). The plant FMU's `fidelity = -1`
(fidelities.AUTO) with its parameter `tolerance`, and `vibrofmu simulate --fidelity auto --tolerance T`.

The candidates, cheapest first by their cost per output relative to the exact model at rtol 1e-8 (LADDER_COST: the
speed ladder's measured ratios; EXACT_RUN_COST: the exact model's per rtol, measured by the auto campaign): the
averaged slow flow, the OAFM analytic solution, then DOP853 on the exact model from the loosest rtol (1e-4) to the
tightest (1e-12). A run also pays its rung's set-up and, for the averaged rung, its table (setup_cost): the exact
model's ~a millisecond (SETUP_COST); the slow flow's fixed set-up (SETUP_COST) and its table per unit of tau over the
whole run (TABLE_COST: tabulated to slowflow.WINDOW at set-up, beyond it by the doSteps, at the same cost per tau);
the OAFM fit per unit of its fit span (FIT_COST: fitted, or read from a cache that holds it). On the paper scene the
table alone (21 outputs of the exact model per tau, 2.1 per output at interval 0.1) costs more than the exact model's
run at any rtol, and the fit more than a run of 10^4 outputs: see docs/rungs.md. So the chooser first estimates the
exact model at each rtol (a closed form of the scene: no plant is built), takes the loosest that meets the tolerance
as the fallback, and builds an averaged or analytic rung only when its modelled cost (set-up, table and outputs at
the interval OUTPUT_INTERVAL over the run's span) is below the fallback's whole run: then a rung built and rejected
costs about the fallback's own cost at most. Their estimate needs their set-up (the slow-flow solution, the OAFM
residual): the plant built to estimate is the plant the run uses. The averaged rung is first asked a pre-check from
its averaged model alone (averaged_floor: a floor of its estimate, the slow flow's frequency error; ~0.1 ms where
its set-up takes ~1-3 ms): a floor above the tolerance passes it over unbuilt, as does its domain's refusal. Only the chosen exact candidate is built. A rung
that refuses the scene (a ParameterError; the analytic rung's fit span is asked before it is built) is passed over;
none meets: refused, naming the tolerance.

The native FMU (no Python: no averaged or analytic rung) walks the same list, generated into its rules.h
(harness/vibrofmu/fmus/native.py: auto_rows), passing over the levels it cannot run; its estimates of the exact
model are this module's to the digit (core/estimate.c), so it chooses what `choose(..., native=True)` does.
"""
from __future__ import annotations

import math
from dataclasses import replace

from .fidelities import AUTO, NATIVE_NEEDS_PYTHON, Fidelity, entry
from .messages import text
from .parameters import ParameterError

DEFAULT_TOLERANCE = 1e-6  # max|x - x_exact| in x's units (the paper scene's amplitude is 0.04)
# The speed ladder's cost per output relative to exact f0 (DOP853 at rtol 1e-8): the C host at output interval 0.1,
# median over its rounds of the thread-CPU ratio (`vibrofmu bench`, docs/numerics.md's speed block; the bench prints
# this table beside the ratios it measures, `auto_costs` in bench.json).
LADDER_COST = {Fidelity.AVERAGED: 0.284, Fidelity.ANALYTIC: 0.362}
# The exact model's cost per output at each candidate rtol relative to rtol 1e-8, and its set-up (make_plant with its
# error estimate) in outputs of the exact model's loop at rtol 1e-8: medians over the 500 pairs of the auto campaign
# (`python -m vibrofmu.analyses.error_calibration auto 500 7`: its candidates' thread CPU on the compiled kernel, the
# doStep loop at interval 0.1; its report block prints the medians it measured beside these).
# The odd decades are the geometric mean of their neighbours' (not measured alone; the campaign's block prints the
# measured medians of all): a ladder of one decade, so that the estimate's over-estimate (10-100x, docs/rungs.md's
# calibration) costs a step of ~1.2x, not of ~1.5x.
EXACT_RUN_COST = {1e-4: 0.69, 1e-5: 0.7, 1e-6: 0.71, 1e-7: 0.84, 1e-8: 1.0, 1e-9: 1.23, 1e-10: 1.52, 1e-11: 1.83, 1e-12: 2.21}
EXACT_RTOLS = tuple(EXACT_RUN_COST)
# The averaged and analytic rungs' set-up in the same unit: medians over the paper scene and 24 random scenes
# (`python -m vibrofmu.analyses.error_calibration costs 24 0`, thread CPU on the compiled kernel, least of 3; its
# per-scene values spread ~3x about the median). The slow flow, integrated and tabulated on the compiled kernel
# (core/slowflow_table.c, its estimate's samples too): 970 fixed (its model, the slow state's start, the first
# table's grid refinement, the estimate's fixed part; medians of two runs 977 and 965, 10-90 % 643-1,920; the paper
# scene 1,850-1,910) and 4.0 per unit of tau of table and estimate (set-up at stop 1000 minus at 200, per tau: medians
# 3.65 and 4.40, the paper scene 3.4-5.1; the doSteps' extensions beyond WINDOW, their lookups included, 9.9-10.1, of
# which the lookups at LADDER_COST are ~7.6), measured at a load average of 6-8 on 2 cores. Per tau at interval 0.1
# the averaged rung (4.0 + 2.84) and the exact model at rtol 1e-4 (6.9) then cost about the same: its fixed set-up
# is paid back only over ~10^4 tau. With SciPy's integration and numpy's table they were 8,750 and 21.
# The OAFM fit per unit of its fit span: 1,900 fitted (median 1,984; the paper scene 3,600), 320 read from the cache
# (median 325; the paper scene 450).
SETUP_COST = {Fidelity.EXACT: 250.0, Fidelity.AVERAGED: 970.0, Fidelity.ANALYTIC: 0.0}
TABLE_COST = 4.0
FIT_COST = {"fitted": 1900.0, "cached": 320.0}
OUTPUT_INTERVAL = 0.1  # the outputs a run is costed by (FMI 2 tells no communication step at initialisation)


def candidates(settings):
    """(cost per output, settings) of every candidate, cheapest first (the exact model from its loosest rtol)."""
    rows = [(cost, replace(settings, fidelity=int(level))) for level, cost in LADDER_COST.items()]
    rows += [(cost, replace(settings, fidelity=int(Fidelity.EXACT), solver=0, rtol=rtol, max_step=0.0))
             for rtol, cost in EXACT_RUN_COST.items()]
    return sorted(rows, key=lambda row: row[0])


EXACT_ROWS = tuple(sorted(((cost, rtol) for rtol, cost in EXACT_RUN_COST.items())))  # (cost, rtol), cheapest first
# choose's walk: (cost per output, registry entry, rtol or None), cheapest first, as candidates()
CHOICE_ROWS = tuple(sorted([(cost, entry(level), None) for level, cost in LADDER_COST.items()]
                           + [(cost, entry(Fidelity.EXACT), rtol) for cost, rtol in EXACT_ROWS], key=lambda row: row[0]))


def setup_cost(level, span: float, fit_span: float | None = None, cached: bool = False) -> float:
    """A candidate's modelled cost of a run of `span` beside its outputs, in outputs of the exact model at rtol 1e-8:
    the exact model's set-up; the slow flow's fixed set-up and its table over the run (at least slowflow.CHUNK, its
    first table); the OAFM fit over fit_span (analytic.covering's tau_end), fitted or read from the cache."""
    level = Fidelity(int(level))
    if level == Fidelity.AVERAGED:
        from .slowflow import CHUNK  # fidelity 3's module: imported only where its cost is asked
        return SETUP_COST[level] + TABLE_COST * max(span, CHUNK)
    if level == Fidelity.ANALYTIC:
        return SETUP_COST[level] + FIT_COST["cached" if cached else "fitted"] * (span if fit_span is None else fit_span)
    return SETUP_COST[level]


def run_cost(level, per_output: float, span: float, fit_span: float | None = None, cached: bool = False) -> float:
    """A candidate's modelled cost of a run of `span`: setup_cost and its outputs at OUTPUT_INTERVAL, in outputs of
    the exact model at rtol 1e-8."""
    return setup_cost(level, span, fit_span, cached) + per_output * span / OUTPUT_INTERVAL


def fit_plan(scene, settings, span: float, t0: float = 0.0, cache_dirs: tuple = ()) -> tuple[float, bool]:
    """(the analytic rung's fit span over a run of `span` from t0, whether a cache holds that fit: one of cache_dirs
    or the user's cache, as analytic.cached_solve looks); ParameterError where the rung refuses the span
    (analytic.covering, strict: the plant's own check)."""
    from pathlib import Path

    from .analytic import cache_key, covering, user_cache_dir
    oafm = covering(scene, settings.oafm, span, strict=True)
    name = cache_key(scene, oafm, t0) + ".json"
    return oafm.tau_end, any((Path(d) / name).is_file() for d in (*cache_dirs, user_cache_dir()))


def exact_estimate(scene, rtol: float, span: float, estimator=None) -> float:
    """The estimate of the exact model's candidate at rtol (DOP853, max_step automatic) without building its plant:
    the registry's estimator's value (error_estimates.solver_terms, here through its AdaptiveEstimator), as the plant
    publishes it (rounded: error_estimates.attach); nan when it cannot estimate. estimator: the scene's
    AdaptiveEstimator over the span, shared by the candidates."""
    from .error_estimates import AdaptiveEstimator, response_parts, round_estimate
    try:
        estimator = estimator or AdaptiveEstimator(scene, span, 0.0, response_parts(scene, span))
        return round_estimate(estimator.terms(rtol)["solver"])
    except (ArithmeticError, ValueError):
        return math.nan


def averaged_floor(scene, t0: float, span: float) -> float:
    """The averaged rung's pre-check, from its averaged model alone (no slow flow integrated, no table: ~0.1 ms
    where its set-up takes ~1-3 ms): error_estimates.averaged_floor, a floor below its estimate; ParameterError
    where its build would refuse the scene before any integration (no stable equilibrium, the averaging's domain:
    fidelities' averaged solution, in the same order)."""
    from .averaging import checked_averaged, validity_estimates  # fidelity 3's modules: loaded only where it is asked
    from .error_estimates import averaged_floor as floor

    model = checked_averaged(scene)
    refusal, _ = validity_estimates(model)
    if refusal is not None:
        raise refusal
    return floor(model, t0, span)


def describe(settings) -> str:
    """"fidelity 0 at rtol 1e-10" or "fidelity 3"."""
    if entry(settings.fidelity).integrated:
        return text("AUTO_EXACT_RUNG", level=int(settings.fidelity), rtol=settings.rtol)
    return text("AUTO_RUNG", level=int(settings.fidelity))


def check_tolerance(tolerance: float) -> None:
    if not (math.isfinite(tolerance) and tolerance > 0.0):
        raise ParameterError("tolerance", tolerance, "must be a positive bound on max|x - x_exact|")


def choose(scene, settings, tolerance: float, build, native: bool = False, span: float | None = None,
           t0: float = 0.0, cache_dirs: tuple = (), passed_over: list | None = None):
    """(the plant of the cheapest candidate whose estimate meets `tolerance`, its settings, the log lines of the
    choice). build(settings) -> plant (make_plant with the run's arguments); span: the run's length (None: the
    estimates' DEFAULT_SPAN); t0, cache_dirs: the run's start and the OAFM caches build reads (fit_plan). ParameterError
    naming `tolerance` when none meets it. native: as the native FMU chooses (the levels it cannot run passed over,
    without building them). The exact model's estimates are asked lazily, loosest rtol first, and the first that
    meets the tolerance is the fallback the cheap rungs must beat. The averaged rung, where its cost would have it
    built, is first asked its pre-check (averaged_floor): passed over unbuilt where its estimate's floor exceeds the
    tolerance or its domain refuses the scene. passed_over: a list that receives the candidates passed over, each
    (message name, its values) as the log line words them (the auto campaign counts the pre-check's by it)."""
    from .error_estimates import DEFAULT_SPAN, AdaptiveEstimator, response_parts

    check_tolerance(tolerance)
    span = DEFAULT_SPAN if span is None or not math.isfinite(span) or span <= 0.0 else float(span)
    try:
        estimator = AdaptiveEstimator(scene, span, 0.0, response_parts(scene, span))
    except (ArithmeticError, ValueError):
        estimator = None  # every exact candidate's estimate is then nan (exact_estimate)
    estimates = {}

    def estimate_at(rtol):
        if rtol not in estimates:
            estimates[rtol] = exact_estimate(scene, rtol, span, estimator) if estimator else math.nan
        return estimates[rtol]

    fallback = next(((cost, rtol) for cost, rtol in EXACT_ROWS if estimate_at(rtol) <= tolerance), None)
    fallback_cost = run_cost(Fidelity.EXACT, fallback[0], span) if fallback is not None else math.inf
    tried = [] if passed_over is None else passed_over  # (message, its values): formatted only for the log line
    for cost, level, rtol in CHOICE_ROWS:
        fidelity = int(level.level)
        if native and level.native_refusal is not None:
            tried.append(("AUTO_REFUSED", {"level": fidelity, "parameter": NATIVE_NEEDS_PYTHON}))
            continue
        if rtol is not None:
            rung = ("AUTO_EXACT_RUNG", {"level": fidelity, "rtol": rtol})
            estimate = estimate_at(rtol)
            if not (math.isfinite(estimate) and estimate <= tolerance):
                tried.append(("AUTO_ESTIMATE", {"rung": rung, "estimate": estimate}))
                continue
            candidate = replace(settings, fidelity=fidelity, solver=0, rtol=rtol, max_step=0.0)
        else:
            rung = ("AUTO_RUNG", {"level": fidelity})
            fit_span, cached = None, True  # the analytic rung's: cached first, its least cost
            if not native and level.level == Fidelity.ANALYTIC and run_cost(fidelity, cost, span, span, True) < \
                    fallback_cost:  # worth asking its fit span and the cache (a file's existence)
                try:
                    fit_span, cached = fit_plan(scene, settings, span, t0, cache_dirs)
                except ParameterError as refusal:
                    tried.append(("AUTO_REFUSED", {"level": fidelity, "parameter": refusal.name}))
                    continue
            if not native and run_cost(fidelity, cost, span, fit_span, cached) >= fallback_cost:
                tried.append(("AUTO_SETUP", {"rung": rung, "fallback": ("AUTO_EXACT_RUNG",
                                                                         {"level": 0, "rtol": fallback[1]})}))
                continue
            candidate = replace(settings, fidelity=fidelity)
            if level.level == Fidelity.AVERAGED:  # its pre-check: passed over unbuilt where it cannot meet the tolerance
                try:
                    floor = averaged_floor(scene, t0, span)
                except ParameterError as refusal:  # the averaging's own domain, as its build would refuse it
                    tried.append(("AUTO_REFUSED", {"level": fidelity, "parameter": refusal.name}))
                    continue
                if floor > tolerance:
                    tried.append(("AUTO_FLOOR", {"rung": rung, "floor": floor}))
                    continue
        try:
            plant = build(candidate)
        except ParameterError as refusal:
            tried.append(("AUTO_REFUSED", {"level": fidelity, "parameter": refusal.name}))
            continue
        estimate = plant.error_estimate["estimate"] if plant.error_estimate else math.nan
        if math.isfinite(estimate) and estimate <= tolerance:
            skipped = text("AUTO_SKIPPED", tried=_listed(tried)) if tried else ""
            return plant, candidate, [text("AUTO_CHOSE", rung=_formatted(rung), cost=cost, estimate=estimate,
                                           tolerance=tolerance, skipped=skipped)]
        tried.append(("AUTO_ESTIMATE", {"rung": rung, "estimate": estimate}))
    raise ParameterError("tolerance", tolerance, text("AUTO_NONE", tried=_listed(tried)))


def _formatted(message) -> str:
    """A (name, values) message of choose, its values' messages formatted first."""
    name, values = message
    return text(name, **{k: _formatted(v) if isinstance(v, tuple) else v for k, v in values.items()})


def _listed(tried) -> str:
    return "; ".join(_formatted(message) for message in tried)


def auto_plant(scene, settings, tolerance: float, build, span: float | None = None, t0: float = 0.0,
               cache_dirs: tuple = ()):
    """The plant fidelity auto runs (choose), its notes opened by the choice's log line (the FMU logs it, fmi2OK)."""
    plant, chosen, log = choose(scene, settings, tolerance, build, span=span, t0=t0, cache_dirs=cache_dirs)
    plant.notes[:0] = log
    return plant


def is_auto(fidelity) -> bool:
    return int(fidelity) == AUTO
