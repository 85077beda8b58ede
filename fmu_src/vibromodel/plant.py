"""The plant as a co-simulation unit: a model of one fidelity, an integrator, and doStep.

The FMU slave maps FMI variables onto this class and nothing more; the harness can also drive it
directly (no FMI) to measure what the FMI layer costs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from . import forces
from .integrate import Dop853, IntegrationError, Rk4
from .models import Fidelity, make_model
from .parameters import ParameterError, Scene, validate, validate_max_step, validate_tolerance

RK4_DEFAULT_STEP = 0.01  # RK4 step when max_step = 0 ("automatic")
TIME_TOLERANCE = 1e-9  # relative mismatch allowed between the host's time and the plant's


class Solver(IntEnum):
    ADAPTIVE = 0
    RK4 = 1


@dataclass(frozen=True)
class Settings:
    fidelity: int = Fidelity.EXACT
    solver: int = Solver.ADAPTIVE
    rtol: float = 1e-8
    max_step: float = 0.0  # 0: automatic (no ceiling for the adaptive solver, 0.01 for RK4)

    def validate(self) -> None:
        if self.fidelity not in set(Fidelity):
            raise ParameterError("fidelity", self.fidelity, f"must be one of {[int(f) for f in Fidelity]}")
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
    """Scene + settings -> a steppable plant. Raises ParameterError for bad input."""

    def __init__(self, scene: Scene, settings: Settings, t0: float = 0.0):
        validate(scene)
        settings.validate()
        self.scene, self.settings = scene, settings
        self.model = make_model(scene, settings.fidelity)
        if settings.solver == Solver.ADAPTIVE:
            max_step = settings.max_step or math.inf
            self.integrator = Dop853(self.model.accel, self.model.events, t0, scene.x_start, scene.v_start,
                                     0.0, settings.rtol, max_step)
        else:
            self.integrator = Rk4(self.model.accel, self.model.events, t0, scene.x_start, scene.v_start,
                                  0.0, settings.max_step or RK4_DEFAULT_STEP)
        self.t = t0
        self.U = 0.0

    def do_step(self, t: float, h: float, U: float) -> Outputs:
        """Advance from the communication point t to t + h with input U held constant.

        Raises ParameterError for a bad step or input, IntegrationError (TerminalEvent for pull-in)
        when the model cannot be advanced.
        """
        if not (math.isfinite(h) and h > 0.0):
            raise ParameterError("communicationStepSize", h, "must be a finite number > 0")
        if not math.isfinite(U):
            raise ParameterError("U", U, "input must be a finite number")
        if not (math.isfinite(t) and abs(t - self.t) <= TIME_TOLERANCE * max(1.0, abs(t))):
            raise ParameterError("currentCommunicationPoint", t, f"the plant is at tau = {self.t!r}")
        self.integrator.set_input(self.t, U)
        self.U = U
        t_end = t + h  # the host's clock: no drift from summing steps
        self.integrator.advance(t_end)
        self.t = t_end
        return self.outputs()

    def outputs(self) -> Outputs:
        x, v = self.integrator.value_at(self.t)
        return self.outputs_at(self.t, x, v)

    def outputs_at(self, t: float, x: float, v: float) -> Outputs:
        f_contact, f_electrostatic = self.model.forces(t, x)
        return Outputs(x=x, v=v, a=self.model.accel(t, x, v, self.U), F_contact=f_contact,
                       F_electrostatic=f_electrostatic, in_contact=forces.contact_indentation(x) > 0.0)


__all__ = ["Plant", "Settings", "Solver", "Outputs", "IntegrationError", "ParameterError"]
