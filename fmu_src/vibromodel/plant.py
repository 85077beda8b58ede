"""The plant as a co-simulation unit: a model of one fidelity, an integrator, and doStep.

The FMU slave maps FMI variables onto this class and nothing more; the harness can also drive it
directly (no FMI) to measure what the FMI layer costs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

from . import forces
from .analytic import OafmSettings, cached_solve, covering
from .integrate import Dop853, IntegrationError, Rk4
from .models import Fidelity, make_model
from .parameters import ParameterError, Scene, validate, validate_max_step, validate_tolerance
from .snapshot import plain_attributes, restore_attributes

DEFAULT_EXPERIMENT = (0.0, 200.0, 0.1)  # start, stop, communication step of the FMU's DefaultExperiment
RK4_DEFAULT_STEP = 0.01  # RK4 step when max_step = 0 ("automatic")
TIME_TOLERANCE = 1e-9  # relative mismatch allowed between the host's time and the plant's
MAX_STEPS_PER_DOSTEP = 10**6  # more steps in one doStep: refused up front (step ceiling) or stopped
# What a snapshot leaves out: built from the scene and settings by the constructor.
PLANT_REBUILT = ("scene", "settings", "model", "integrator", "analytic")
INTEGRATOR_REBUILT = ("accel", "events")


class Solver(IntEnum):
    ADAPTIVE = 0
    RK4 = 1


@dataclass(frozen=True)
class Settings:
    fidelity: int = Fidelity.EXACT
    solver: int = Solver.ADAPTIVE
    rtol: float = 1e-8
    max_step: float = 0.0  # 0: automatic (no ceiling for the adaptive solver, 0.01 for RK4)
    oafm: OafmSettings = field(default_factory=OafmSettings)  # fidelity 4 only

    def validate(self) -> None:
        if self.fidelity not in set(Fidelity):
            raise ParameterError("fidelity", self.fidelity, f"must be one of {[int(f) for f in Fidelity]}")
        if self.fidelity == Fidelity.AVERAGED:
            raise ParameterError("fidelity", self.fidelity, "3 (averaged slow flow) is not available yet")
        if self.fidelity == Fidelity.ANALYTIC:
            self.oafm.validate()
        if self.solver not in set(Solver):
            raise ParameterError("solver", self.solver, "must be 0 (adaptive) or 1 (RK4)")
        validate_tolerance(self.rtol)
        if self.max_step != 0.0:
            validate_max_step(self.max_step)


@dataclass(frozen=True)
class Outputs:
    x: float
    v: float
    a: float
    F_contact: float
    F_electrostatic: float
    in_contact: bool


class Plant:
    """Scene + settings -> a steppable plant. Raises ParameterError for bad input.

    Fidelity 4 has no integrator: the OAFM solution is fitted here (or read from a cache in
    cache_dirs or the user cache) to cover [t0, stop_time], and doStep evaluates closed forms.
    `notes` says what initialisation did, for the FMU's log.
    """

    def __init__(self, scene: Scene, settings: Settings, t0: float = 0.0, stop_time: float | None = None,
                 cache_dirs: tuple = ()):
        validate(scene)
        settings.validate()
        self.scene, self.settings = scene, settings
        self.model = make_model(scene, settings.fidelity)
        self.t = t0
        self.U = 0.0
        self.notes: list[str] = []
        self.integrator = self.analytic = None
        if settings.fidelity == Fidelity.ANALYTIC:
            span = None if stop_time is None else stop_time - t0
            oafm = covering(scene, settings.oafm, span)
            self.analytic, source = cached_solve(scene, oafm, t0, read_dirs=cache_dirs)
            self.notes.append(f"OAFM {oafm.basis} basis, tau* = {self.analytic.pieces[1].start:.6g}, fit to "
                              f"tau = {self.analytic.tau_end:.6g} ({source})")
            if stop_time is None:
                self.notes.append(f"no stop time given: beyond tau = {self.analytic.tau_end:.6g} the analytic "
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
        if not (math.isfinite(h) and h > 0.0):
            raise ParameterError("communicationStepSize", h, "must be a finite number > 0")
        if not math.isfinite(U):
            raise ParameterError("U", U, "input must be a finite number")
        ceiling = math.inf if self.integrator is None else self.integrator.max_step
        if h / ceiling > MAX_STEPS_PER_DOSTEP:
            raise ParameterError("communicationStepSize", h, f"needs more than {MAX_STEPS_PER_DOSTEP} steps of "
                                 f"{ceiling:g} (max_step); make smaller communication steps or raise max_step")
        if not (math.isfinite(t) and abs(t - self.t) <= TIME_TOLERANCE * max(1.0, abs(t))):
            raise ParameterError("currentCommunicationPoint", t, f"the plant is at tau = {self.t!r}")
        t_end = t + h  # the host's clock: no drift from summing steps
        if self.analytic is not None:
            if U != 0.0:
                raise ParameterError("U", U, "fidelity 4 (OAFM analytic) is open loop: the input must be 0")
        else:
            self.integrator.set_input(self.t, U)
            self.U = U
            self.integrator.advance(t_end)
        self.t = t_end
        return self.outputs()

    def snapshot(self) -> dict:
        """Everything that decides the plant's future beyond its constructor's arguments, as plain data."""
        integrator = None if self.integrator is None else plain_attributes(self.integrator, INTEGRATOR_REBUILT)
        return {"plant": plain_attributes(self, PLANT_REBUILT), "integrator": integrator}

    def restore(self, snapshot: dict) -> None:
        """Return a plant built with the same arguments to the moment `snapshot` was taken.

        Fidelity 4's analytic solution is not in the snapshot: the constructor re-derives it
        deterministically from the scene and settings (or reads the same fit from a cache).
        """
        restore_attributes(self, snapshot["plant"], PLANT_REBUILT)
        if self.integrator is not None:
            restore_attributes(self.integrator, snapshot["integrator"], INTEGRATOR_REBUILT)

    def outputs(self) -> Outputs:
        if self.analytic is not None:
            return self.outputs_at(self.t, *self.analytic.state(self.t))
        x, v = self.integrator.value_at(self.t)
        return self.outputs_at(self.t, x, v)

    def outputs_at(self, t: float, x: float, v: float, a: float | None = None) -> Outputs:
        """Outputs at a state; a = x'' of the model unless given (the analytic solution's own x~'')."""
        f_contact, f_electrostatic = self.model.forces(t, x)
        if a is None:
            a = self.model.accel(t, x, v, self.U)
        return Outputs(x=x, v=v, a=a, F_contact=f_contact,
                       F_electrostatic=f_electrostatic, in_contact=forces.contact_indentation(x) > 0.0)


__all__ = ["Plant", "Settings", "Solver", "Outputs", "IntegrationError", "ParameterError"]
