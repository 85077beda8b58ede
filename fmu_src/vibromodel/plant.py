"""The plant as a co-simulation unit: a model of one fidelity, an integrator, and doStep.

The FMU slave maps FMI variables onto this class and nothing more; the harness can also drive it
directly (no FMI) to measure what the FMI layer costs.
"""
from __future__ import annotations

import math
from dataclasses import replace

from . import error_estimates, forces
from .compiled import CompiledPlant, supports
from .compiled_open_loop import CompiledOpenLoopPlant
from .fidelities import entry
from .integrate import IntegrationError
from .models import drive_step_ceiling, solver_tolerance
from .parameters import ParameterError, Scene, validate
from .settings import (DEFAULT_EXPERIMENT, MAX_STEPS_PER_DOSTEP, RK4_DEFAULT_STEP, TIME_TOLERANCE, Kernel, Outputs,
                       Settings, Solver, check_step, checked_settings, rk4_drive_warnings, step_budget)
from .snapshot import plain_attributes, restore_attributes
from .solvers import solver_entry

# What a snapshot leaves out: built from the scene and settings by the constructor.
PLANT_REBUILT = ("scene", "settings", "model", "integrator", "solution", "warnings")
INTEGRATOR_REBUILT = ("accel", "events", "rates", "phased")
SLOW_FLOW_REBUILT = ("flow", "kernel", "_array", "averaged")  # fidelity 3: its table and integration end are plain data


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
        level = entry(settings.fidelity)
        self.model = level.model(scene)
        self.t = t0
        self.U = 0.0
        self.notes: list[str] = []
        self.integrator = self.solution = None
        if level.open_loop is not None:
            self.solution, notes = level.open_loop(scene, settings, t0, stop_time, cache_dirs)
            self.notes += notes
            self.warnings += getattr(self.solution, "warnings", [])  # the rung's doubts about its own domain
        else:  # the solver of the settings (solvers.SOLVERS), at the rtol of a long, lightly damped run
            rtol, notes = solver_tolerance(scene, settings, t0, stop_time)
            self.notes += notes
            self.integrator = solver_entry(settings.solver).make(
                self.model.accel, self.model.events, t0, scene.x_start, scene.v_start, 0.0, replace(settings, rtol=rtol),
                phased=(self.model.drive_frequencies, self.model.accel_phased), step_budget=step_budget(settings.kernel),
                drive_ceiling=drive_step_ceiling(scene))

    def do_step(self, t: float, h: float, U: float) -> Outputs:
        """Advance from the communication point t to t + h with input U held constant.

        Raises ParameterError for a bad step or input, IntegrationError (TerminalEvent for pull-in)
        when the model cannot be advanced.
        """
        check_step(self.t, t, h, U, math.inf if self.integrator is None else self.integrator.max_step,
                   None if self.solution is None else self.settings.fidelity, self.settings.kernel)
        x, v, a = self.advance(t + h, U)  # t + h: the host's clock, no drift from sums
        return self.outputs_at(self.t, x, v, a)  # every output at the new communication point t + h

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
            vars(self.solution).pop("_array", None)  # the fresh table's array, not the restored table's

    def _slow_flow(self) -> bool:
        return entry(self.settings.fidelity).solution_in_snapshot

    def outputs(self) -> Outputs:
        return self.outputs_at(self.t, *self.state())

    def outputs_at(self, t: float, x: float, v: float, a: float | None = None) -> Outputs:
        """Outputs at a state; a = x'' of the model unless given."""
        f_contact, f_electrostatic = self.model.forces(t, x)
        if a is None:
            a = self.model.accel(t, x, v, self.U)
        return Outputs(x=x, v=v, a=a, F_contact=f_contact,
                       F_electrostatic=f_electrostatic, in_contact=forces.in_contact(x, v, a))


def make_plant(scene: Scene, settings: Settings, t0: float = 0.0, stop_time: float | None = None,
               cache_dirs: tuple = (), library: tuple = (None, "no library given")):
    """The plant of `settings`: on the compiled kernel (vibromodel.compiled.CompiledPlant) where it applies,
    settings.kernel asks for it and library = (vibromodel.compiled.load_library's result) holds one; else Plant.
    The plant's notes say which it is. Its `error_estimate` (error_estimates.attach) estimates max|x - x_exact| over
    [t0, stop_time]; a rung whose estimate exceeds its share of the amplitude adds its warning."""
    plant = _make_plant(scene, settings, t0, stop_time, cache_dirs, library)
    error_estimates.attach(plant, entry(settings.fidelity), t0, stop_time)
    return plant


def _make_plant(scene: Scene, settings: Settings, t0: float = 0.0, stop_time: float | None = None,
               cache_dirs: tuple = (), library: tuple = (None, "no library given")):
    """make_plant without the error estimate."""
    compiled, reason = library
    if settings.kernel == Kernel.COMPILED and entry(settings.fidelity).open_loop is not None:
        plant = Plant(scene, settings, t0, stop_time, cache_dirs)  # the set-up (table, fit) stays in Python
        if compiled is None:
            plant.notes.append(f"pure-Python evaluation: the compiled kernel is not available ({reason})")
            return plant
        wrapped, why = CompiledOpenLoopPlant.make(plant, compiled)
        plant.notes.append(f"per-output evaluation on the {why}" if wrapped is not None else
                           f"pure-Python evaluation: {why}")
        return wrapped if wrapped is not None else plant
    wanted = settings.kernel == Kernel.COMPILED and supports(settings)
    if wanted and compiled is not None:
        plant = CompiledPlant(scene, settings, compiled, t0, stop_time)
        plant.notes.append(f"{solver_entry(settings.solver).name} on the {reason}")
        return plant
    plant = Plant(scene, settings, t0, stop_time, cache_dirs)
    if wanted:
        plant.notes.append(f"pure-Python {solver_entry(settings.solver).name}: the compiled kernel is not available "
                           f"({reason})")
    return plant


__all__ = ["Plant", "make_plant", "Kernel", "Settings", "check_step", "checked_settings", "Solver", "Outputs",
           "IntegrationError", "ParameterError", "DEFAULT_EXPERIMENT", "MAX_STEPS_PER_DOSTEP", "RK4_DEFAULT_STEP",
           "TIME_TOLERANCE", "rk4_drive_warnings"]
