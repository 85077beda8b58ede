"""The plant's settings (fidelity, solver, tolerance, kernel), their checks, its outputs and the checks of a step:
shared by every plant implementation (plant.Plant, compiled.CompiledPlant) and the closed loop, so that neither
imports the other.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import IntEnum

from .analytic import OafmSettings
from .fidelities import Fidelity, entry
from .integrate import RK4_DRIVE_ERROR, RK4_DRIVE_THETA, rk4_drive_gains
from .parameters import (ParameterError, Scene, check_parameters, clamp_tolerance, validate_max_step,
                         validate_tolerance)
from .solvers import BY_VALUE as _SOLVERS_BY_VALUE, FIXED_DEFAULT_STEP, must_be, solver_entry

DEFAULT_EXPERIMENT = (0.0, 200.0, 0.1)  # start, stop, communication step of the FMU's DefaultExperiment
RK4_DEFAULT_STEP = FIXED_DEFAULT_STEP  # RK4 step when max_step = 0 ("automatic"): solvers.FIXED_DEFAULT_STEP
TIME_TOLERANCE = 1e-9  # relative mismatch allowed between the host's time and the plant's
MAX_STEPS_PER_DOSTEP = 10**6  # more steps in one doStep: refused up front (step ceiling) or stopped
# The bound is on a doStep's work, not its steps: a step of the pure-Python kernel costs about PYTHON_STEP_COST steps
# of the compiled one (measured on this machine: the plant's RK4 step 37 us in Python, the closed loop's about 200 us,
# against 0.3 to 2 us compiled), so the pure-Python kernel gets MAX_STEPS_PER_DOSTEP / PYTHON_STEP_COST steps (a
# closed loop doStep of 999,000 RK4 steps in Python had not returned after 200 s). The native FMUs run both kernels
# compiled: their bound is MAX_STEPS_PER_DOSTEP.
PYTHON_STEP_COST = 100


# The solvers of the registry (solvers.SOLVERS): Solver.ADAPTIVE, Solver.RK4, ...
Solver = IntEnum("Solver", [(entry.enum, entry.value) for entry in _SOLVERS_BY_VALUE.values()], module=__name__)


class Kernel(IntEnum):
    COMPILED = 0  # vibromodel.compiled (C) where it applies (fidelities.FidelityEntry.c_model)
    PYTHON = 1


@dataclass(frozen=True)
class Settings:
    fidelity: int = Fidelity.EXACT
    solver: int = Solver.ADAPTIVE
    rtol: float = 1e-8
    max_step: float = 0.0  # 0: automatic (no ceiling for the adaptive solver, 0.01 for RK4)
    kernel: int = Kernel.COMPILED
    oafm: OafmSettings = field(default_factory=OafmSettings)  # fidelity 4 only

    def validate(self) -> None:
        level = entry(self.fidelity)  # ParameterError for an unknown fidelity
        if level.check_settings is not None:
            level.check_settings(self)
        if self.solver not in set(Solver):
            raise ParameterError("solver", self.solver, must_be())
        if self.kernel not in set(Kernel):
            raise ParameterError("kernel", self.kernel, "must be 0 (compiled) or 1 (pure Python)")
        validate_tolerance(self.rtol)
        if self.max_step != 0.0:
            validate_max_step(self.max_step)


def checked_settings(scene: Scene, settings: Settings, interval: float | None = None) -> tuple[Settings, list[str]]:
    """(the settings a plant runs with, warnings about them). Raises ParameterError for bad settings.

    rtol below MIN_RTOL is clamped to it (parameters.clamp_tolerance); an RK4 step that does not resolve a
    forcing term of Eq. 3 or 7 is warned about (rk4_drive_warnings). Every plant implementation (and the closed
    loop) calls this one function. `interval`: the communication step when the caller knows it (a host): a
    doStep no longer than max_step is one RK4 step, so the warnings are about the step RK4 really takes.
    """
    settings.validate()
    check_parameters({**scene.as_dict(), "fidelity": int(settings.fidelity)})  # the fidelity's own ranges (robust)
    rtol, warning = clamp_tolerance(settings.rtol)
    warnings = [] if warning is None else [warning]
    solver = solver_entry(settings.solver)
    if solver.drive_gains is not None and entry(settings.fidelity).integrated:
        step = solver.step(settings.max_step)
        warnings += rk4_drive_warnings(scene, step if interval is None else min(step, interval),
                                       None if interval is None or interval >= step else settings.max_step)
    return replace(settings, rtol=rtol), warnings


def rk4_drive_warnings(scene: Scene, max_step: float, ceiling: float | None = None) -> list[str]:
    """Warnings for the forcing terms that RK4 steps of max_step do not resolve (integrate.RK4_DRIVE_THETA).

    The electrostatic AC terms oscillate at Omega (beta sin Omega t) and 2 Omega (gamma cos 2 Omega t), the load
    at omega (Delta cos omega t); a term with zero amplitude needs no resolving. Steps are at most max_step (a
    communication step that is not a multiple of it gets shorter steps), so the check is on max_step. `ceiling`:
    the setting max_step when max_step here is the (shorter) communication step, named in the text.
    """
    what_step = (f"RK4 max_step = {max_step:g}" if ceiling is None else
                 f"RK4 steps of {max_step:g} (the output interval; max_step = {ceiling:g} is longer)")
    ac = ([(2.0 * scene.Omega, "gamma cos(2 Omega tau)")] if scene.gamma != 0.0 else []) + \
         ([(scene.Omega, "beta sin(Omega tau)")] if scene.beta != 0.0 else [])
    drives = [("AC drive", "Omega", scene.Omega, ac[0][0], ac[0][1])] if ac else []
    if scene.Delta != 0.0:
        drives.append(("load forcing", "omega", scene.omega, scene.omega, "Delta cos(omega tau)"))
    warnings = []
    for what, name, value, nu, term in drives:
        theta = nu * max_step
        if theta <= RK4_DRIVE_THETA * (1.0 + 1e-12):  # the step this warning names, RK4_DRIVE_THETA / nu, passes
            continue
        gain = rk4_drive_gains(theta)[0]
        error = abs(gain - 1.0)  # inf at theta = 2 pi k: every step samples the drive at the same phase
        wrong = f"by {error:.0%}" if error <= 10.0 else "by more than 1000% (near 2 pi k rad per step, a resonance)"
        warnings.append(
            f"{what_step} do{'es' if ceiling is None else ''} not resolve the {what} at {name} = {value:g}: its term {term} "
            f"turns by {theta:.3g} rad per step (more than {RK4_DRIVE_THETA:.3g}, i.e. fewer than "
            f"{2.0 * math.pi / RK4_DRIVE_THETA:.2g} steps per period), so RK4 gets the ripple it drives in x wrong "
            f"{wrong}; the largest step that resolves it (ripple within {RK4_DRIVE_ERROR:.0%}) is "
            f"max_step = {RK4_DRIVE_THETA / nu:.3g}")
    return warnings


@dataclass(frozen=True)
class Outputs:
    x: float
    v: float
    a: float
    F_contact: float
    F_electrostatic: float
    in_contact: bool


def step_budget(kernel: int) -> int:
    """The most solver steps one doStep may take on `kernel` (the work bound: see PYTHON_STEP_COST)."""
    return MAX_STEPS_PER_DOSTEP if kernel == Kernel.COMPILED else MAX_STEPS_PER_DOSTEP // PYTHON_STEP_COST


def too_many_steps(h: float, ceiling: float, kernel: int = Kernel.COMPILED) -> str | None:
    """Why a doStep of h with steps of at most `ceiling` is refused up front on `kernel`, or None."""
    budget = step_budget(kernel)
    if not h / ceiling * (1.0 - 1e-12) > budget:  # the steps RK4 takes, ceil(h / ceiling * (1 - 1e-12)): a ratio
        # equal to the budget but for rounding (0.1 / 1e-7 = 1000000.0000000001) is accepted (plant.h's vk_too_many_steps)
        return None
    if kernel == Kernel.COMPILED:
        return (f"needs more than {budget} steps of {ceiling:g} (max_step); make smaller communication steps or "
                "raise max_step")
    return (f"needs more than {budget} steps of {ceiling:g} (max_step) on the pure-Python kernel (kernel = 1: a step "
            f"costs about {PYTHON_STEP_COST} of the compiled kernel's, which allows {MAX_STEPS_PER_DOSTEP}); make "
            "smaller communication steps, raise max_step or use kernel = 0")


def time_refused(at: float, t: float, h: float, ceiling: float, kernel: int = Kernel.COMPILED) -> bool:
    """Whether a doStep from the communication point t over h is refused for its time, the stepper being at `at`
    (plant.h's vk_time_refused; the plant's and the closed loop's check, each with its own words).

    t may differ from `at` by TIME_TOLERANCE relative, and the solver covers at .. t + h, not h: at a large |t| that
    difference alone can be many steps (at t = 3e296, where an ulp is 4e280, a fuzzed host's t beside the plant's
    asked RK4 for more than 1e280 steps of 0.01 within a doStep of 3.7e-6: a hang), so the span's steps are bounded
    as h's are."""
    return not (math.isfinite(t) and abs(t - at) <= TIME_TOLERANCE * max(1.0, abs(t))
                and too_many_steps((t + h) - at, ceiling, kernel) is None)


def check_step(plant_t: float, t: float, h: float, U: float, ceiling: float, open_loop: int | None = None,
               kernel: int = Kernel.COMPILED) -> None:
    """Plant.do_step's checks of a step from the communication point t (the plant is at plant_t) over h with
    input U; ceiling is the solver's max_step (inf: none), open_loop the fidelity of an open-loop plant (3, 4)
    or None, kernel the one stepping (its work bound). Raises ParameterError for the first check that fails."""
    if not (math.isfinite(h) and h > 0.0):
        raise ParameterError("communicationStepSize", h, "must be a finite number > 0")
    if not math.isfinite(U):
        raise ParameterError("U", U, "input must be a finite number")
    refusal = too_many_steps(h, ceiling, kernel)
    if refusal is not None:
        raise ParameterError("communicationStepSize", h, refusal)
    if time_refused(plant_t, t, h, ceiling, kernel):
        raise ParameterError("currentCommunicationPoint", t, f"the plant is at tau = {plant_t!r}")
    if open_loop is not None and U != 0.0:
        raise ParameterError("U", U, f"fidelity {open_loop} ({Fidelity(open_loop).name.lower()}) is open loop: "
                             "the input must be 0")
