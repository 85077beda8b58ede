"""Fidelity "auto": the cheapest rung and setting whose error estimate meets a tolerance on max|x - x_exact|
(vibromodel.error_estimates; docs/rungs.md, Choosing by tolerance). The plant FMU's `fidelity = -1`
(fidelities.AUTO) with its parameter `tolerance`, and `vibrofmu simulate --fidelity auto --tolerance T`.

The candidates, cheapest first by their cost per output relative to the exact model at rtol 1e-8 (LADDER_COST: the
speed ladder's measured ratios; DOP853's steps grow as rtol^(-1/8) below rtol 1e-8, its order's step-size rule, and
are taken as no cheaper above it, where the drive's step ceiling bounds the steps): the averaged slow flow, the OAFM
analytic solution, then DOP853 on the exact model at rtol 1e-4 ... 1e-12 (at one cost the tightest first). Each is
built in turn (a rung that refuses the scene is skipped) until one's estimate meets the tolerance; none: refused,
naming the tolerance. The first plant that meets it is the one the run uses.

The native FMU (no Python: no averaged or analytic rung) walks the same list, generated into its rules.h
(harness/vibrofmu/fmus/native.py: auto_rows), passing over the levels it cannot run; its estimates of the exact
model are this module's to the digit (native/plant_setup.c), so it chooses what `choose(..., native=True)` does.
"""
from __future__ import annotations

import math
from dataclasses import replace

from .fidelities import AUTO, NATIVE_NEEDS_PYTHON, Fidelity, entry
from .messages import text
from .parameters import ParameterError

DEFAULT_TOLERANCE = 1e-6  # max|x - x_exact| in x's units (the paper scene's amplitude is 0.04)
EXACT_RTOLS = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
# The speed ladder's cost per output relative to exact f0 (DOP853 at rtol 1e-8): the C host at output interval 0.1,
# median over its rounds of the thread-CPU ratio (`vibrofmu bench`, docs/numerics.md's speed block; the bench prints
# this table beside the ratios it measures, `auto_costs` in bench.json).
LADDER_COST = {Fidelity.AVERAGED: 0.284, Fidelity.ANALYTIC: 0.362}
EXACT_RTOL_EXPONENT = 0.125  # DOP853 (order 8): steps per unit time ~ rtol^(-1/8)


def exact_cost(rtol: float) -> float:
    """The exact model's cost at rtol, relative to rtol 1e-8."""
    return max(1.0, (1e-8 / rtol) ** EXACT_RTOL_EXPONENT)


def candidates(settings):
    """(cost, settings) of every candidate, cheapest first (at one cost, the tightest rtol first)."""
    rows = [(cost, replace(settings, fidelity=int(level))) for level, cost in LADDER_COST.items()]
    rows += [(exact_cost(rtol), replace(settings, fidelity=int(Fidelity.EXACT), solver=0, rtol=rtol, max_step=0.0))
             for rtol in EXACT_RTOLS]
    return sorted(rows, key=lambda row: (row[0], row[1].rtol if entry(row[1].fidelity).integrated else 0.0))


def describe(settings) -> str:
    """"fidelity 0 at rtol 1e-10" or "fidelity 3"."""
    if entry(settings.fidelity).integrated:
        return text("AUTO_EXACT_RUNG", level=int(settings.fidelity), rtol=settings.rtol)
    return text("AUTO_RUNG", level=int(settings.fidelity))


def check_tolerance(tolerance: float) -> None:
    if not (math.isfinite(tolerance) and tolerance > 0.0):
        raise ParameterError("tolerance", tolerance, "must be a positive bound on max|x - x_exact|")


def choose(scene, settings, tolerance: float, build, native: bool = False):
    """(the plant of the cheapest candidate whose estimate meets `tolerance`, its settings, the log lines of the
    choice). build(settings) -> plant (make_plant with the run's arguments). ParameterError naming `tolerance` when
    none meets it. native: as the native FMU chooses (the levels it cannot run passed over, without building them)."""
    check_tolerance(tolerance)
    tried = []
    for cost, candidate in candidates(settings):
        level = entry(candidate.fidelity)
        if native and level.native_refusal is not None:
            tried.append(text("AUTO_REFUSED", level=int(level.level), parameter=NATIVE_NEEDS_PYTHON))
            continue
        try:
            plant = build(candidate)
        except ParameterError as refusal:
            tried.append(text("AUTO_REFUSED", level=int(level.level), parameter=refusal.name))
            continue
        estimate = plant.error_estimate["estimate"] if plant.error_estimate else math.nan
        rung = describe(candidate)
        if math.isfinite(estimate) and estimate <= tolerance:
            skipped = text("AUTO_SKIPPED", tried="; ".join(tried)) if tried else ""
            return plant, candidate, [text("AUTO_CHOSE", rung=rung, cost=cost, estimate=estimate, tolerance=tolerance,
                                           skipped=skipped)]
        tried.append(text("AUTO_ESTIMATE", rung=rung, estimate=estimate))
    raise ParameterError("tolerance", tolerance, text("AUTO_NONE", tried="; ".join(tried)))


def auto_plant(scene, settings, tolerance: float, build):
    """The plant fidelity auto runs (choose), its notes opened by the choice's log line (the FMU logs it, fmi2OK)."""
    plant, chosen, log = choose(scene, settings, tolerance, build)
    plant.notes[:0] = log
    return plant


def is_auto(fidelity) -> bool:
    return int(fidelity) == AUTO
