"""The fidelity registry: one entry per fidelity level of the plant, read by everything that depends on the level
(plant.Plant, compiled.CompiledPlant, models.make_model, settings.checked_settings, the harness's simulate and bench).

Adding a fidelity touches its model (a module with the model or solution), its compiled evaluator (fmu_src/core) if
it has one, and one entry here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from .models import ExactModel, Fidelity, PolynomialModel
from .parameters import ParameterError, Scene


@dataclass(frozen=True)
class FidelityEntry:
    """level: the FMU's `fidelity` value; key: its command-line name; description: the FMU parameter's text.
    model(scene): the forces (and x'' for an integrated level) of the level.
    integrated: the plant steps model.accel with DOP853 or RK4 (Eq. 3 or Eq. 7).
    compiled_model: VkModel.polynomial of the compiled core (core/model.h) for the level, None if the compiled plant
    does not run it.
    open_loop(scene, settings, t0, stop_time, cache_dirs) -> (solution, notes): for a level whose doStep evaluates a
    precomputed solution (solution.state(t) -> (x, x', x'')) with U = 0; None for integrated levels.
    solution_in_snapshot: the solution holds state that FMU states must carry (it grows as the run advances).
    check_settings(settings): raises ParameterError for settings only this level has (None: none).
    work(solution) -> dict: what the set-up of an open-loop level did (table size, fit size...), for the bench.
    uses_rtol: the level's result depends on Settings.rtol (every integrated level; fidelity 3's slow flow)."""

    level: Fidelity
    key: str
    description: str
    model: Callable[[Scene], object]
    integrated: bool
    compiled_model: int | None
    open_loop: Callable | None = None
    solution_in_snapshot: bool = False
    check_settings: Callable | None = None
    work: Callable | None = None
    uses_rtol: bool = True

    @property
    def name(self) -> str:
        """The description without its leading level number ("averaged slow flow")."""
        return self.description.split(" ", 1)[1]


def _averaged_solution(scene, settings, t0, stop_time, cache_dirs):
    """Fidelity 3: the averaged slow flow integrated with large steps (docs/model.md, Averaging and slow flow)."""
    from .averaging import averaged, validity_notes  # only fidelity 3 loads the slow flow
    from .slowflow import SlowFlowSolution

    model = averaged(scene)
    solution = SlowFlowSolution(model, t0, scene.x_start, scene.v_start, settings.rtol, settings.max_step or math.inf,
                                stop_time, bounded=True)  # a window of the table at a time (slowflow.WINDOW)
    notes = [f"averaged slow flow (docs/model.md, Averaging and slow flow, {model.backbone.kind} backbone): x_e = {model.eq.x_e:.6g}, omega_e = "
             f"{model.omega_e:.8g}, table spacing {solution.spacing:.3g}"]
    return solution, notes + [f"outside the averaging's validity: {note}" for note in validity_notes(model)]


def _analytic_solution(scene, settings, t0, stop_time, cache_dirs):
    """Fidelity 4: the OAFM solution fitted to cover [t0, stop_time] (or read from a cache)."""
    from .analytic import cached_solve, covering

    span = None if stop_time is None else stop_time - t0
    oafm = covering(scene, settings.oafm, span, strict=True)  # refuses a fit beyond analytic.MAX_FIT_SPAN
    solution, source = cached_solve(scene, oafm, t0, read_dirs=cache_dirs)
    notes = [f"OAFM {oafm.basis} basis, tau* = {solution.pieces[1].start:.6g}, fit to tau = {solution.tau_end:.6g} "
             f"({source})"]
    if stop_time is None:
        notes.append(f"no stop time given: beyond tau = {solution.tau_end:.6g} the analytic solution extrapolates "
                     "the fit")
    return solution, notes


def _averaged_work(solution) -> dict:
    return {"slow_flow_integration_seconds": solution.integration_seconds, "table_cells": len(solution.cells),
            "table_spacing": solution.spacing}


def _analytic_work(solution) -> dict:
    return {"pieces": len(solution.pieces), "convergence_control_parameters": sum(len(c) for c in solution.C)}


def _check_oafm(settings) -> None:
    settings.oafm.validate()


REGISTRY: dict[Fidelity, FidelityEntry] = {e.level: e for e in (
    FidelityEntry(Fidelity.EXACT, "exact", "0 exact Eq. 3", ExactModel, True, 0),
    FidelityEntry(Fidelity.POLYNOMIAL, "polynomial", "1 polynomial Eq. 7", PolynomialModel, True, 1),
    FidelityEntry(Fidelity.POLYNOMIAL_PAPER, "polynomial-paper", "2 Eq. 7 printed coefficients",
                  lambda scene: PolynomialModel(scene, printed=True), True, 1),
    FidelityEntry(Fidelity.AVERAGED, "averaged", "3 averaged slow flow", ExactModel, False, None,
                  open_loop=_averaged_solution, solution_in_snapshot=True, work=_averaged_work),
    FidelityEntry(Fidelity.ANALYTIC, "analytic", "4 OAFM analytic", ExactModel, False, None,
                  open_loop=_analytic_solution, check_settings=_check_oafm, work=_analytic_work, uses_rtol=False),
)}


def entry(fidelity: int) -> FidelityEntry:
    """The registry's entry of a fidelity level; ParameterError for an unknown one."""
    try:
        return REGISTRY[Fidelity(fidelity)]
    except ValueError:
        raise ParameterError("fidelity", fidelity, f"must be one of {[int(f) for f in REGISTRY]}") from None


def keys() -> dict[str, int]:
    """Command-line names -> levels."""
    return {e.key: int(e.level) for e in REGISTRY.values()}


def open_loop() -> tuple[Fidelity, ...]:
    """The levels whose doStep evaluates a precomputed solution (approximations of Eq. 3 no setting refines)."""
    return tuple(e.level for e in REGISTRY.values() if not e.integrated)


def integrated() -> tuple[Fidelity, ...]:
    """The levels whose plant steps Eq. 3 or 7 (the closed loop's possible plants)."""
    return tuple(e.level for e in REGISTRY.values() if e.integrated)
