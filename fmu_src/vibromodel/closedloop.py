"""Plant + adaptive controller + reference as one co-simulation unit (the monolithic closed loop).

The state is (x, v, theta^): the plant model (fidelity 0, 1, 2 of models.py) with U = the control law, and the
nine estimates as extra first-order states of the plant's integrators (integrate.py, `rates`). The reference
is a closed form (tracking.py) evaluated at every stage.

A snapshot (FMU state) holds the loop's time and its integrator's complete numeric state: time, x, v, the
estimates' vector in the U slot and its rates, step size, stages and dense output, contact-event side,
counters. The reference is a function of time only: it is rebuilt with the model and the controller.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .control import ERRATA_INITIAL_ESTIMATES, Controller, Gains, Law, validate_estimates, validate_law
from .fidelities import closed_loop_refusal, entry, integrated
from .models import drive_step_ceiling
from .parameters import ParameterError, Scene, validate
from .plant import INTEGRATOR_REBUILT, Settings, checked_settings
from .settings import step_budget, time_refused, too_many_steps
from .snapshot import plain_attributes, restore_attributes
from .solvers import solver_entry
from .tracking import ReferenceSettings, make_reference

# docs/model.md, Adaptive controller simulation: the plant starts at x(0) = 0.06, x'(0) = 0.01, off the reference.
ERRATA_SCENE = Scene(x_start=0.06, v_start=0.01)
PLANT_FIDELITIES = integrated()  # the registry's levels that integrate Eq. 3 or 7 (0, 1, 2)
# What a snapshot leaves out: built by the constructor (_stage is a cache of the last stage's control U).
LOOP_REBUILT = ("scene", "settings", "loop", "model", "controller", "reference", "integrator", "_stage", "warnings")


@dataclass(frozen=True)
class LoopSettings:
    law: int = Law.PAPER_CORRECTED
    gains: Gains = field(default_factory=Gains)
    estimates: tuple[float, ...] = ERRATA_INITIAL_ESTIMATES
    reference: ReferenceSettings = field(default_factory=ReferenceSettings)

    def validate(self) -> None:
        validate_law(self.law)
        self.gains.validate()
        validate_estimates(self.estimates)
        self.reference.validate()


class ClosedLoop:
    """Scene + plant settings + loop settings -> a steppable closed loop. Raises ParameterError for bad input."""

    def __init__(self, scene: Scene, settings: Settings, loop: LoopSettings, t0: float = 0.0,
                 stop_time: float | None = None, cache_dirs: tuple = ()):
        validate(scene)
        if settings.fidelity not in PLANT_FIDELITIES:  # before checked_settings, which knows no fidelity auto (-1)
            raise ParameterError("fidelity", settings.fidelity, closed_loop_refusal())
        settings, self.warnings = checked_settings(scene, settings)  # rtol clamped; RK4 drive resolution
        loop.validate()
        self.scene, self.settings, self.loop = scene, settings, loop
        self.model = entry(settings.fidelity).model(scene)
        self.controller = Controller(scene, loop.gains, loop.law)
        self.reference, note = make_reference(scene, loop.reference, t0, stop_time, cache_dirs)
        self.notes = [note]
        self.t = t0
        self._stage = (None, None, None, None, None)  # (t, x, v, theta^, U) of the last rates() call
        theta0 = np.array(loop.estimates, dtype=float)
        # max_step = 0: the adaptive solver's ceiling from the scene's drive and the reference's fastest term
        self.drive_ceiling = drive_step_ceiling(scene, self.reference.fastest_frequency())
        self.integrator = solver_entry(settings.solver).make(self._accel, self.model.events, t0, scene.x_start,
                                                             scene.v_start, theta0, settings, rates=self._rates,
                                                             step_budget=step_budget(settings.kernel),
                                                             drive_ceiling=self.drive_ceiling)

    # The integrators call rates(t, x, v, theta^) and then accel(t, x, v, theta^) at each stage: the control
    # U computed for the first is reused by the second.
    def _rates(self, t, x, v, theta_hat):
        ref = self.reference.state(t)
        U = self.controller.control(t, x, v, ref, theta_hat)
        self._stage = (t, x, v, theta_hat, U)
        return self.controller.rates(t, x, v, ref)

    def _accel(self, t, x, v, theta_hat):
        st, sx, sv, s_theta, U = self._stage
        if not (t == st and x == sx and v == sv and theta_hat is s_theta):
            U = self.controller.control(t, x, v, self.reference.state(t), theta_hat)
        return self.model.accel(t, x, v, U)

    def do_step(self, t: float, h: float) -> dict:
        """Advance from the communication point t to t + h. Raises ParameterError for a bad step,
        IntegrationError (TerminalEvent for pull-in) when the loop cannot be advanced."""
        self.check_step(t, h)
        self.integrator.advance(t + h)
        self.t = t + h
        return self.outputs()

    def check_step(self, t: float, h: float) -> None:
        """ParameterError for a step the loop refuses (what the compiled loop's do_step checks too)."""
        if not (math.isfinite(h) and h > 0.0):
            raise ParameterError("communicationStepSize", h, "must be a finite number > 0")
        refusal = too_many_steps(h, self.integrator.max_step, self.settings.kernel)  # the plant's guard, same words
        if refusal is not None:
            raise ParameterError("communicationStepSize", h, refusal)
        if time_refused(self.t, t, h, self.integrator.max_step, self.settings.kernel):
            raise ParameterError("currentCommunicationPoint", t, f"the closed loop is at tau = {self.t!r}")

    def snapshot(self) -> dict:
        """Everything that decides the loop's future beyond its constructor's arguments, as plain data."""
        return {"loop": plain_attributes(self, LOOP_REBUILT),
                "integrator": plain_attributes(self.integrator, INTEGRATOR_REBUILT)}

    def restore(self, snapshot: dict) -> None:
        """Return a loop built with the same arguments to the moment `snapshot` was taken."""
        restore_attributes(self, snapshot["loop"], LOOP_REBUILT)
        restore_attributes(self.integrator, snapshot["integrator"], INTEGRATOR_REBUILT)

    def outputs(self) -> dict:
        x, v = self.integrator.value_at(self.t)
        return self.outputs_at(self.t, x, v, self.integrator.U_at(self.t))

    def outputs_at(self, t: float, x: float, v: float, theta_hat) -> dict:
        """x, v, x_ref, U, e1, e2, V, dV/dt (chain rule), the dV/dt the law promises, and the estimates."""
        c = self.controller
        ref = self.reference.state(t)
        U = c.control(t, x, v, ref, theta_hat)
        e1, e2 = c.errors(x, v, ref)
        rate = c.lyapunov_rate(x, v, self.model.accel(t, x, v, U), ref, theta_hat, c.rates(t, x, v, ref))
        return {"x": x, "v": v, "x_ref": ref[0], "U": U, "e1": e1, "e2": e2, "V": c.lyapunov(e1, e2, theta_hat),
                "V_rate": rate, "V_rate_promised": c.promised_rate(e1, e2), "estimates": tuple(map(float, theta_hat))}
