"""The solver registry: one entry per solver of the plant and the closed loop (the `solver` setting), read by
everything that depends on the solver -- the settings' check and enum (settings.Solver), the parameter rule
(parameters.RULES), the FMUs' parameter description, the plants and the closed loop (their integrator), the compiled
front ends (which solver state the compiled core uses), the harness's --solver choices, the bench, the extremes and
the campaigns. Like SciPy's integrate/_ivp METHODS.

The compiled core has the same table in C: fmu_src/core/solver.c's vk_solvers, indexed by the same `value`
(core/solver.h: the solver interface, VK_SOLVER_LIST the list). Adding a solver (docs/architecture.md, How to add):
its Python integrator on integrate.Integrator (integrate.py), an entry here, its step in C (core/<file>.c) and its ops
with one X(<file>) in core/solver.h's VK_SOLVER_LIST.

This module imports nothing of vibromodel at import time (parameters.py reads it): the integrator classes are
resolved on first use.
"""
from __future__ import annotations

import importlib
import math
from dataclasses import dataclass

FIXED_DEFAULT_STEP = 0.01  # the fixed-step solvers' step when max_step = 0 ("automatic")


@dataclass(frozen=True)
class SolverEntry:
    """One solver.

    key: its name in the harness's records (campaign counters): "dop853", "rk4"; option: its --solver choice;
    value: the `solver` setting (Settings.solver, the FMU parameter) and the index of core/solver.c's table;
    enum: its member of settings.Solver; name: as notes and logs name it; label: as the settings' error names it;
    description: as the parameter rule and the FMU's parameter description name it;
    parameters: the settings it reads, with what each means to it (the rule text of max_step in its terms);
    family: "adaptive" (its state in the compiled core is Dop853: core/dop853.h) or "fixed" (Rk4: core/rk4.h), the
    compiled plants' state slot; integrator: "module:Class" of its Python integrator (make() builds it);
    drive_gains: "module:function" of (G_x, G_v) of a fast drive over the step (integrate.rk4_drive_gains), for a
    solver whose drive resolution the settings check and warn about, else None;
    compiled: whether the compiled core has it (core/solver.c).
    """
    key: str
    option: str
    value: int
    enum: str
    name: str
    label: str
    description: str
    parameters: tuple[tuple[str, str], ...]
    family: str
    integrator: str
    drive_gains: str | None = None
    compiled: bool = True

    @property
    def integrator_class(self):
        return _resolve(self.integrator)

    @property
    def drive_gain_function(self):
        return None if self.drive_gains is None else _resolve(self.drive_gains)

    @property
    def fixed_step(self) -> bool:
        return self.family == "fixed"

    def step(self, max_step: float, drive_ceiling: float = math.inf) -> float:
        """The step ceiling (adaptive) or the step (fixed) of the setting max_step; 0: automatic, i.e. the adaptive
        solver's drive_ceiling (models.drive_step_ceiling; inf: none) or the fixed step FIXED_DEFAULT_STEP."""
        return max_step or (FIXED_DEFAULT_STEP if self.fixed_step else drive_ceiling)

    def make(self, accel, events, t0, x0, v0, U, settings, *, rates=None, phased=None, step_budget=math.inf,
             drive_ceiling=math.inf):
        """The integrator of `settings` (rtol, max_step) from (t0, x0, v0) with input U; rates: extra states (the
        closed loop), phased: (frequencies, accel_phased) for a solver that steps with the drive's phasors,
        step_budget: most steps one advance may take (an adaptive solver's), drive_ceiling: the adaptive solver's step
        ceiling when max_step = 0 (models.drive_step_ceiling)."""
        return self.integrator_class.from_settings(accel, events, t0, x0, v0, U, settings,
                                                   self.step(settings.max_step, drive_ceiling), rates=rates,
                                                   phased=phased, step_budget=step_budget)


def _resolve(path: str):
    module, name = path.split(":")
    return getattr(importlib.import_module(module, __package__), name)


SOLVERS: dict[str, SolverEntry] = {entry.key: entry for entry in (
    SolverEntry("dop853", "adaptive", 0, "ADAPTIVE", "DOP853", "adaptive", "adaptive DOP853",
                (("rtol", "relative tolerance of the error control"),
                 ("max_step", "step ceiling; 0 = 4/(the fastest forcing frequency switched on)")),
                "adaptive", ".integrate:Dop853"),
    SolverEntry("rk4", "rk4", 1, "RK4", "RK4", "RK4", "fixed-step RK4",
                (("max_step", f"the step; 0 = {FIXED_DEFAULT_STEP:g}"),),
                "fixed", ".integrate:Rk4", drive_gains=".integrate:rk4_drive_gains"),
)}
BY_VALUE: dict[int, SolverEntry] = {entry.value: entry for entry in SOLVERS.values()}
assert sorted(BY_VALUE) == list(range(len(BY_VALUE))), "solver values must be 0, 1, ... (core/solver.c's indices)"

# What the `solver` setting means, in the FMU parameter's description and its rule: "0 adaptive DOP853, 1 fixed-step
# RK4"
RULE_TEXT = ", ".join(f"{entry.value} {entry.description}" for entry in BY_VALUE.values())


def solver_entry(value: int) -> SolverEntry:
    """The entry of the setting `value`; KeyError for another."""
    return BY_VALUE[int(value)]


def must_be() -> str:
    """The settings' error text: "must be 0 (adaptive) or 1 (RK4)"."""
    choices = [f"{entry.value} ({entry.label})" for entry in BY_VALUE.values()]
    return "must be " + (", ".join(choices[:-1]) + " or " + choices[-1] if len(choices) > 1 else choices[0])
