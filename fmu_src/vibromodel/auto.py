"""Fidelity "auto": the cheapest rung and setting whose error estimate meets a tolerance on max|x - x_exact|
(vibromodel.error_estimates; docs/rungs.md, Choosing by tolerance).

The candidates, cheapest first by their cost per output relative to the exact model at rtol 1e-8 (the speed
ladder's measured ratios, docs/rungs.md, Choosing a rung: the averaged and analytic rungs cost at most 0.5 of it,
RK4 at h = 0.01 up to 4 times; DOP853's steps grow as rtol^(-1/8) below rtol 1e-8, its order's step-size rule, and
are taken as no cheaper above it, where the drive's step ceiling bounds the steps):
the averaged slow flow, the OAFM analytic solution, then DOP853 on the exact model at rtol 1e-4 ... 1e-12. Each is
built in turn (a rung that refuses the scene is skipped) until one's estimate meets the tolerance; none: refused,
naming the tolerance. The first plant that meets it is the one the run uses.
"""
from __future__ import annotations

import math
from dataclasses import replace

from .fidelities import Fidelity
from .parameters import ParameterError

DEFAULT_TOLERANCE = 1e-6  # max|x - x_exact| in x's units (the paper scene's amplitude is 0.04)
EXACT_RTOLS = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
# cost per output relative to exact DOP853 at rtol 1e-8 (the ladder's acceptance limits for the open-loop rungs)
OPEN_LOOP_COST = {Fidelity.AVERAGED: 0.3, Fidelity.ANALYTIC: 0.4}


def candidates(settings):
    """(cost, settings) of every candidate, cheapest first."""
    rows = [(cost, replace(settings, fidelity=int(level))) for level, cost in OPEN_LOOP_COST.items()]
    rows += [(max(1.0, (1e-8 / rtol) ** 0.125), replace(settings, fidelity=int(Fidelity.EXACT), solver=0, rtol=rtol,
                                              max_step=0.0)) for rtol in EXACT_RTOLS]
    return sorted(rows, key=lambda row: (row[0], row[1].rtol))  # at one cost, the tightest rtol


def choose(scene, settings, tolerance: float, build):
    """(the plant of the cheapest candidate whose estimate meets `tolerance`, its settings, the log lines of the
    choice). build(settings) -> plant (make_plant with the run's arguments). ParameterError naming `tolerance` when
    none meets it."""
    if not (math.isfinite(tolerance) and tolerance > 0.0):
        raise ParameterError("tolerance", tolerance, "must be a positive bound on max|x - x_exact|")
    tried = []
    for cost, candidate in candidates(settings):
        try:
            plant = build(candidate)
        except ParameterError as refusal:
            tried.append(f"fidelity {candidate.fidelity}: refused ({refusal.name})")
            continue
        estimate = plant.error_estimate["estimate"] if plant.error_estimate else math.nan
        label = describe(candidate)
        if math.isfinite(estimate) and estimate <= tolerance:
            return plant, candidate, [f"fidelity auto chose {label} (cost {cost:.2g} of exact at rtol 1e-8): its "
                                      f"error estimate {estimate:.3g} meets the tolerance {tolerance:g}"
                                      + (f"; skipped: {'; '.join(tried)}" if tried else "")]
        tried.append(f"{label}: estimate {estimate:.3g}")
    raise ParameterError("tolerance", tolerance, "no rung's error estimate meets it (" + "; ".join(tried)
                         + "); raise the tolerance")


def describe(settings) -> str:
    """"fidelity 0 at rtol 1e-10" or "fidelity 3"."""
    if settings.fidelity == Fidelity.EXACT:
        return f"fidelity 0 at rtol {settings.rtol:g}"
    return f"fidelity {int(settings.fidelity)}"
