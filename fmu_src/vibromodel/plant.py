"""The plant as a co-simulation unit: a model of one fidelity, an integrator, and doStep.

The FMU slave maps FMI variables onto this class and nothing more; the harness can also drive it
directly (no FMI) to measure what the FMI layer costs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import IntEnum

from . import forces
from .analytic import OafmSettings, cached_solve, covering
from .integrate import RK4_DRIVE_ERROR, RK4_DRIVE_THETA, Dop853, IntegrationError, Rk4, rk4_drive_gains
from .models import Fidelity, make_model
from .parameters import (ParameterError, Scene, check_parameters, clamp_tolerance, validate, validate_max_step,
                         validate_tolerance)
from .snapshot import plain_attributes, restore_attributes

DEFAULT_EXPERIMENT = (0.0, 200.0, 0.1)  # start, stop, communication step of the FMU's DefaultExperiment
RK4_DEFAULT_STEP = 0.01  # RK4 step when max_step = 0 ("automatic")
TIME_TOLERANCE = 1e-9  # relative mismatch allowed between the host's time and the plant's
MAX_STEPS_PER_DOSTEP = 10**6  # more steps in one doStep: refused up front (step ceiling) or stopped
# What a snapshot leaves out: built from the scene and settings by the constructor.
PLANT_REBUILT = ("scene", "settings", "model", "integrator", "solution", "warnings")
INTEGRATED_FIDELITIES = (Fidelity.EXACT, Fidelity.POLYNOMIAL, Fidelity.POLYNOMIAL_PAPER)  # Eq. 3 or 7 stepped
INTEGRATOR_REBUILT = ("accel", "events", "rates")
SLOW_FLOW_REBUILT = ("flow",)  # fidelity 3: its table and integration end are plain data


class Solver(IntEnum):
    ADAPTIVE = 0
    RK4 = 1


class Kernel(IntEnum):
    COMPILED = 0  # vibromodel.compiled (C) where it applies: fidelities 0-2 with the adaptive solver
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
        if self.fidelity not in set(Fidelity):
            raise ParameterError("fidelity", self.fidelity, f"must be one of {[int(f) for f in Fidelity]}")
        if self.fidelity == Fidelity.ANALYTIC:
            self.oafm.validate()
        if self.solver not in set(Solver):
            raise ParameterError("solver", self.solver, "must be 0 (adaptive) or 1 (RK4)")
        if self.kernel not in set(Kernel):
            raise ParameterError("kernel", self.kernel, "must be 0 (compiled) or 1 (pure Python)")
        validate_tolerance(self.rtol)
        if self.max_step != 0.0:
            validate_max_step(self.max_step)


def checked_settings(scene: Scene, settings: Settings) -> tuple[Settings, list[str]]:
    """(the settings a plant runs with, warnings about them). Raises ParameterError for bad settings.

    rtol below MIN_RTOL is clamped to it (parameters.clamp_tolerance); an RK4 step that does not resolve a
    forcing term of Eq. 3 or 7 is warned about (rk4_drive_warnings). Every plant implementation (and the closed
    loop) calls this one function.
    """
    settings.validate()
    check_parameters({**scene.as_dict(), "fidelity": int(settings.fidelity)})  # the fidelity's own ranges
    rtol, warning = clamp_tolerance(settings.rtol)
    warnings = [] if warning is None else [warning]
    if settings.solver == Solver.RK4 and settings.fidelity in INTEGRATED_FIDELITIES:
        warnings += rk4_drive_warnings(scene, settings.max_step or RK4_DEFAULT_STEP)
    return replace(settings, rtol=rtol), warnings


def rk4_drive_warnings(scene: Scene, max_step: float) -> list[str]:
    """Warnings for the forcing terms that RK4 steps of max_step do not resolve (integrate.RK4_DRIVE_THETA).

    The electrostatic AC terms oscillate at Omega (beta sin Omega t) and 2 Omega (gamma cos 2 Omega t), the load
    at omega (Delta cos omega t); a term with zero amplitude needs no resolving. Steps are at most max_step (a
    communication step that is not a multiple of it gets shorter steps), so the check is on max_step.
    """
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
            f"RK4 max_step = {max_step:g} does not resolve the {what} at {name} = {value:g}: its term {term} "
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


def check_step(plant_t: float, t: float, h: float, U: float, ceiling: float, open_loop: int | None = None) -> None:
    """Plant.do_step's checks of a step from the communication point t (the plant is at plant_t) over h with
    input U; ceiling is the solver's max_step (inf: none), open_loop the fidelity of an open-loop plant (3, 4)
    or None. Raises ParameterError for the first check that fails."""
    if not (math.isfinite(h) and h > 0.0):
        raise ParameterError("communicationStepSize", h, "must be a finite number > 0")
    if not math.isfinite(U):
        raise ParameterError("U", U, "input must be a finite number")
    if h / ceiling > MAX_STEPS_PER_DOSTEP:
        raise ParameterError("communicationStepSize", h, f"needs more than {MAX_STEPS_PER_DOSTEP} steps of "
                             f"{ceiling:g} (max_step); make smaller communication steps or raise max_step")
    if not (math.isfinite(t) and abs(t - plant_t) <= TIME_TOLERANCE * max(1.0, abs(t))):
        raise ParameterError("currentCommunicationPoint", t, f"the plant is at tau = {plant_t!r}")
    if open_loop is not None and U != 0.0:
        raise ParameterError("U", U, f"fidelity {open_loop} ({Fidelity(open_loop).name.lower()}) is open loop: "
                             "the input must be 0")


class Plant:
    """Scene + settings -> a steppable plant. Raises ParameterError for bad input.

    Fidelities 3 and 4 have no integrator of Eq. 3 and are open loop (U = 0): fidelity 3 integrates the
    averaged slow flow here with large steps; fidelity 4 fits the OAFM solution here (or reads it from a
    cache in cache_dirs or the user cache) to cover [t0, stop_time]. doStep then evaluates their
    `solution.state`. `notes` says what initialisation did, for the FMU's log; `warnings` what it changed in
    the settings or doubts about them (checked_settings), for the FMU's log as fmi2Warning. `settings` are
    those used (rtol clamped).
    """

    def __init__(self, scene: Scene, settings: Settings, t0: float = 0.0, stop_time: float | None = None,
                 cache_dirs: tuple = ()):
        validate(scene)
        settings, self.warnings = checked_settings(scene, settings)
        self.scene, self.settings = scene, settings
        self.model = make_model(scene, settings.fidelity)
        self.t = t0
        self.U = 0.0
        self.notes: list[str] = []
        self.integrator = self.solution = None
        if settings.fidelity == Fidelity.AVERAGED:
            from .averaging import averaged, validity_notes  # only fidelity 3 loads the slow flow
            from .slowflow import SlowFlowSolution

            model = averaged(scene)
            self.solution = SlowFlowSolution(model, t0, scene.x_start, scene.v_start, settings.rtol,
                                             settings.max_step or math.inf, stop_time)
            self.notes.append(f"averaged slow flow (ERRATA §3.4, {model.backbone.kind} backbone): x_e = "
                              f"{model.eq.x_e:.6g}, omega_e = {model.omega_e:.8g}, table spacing "
                              f"{self.solution.spacing:.3g}")
            self.notes += [f"outside the averaging's validity: {note}" for note in validity_notes(model)]
        elif settings.fidelity == Fidelity.ANALYTIC:
            span = None if stop_time is None else stop_time - t0
            oafm = covering(scene, settings.oafm, span)
            self.solution, source = cached_solve(scene, oafm, t0, read_dirs=cache_dirs)
            self.notes.append(f"OAFM {oafm.basis} basis, tau* = {self.solution.pieces[1].start:.6g}, fit to "
                              f"tau = {self.solution.tau_end:.6g} ({source})")
            if stop_time is None:
                self.notes.append(f"no stop time given: beyond tau = {self.solution.tau_end:.6g} the analytic "
                                  "solution extrapolates the fit")
        elif settings.solver == Solver.ADAPTIVE:
            max_step = settings.max_step or math.inf
            self.integrator = Dop853(self.model.accel, self.model.events, t0, scene.x_start, scene.v_start,
                                     0.0, settings.rtol, max_step, step_budget=MAX_STEPS_PER_DOSTEP)
        else:
            self.integrator = Rk4(self.model.accel, self.model.events, t0, scene.x_start, scene.v_start,
                                  0.0, settings.max_step or RK4_DEFAULT_STEP)

    def do_step(self, t: float, h: float, U: float) -> Outputs:
        """Advance from the communication point t to t + h with input U held constant.

        Raises ParameterError for a bad step or input, IntegrationError (TerminalEvent for pull-in)
        when the model cannot be advanced.
        """
        check_step(self.t, t, h, U, math.inf if self.integrator is None else self.integrator.max_step,
                   None if self.solution is None else self.settings.fidelity)
        return self.outputs_at(self.t, *self.advance(t + h, U))  # t + h: the host's clock, no drift from sums

    def advance(self, t_end: float, U: float = 0.0) -> tuple[float, float, float]:
        """Move to t_end with U held and return (x, x', x''): the model's own work, without the checks
        and the output forces of do_step (what the speed measurements call model computation)."""
        if self.solution is None:
            self.integrator.set_input(self.t, U)  # at the old time: U changes there
            self.U = U
            self.integrator.advance(t_end)
        self.t = t_end
        return self.state()

    def state(self) -> tuple[float, float, float]:
        """(x, x', x'') now; x'' is the model's acceleration (fidelities 3 and 4: the solution's own x'')."""
        if self.solution is not None:
            return self.solution.state(self.t)
        x, v = self.integrator.value_at(self.t)
        return x, v, self.model.accel(self.t, x, v, self.U)

    def snapshot(self) -> dict:
        """Everything that decides the plant's future beyond its constructor's arguments, as plain data."""
        integrator = None if self.integrator is None else plain_attributes(self.integrator, INTEGRATOR_REBUILT)
        slow_flow = plain_attributes(self.solution, SLOW_FLOW_REBUILT) if self._slow_flow() else None
        return {"plant": plain_attributes(self, PLANT_REBUILT), "integrator": integrator, "slow_flow": slow_flow}

    def restore(self, snapshot: dict) -> None:
        """Return a plant built with the same arguments to the moment `snapshot` was taken.

        Fidelity 4's analytic solution is not in the snapshot: the constructor re-derives it
        deterministically from the scene and settings (or reads the same fit from a cache). Fidelity 3's
        table is: without a stop time it grows in chunks that depend on the steps taken.
        """
        restore_attributes(self, snapshot["plant"], PLANT_REBUILT)
        if self.integrator is not None:
            restore_attributes(self.integrator, snapshot["integrator"], INTEGRATOR_REBUILT)
        if self._slow_flow():
            restore_attributes(self.solution, snapshot["slow_flow"], SLOW_FLOW_REBUILT)

    def _slow_flow(self) -> bool:
        return self.settings.fidelity == Fidelity.AVERAGED

    def outputs(self) -> Outputs:
        return self.outputs_at(self.t, *self.state())

    def outputs_at(self, t: float, x: float, v: float, a: float | None = None) -> Outputs:
        """Outputs at a state; a = x'' of the model unless given."""
        f_contact, f_electrostatic = self.model.forces(t, x)
        if a is None:
            a = self.model.accel(t, x, v, self.U)
        return Outputs(x=x, v=v, a=a, F_contact=f_contact,
                       F_electrostatic=f_electrostatic, in_contact=forces.contact_indentation(x) > 0.0)


def make_plant(scene: Scene, settings: Settings, t0: float = 0.0, stop_time: float | None = None,
               cache_dirs: tuple = (), library: tuple = (None, "no library given")):
    """The plant of `settings`: on the compiled kernel (vibromodel.compiled.CompiledPlant) where it applies,
    settings.kernel asks for it and library = (vibromodel.compiled.load_library's result) holds one; else Plant.
    The plant's notes say which it is."""
    from .compiled import CompiledPlant, supports  # the compiled plant builds on this module

    compiled, reason = library
    wanted = settings.kernel == Kernel.COMPILED and supports(settings)
    if wanted and compiled is not None:
        plant = CompiledPlant(scene, settings, compiled, t0)
        plant.notes.append(f"DOP853 on the {reason}")
        return plant
    plant = Plant(scene, settings, t0, stop_time, cache_dirs)
    if wanted:
        plant.notes.append(f"pure-Python DOP853: the compiled kernel is not available ({reason})")
    return plant


__all__ = ["Plant", "make_plant", "Kernel", "Settings", "check_step", "checked_settings", "Solver", "Outputs",
           "IntegrationError", "ParameterError"]
