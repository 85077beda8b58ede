"""The plant from Python at the compiled kernel's speed, without FMI: `simulate` runs one scene, `simulate_many` many,
and both return numpy arrays of the plant FMU's outputs (time, x, v, a, F_contact, F_electrostatic, in_contact).

They run the kernel the plant FMU runs (fmu_src/core, compiled once per source version by vibrofmu.fmus.kernel) on
the same settings, and check the scene and settings with the same rules and messages (vibromodel.parameters: a
ParameterError naming the parameter and its value). A run takes the host's grid: the doStep from point k is at
t = start_time + k * interval, as a host computes it, so the outputs are the bits of the plant FMU's (and of
vibromodel.compiled.CompiledPlant's) under such a host. A run that stops early (pull-in, a failed step) keeps the
points before the stop and says why (`Run.stopped`, `Run.error`), as the FMU's log would.

`simulate_many` checks the scenes as columns with numpy (one comparison per rule for all scenes; a scene that breaks
a rule is then checked alone, so its error is the one `simulate` raises), fills the kernel's state structures as
one numpy array and runs every scene in one C call: its cost per scene beyond the kernel's own work is a few
microseconds. `Simulation` keeps one plant to advance in pieces (the studies' core engine settles with it).
"""
from __future__ import annotations

import ctypes
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from vibromodel import compiled
from vibromodel.compiled import take_pending
from vibromodel.core_layouts import VkPlant
from vibromodel.fidelities import CModel, entry
from vibromodel.integrate import ATOL_PER_RTOL
from vibromodel.models import DRIVE_STEP_TURN, ERROR_MEMORY_REFERENCE, TOLERANCE_FACTOR_FLOOR, solver_tolerance
from vibromodel.parameters import (MIN_RTOL, PULL_IN_GAP, RULES, ParameterError, Scene, model_parameter_names,
                                   scene_names, validate)
from vibromodel.settings import (MAX_STEPS_PER_DOSTEP, RK4_DEFAULT_STEP, TIME_TOLERANCE, Kernel, Settings,
                                 check_step, checked_settings, rk4_drive_warnings)
from vibromodel.solvers import solver_entry

from vibrofmu.fmus.kernel import kernel_library

OUTPUTS = ("time", "x", "v", "a", "F_contact", "F_electrostatic", "in_contact")
STATE = OUTPUTS[:3]  # what a run computes when asked for no more (outputs=STATE): the steps without x'' and forces
CHUNK = 64  # scenes per C call in simulate_many: their state structures (6 kB each) stay in the caches

_double_p, _int_p = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int64)
PLANT_DTYPE = np.dtype(VkPlant)


# The scene's parameters of the equation: the core's VkModel fields of the same names (models.scene_fields)
MODEL_PARAMETERS = tuple(model_parameter_names())


@functools.cache
def default_library():
    """The compiled kernel (built on first use; vibrofmu.fmus.kernel.kernel_library), once per process."""
    return kernel_library()


@dataclass
class _Outputs:
    """The plant's outputs over time (Run: one scene's, Batch: many scenes')."""

    time: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    F_contact: np.ndarray
    F_electrostatic: np.ndarray


@dataclass
class Run(_Outputs):
    """One scene's outputs at start_time and after each interval: arrays of one length (the points reached)."""

    in_contact: np.ndarray | None  # bool; None (and a, F_contact, F_electrostatic): not asked for (outputs)
    stopped: str = ""  # why the run stopped before stop_time ("" if it did not): the FMU's log line
    error: BaseException | None = None  # what CompiledPlant raises there (TerminalEvent at pull-in, ...)
    warnings: list[str] = field(default_factory=list)  # what the FMU logs as warnings (settings)
    notes: list[str] = field(default_factory=list)  # what the FMU logs at initialisation (the tolerance factor)


@dataclass
class Batch(_Outputs):
    """Many scenes' outputs: arrays of shape (scenes, points); after a scene's stop its rows hold NaN."""

    in_contact: np.ndarray | None  # float: 1.0, 0.0, NaN after a stop; None (and a, F_*): not asked for
    n_points: np.ndarray  # points reached per scene
    stopped: list[str]
    errors: list[BaseException | None]
    warnings: list[list[str]]
    notes: list[list[str]]

    def __len__(self) -> int:
        return len(self.n_points)

    def run(self, i: int) -> Run:
        """Scene i as a Run."""
        n = int(self.n_points[i])
        values = {name: None if getattr(self, name) is None else getattr(self, name)[i, :n] for name in OUTPUTS}
        if values["in_contact"] is not None:
            values["in_contact"] = values["in_contact"] != 0.0
        return Run(**values, stopped=self.stopped[i], error=self.errors[i], warnings=self.warnings[i],
                   notes=self.notes[i])


def _steps(start_time: float, stop_time: float, interval: float) -> int:
    """The number of intervals from start_time to stop_time (a whole number, at least 1)."""
    for name, value in (("start_time", start_time), ("stop_time", stop_time)):
        if not math.isfinite(value):
            raise ParameterError(name, value, "must be a finite number")
    if not (math.isfinite(interval) and interval > 0.0):
        raise ParameterError("interval", interval, "must be a finite number > 0")  # plant.check_step's rule
    span = (stop_time - start_time) / interval
    n = round(span)
    if n < 1 or abs(span - n) > 1e-9 * max(1.0, span):
        raise ParameterError("stop_time", stop_time, f"must be start_time = {start_time!r} plus a whole number (>= 1) "
                             f"of intervals of {interval!r}")
    return n


@functools.lru_cache(maxsize=64)
def _settings(settings: Settings) -> tuple[Settings, tuple[str, ...]]:
    """The settings checked as CompiledPlant checks them (on the paper scene: the scenes' own rules come later);
    kept per settings value (a frozen dataclass): a run's check of its settings costs a look-up."""
    if settings.kernel != Kernel.COMPILED:
        raise ParameterError("kernel", settings.kernel, "vibrofmu.api runs the compiled kernel (0) only")
    checked, warnings = checked_settings(Scene(), settings)  # validate(), rtol clamped; RK4 warnings are per scene
    if not compiled.supports(checked):
        raise ParameterError("fidelity", settings.fidelity, "vibrofmu.api runs the integrated fidelities with a "
                             "compiled model (0, 1, 2)")
    return checked, tuple(w for w in warnings if w.startswith("parameter rtol"))


def scene_columns(scenes) -> dict[str, np.ndarray]:
    """The scenes as one float array per Scene field: a list of Scene, or a dict of arrays (and scalars) over the
    paper scene's values (each named field must be a Scene field)."""
    names = scene_names()
    if isinstance(scenes, dict):
        unknown = sorted(set(scenes) - set(names))
        if unknown:
            raise ParameterError(unknown[0], scenes[unknown[0]], f"unknown parameter; known: {', '.join(names)}")
        arrays = {name: np.atleast_1d(np.asarray(value, dtype=float)) for name, value in scenes.items()}
        m = max((len(a) for a in arrays.values()), default=1)
        base = Scene()
        return {name: np.broadcast_to(arrays.get(name, getattr(base, name)), (m,)).astype(float, copy=False)
                for name in names}
    scenes = list(scenes)
    return {name: np.fromiter((getattr(s, name) for s in scenes), float, len(scenes)) for name in names}


def _scene(columns: dict, i: int) -> Scene:
    return Scene(**{name: float(column[i]) for name, column in columns.items()})


@functools.lru_cache(maxsize=8)
def _rule_table(fidelity: int) -> tuple[np.ndarray, ...]:
    """The scene rules of parameters.RULES that apply at this fidelity as columns: the row of each rule's field in
    scene_names(), its low and high ends, whether each is inclusive, its automatic value (NaN: none)."""
    names = scene_names()
    rules = [r for r in RULES if r.name in names and r.applies({"fidelity": fidelity})]
    column = np.array  # each a column vector, compared with a (rules, scenes) matrix
    return (np.array([names.index(r.name) for r in rules]), column([[r.low] for r in rules]),
            column([[r.high] for r in rules]), column([[r.low_inclusive] for r in rules]),
            column([[r.high_inclusive] for r in rules]),
            column([[math.nan if r.automatic is None else r.automatic] for r in rules]))


def scenes_broken(columns: dict, fidelity: int) -> np.ndarray:
    """Mask of the scenes that break a rule of parameters.RULES (at this fidelity) or the electrodes' rule of
    validate(): Rule.refusal's test in numpy, every rule and scene at once."""
    rows, low, high, low_inclusive, high_inclusive, automatic = _rule_table(fidelity)
    values = np.stack([columns[name] for name in scene_names()])[rows]  # (rules, scenes)
    with np.errstate(all="ignore"):
        ok = np.isfinite(values) & np.where(low_inclusive, values >= low, values > low)
        ok &= np.where(high_inclusive, values <= high, values < high)
        ok |= values == automatic
        u = 2.0 * columns["x_start"] / (3.0 * columns["R"])  # parameters.electrode_gaps
        return ~ok.all(axis=0) | ~((1.0 - u > PULL_IN_GAP) & (1.0 + u > PULL_IN_GAP))


def _check(columns: dict, settings: Settings) -> None:
    """Raise the ParameterError of the first scene that breaks a rule (with a note naming the scene)."""
    bad = np.flatnonzero(scenes_broken(columns, int(settings.fidelity)))
    if len(bad):
        i = int(bad[0])
        scene = _scene(columns, i)
        try:
            validate(scene)
            checked_settings(scene, settings)
        except ParameterError as error:
            if len(columns["mu"]) > 1:
                error.add_note(f"in scene {i}")
            raise
        raise RuntimeError(f"scene {i} breaks a rule in vibrofmu.api's check but not in validate (a bug): {scene}")


def fill_plants(plants: np.ndarray, columns: dict, settings: Settings, start_time: float,
          stop_time: float) -> tuple[np.ndarray, list, list]:
    """`plants` (one kernel state structure per scene of `columns`) filled as CompiledPlant fills its plant (before
    vk_init); the scenes' warnings and notes."""
    m = len(columns["mu"])
    level = entry(settings.fidelity)
    plants.view(np.uint8).reshape(m, PLANT_DTYPE.itemsize)[:] = _template(settings, start_time)
    model = plants["model"]
    if level.c_model == CModel.EXACT:  # models.scene_fields and ExactModel.compiled_fields, for all scenes at once
        for name in MODEL_PARAMETERS:
            model[name] = columns[name]
        ac = (columns["beta"] != 0.0) | (columns["gamma"] != 0.0)
        model["pull_in_c"] = 2.0 / (3.0 * columns["R"])  # models.pull_in_slope
        model["load_forcing"] = columns["Delta"] != 0.0
        model["ac"] = ac
        model["electrostatics"] = (columns["alpha"] != 0.0) | ac
    else:  # Eq. 7's coefficients: the level's model object fills each scene's, as in CompiledPlant
        for i in range(m):
            scene = _scene(columns, i)
            compiled.fill_model(VkPlant.from_buffer(plants, i * PLANT_DTYPE.itemsize).model, level.model(scene))
    delta, beta, gamma, omega, Omega = (columns[n] for n in ("Delta", "beta", "gamma", "omega", "Omega"))
    # the solver's tolerance (models.solver_tolerance) and the drive's step ceiling (models.drive_step_ceiling)
    mu, span = columns["mu"], stop_time - start_time
    with np.errstate(divide="ignore"):
        memory = np.where(mu > 0.0, 2.0 / mu, math.inf)
        if span > 0.0:
            memory = np.where(span < memory, span, memory)
        factor = np.clip(ERROR_MEMORY_REFERENCE / memory, TOLERANCE_FACTOR_FLOOR, 1.0)
        rtol = np.where(factor == 1.0, settings.rtol, np.maximum(MIN_RTOL, settings.rtol * factor))
        fastest = np.maximum.reduce([np.where(delta != 0.0, omega, 0.0), np.where(beta != 0.0, Omega, 0.0),
                                     np.where(gamma != 0.0, 2.0 * Omega, 0.0)])
        ceiling = np.where(fastest > 0.0, DRIVE_STEP_TURN / fastest, math.inf)
    dop, rk4 = plants["dop"], plants["rk4"]
    dop["rtol"], dop["atol"] = rtol, rtol * ATOL_PER_RTOL
    dop["max_step"] = settings.max_step or ceiling
    notes: list[list[str]] = [[] for _ in range(m)]
    for i in np.flatnonzero(factor < 1.0):  # the note's text, scene by scene (few scenes are that lightly damped)
        notes[i] = solver_tolerance(_scene(columns, i), settings, start_time, stop_time)[1]
    warnings: list[list[str]] = [[] for _ in range(m)]
    solver = solver_entry(settings.solver)
    if solver.drive_gains is not None:
        step = solver.step(settings.max_step)
        for i in range(m):
            warnings[i] = rk4_drive_warnings(_scene(columns, i), step)
    ceilings = np.where(plants["solver"] == 0, dop["max_step"], rk4["max_step"])  # the solver's (plant.check_step)
    return ceilings, warnings, notes


@functools.lru_cache(maxsize=8)
def _rule_rows(fidelity: int) -> tuple[tuple, ...]:
    """_rule_table's rules as rows of Python values (name, low, high, low inclusive, high inclusive, automatic)."""
    names = scene_names()
    rows, low, high, low_inclusive, high_inclusive, automatic = _rule_table(fidelity)
    return tuple((names[int(r)], float(lo[0]), float(hi[0]), bool(li[0]), bool(hin[0]), float(au[0]))
                 for r, lo, hi, li, hin, au in zip(rows, low, high, low_inclusive, high_inclusive, automatic))


def scene_broken(scene: Scene, fidelity: int) -> bool:
    """scenes_broken for one scene in Python floats (the same comparisons: a run of one scene skips numpy's per-call
    cost)."""
    for name, low, high, low_inclusive, high_inclusive, automatic in _rule_rows(fidelity):
        value = getattr(scene, name)
        ok = math.isfinite(value) and (value >= low if low_inclusive else value > low) and (
            value <= high if high_inclusive else value < high)
        if not (ok or value == automatic):
            return True
    u = 2.0 * scene.x_start / (3.0 * scene.R)  # parameters.electrode_gaps (R > 0: its rule holds here)
    return not (1.0 - u > PULL_IN_GAP and 1.0 + u > PULL_IN_GAP)


def fill_one(scene: Scene, settings: Settings, start_time: float,
             stop_time: float) -> tuple[VkPlant, float, list[str], list[str]]:
    """fill_plants for one scene of the exact model (c_model EXACT) in Python floats, the same operations on the
    same values (tests/harness/test_api.py compares the bytes): (its kernel structure, a new ctypes VkPlant; its
    step ceiling, warnings, notes)."""
    plant = VkPlant.from_buffer_copy(_template(settings, start_time))
    model = plant.model
    for name in MODEL_PARAMETERS:
        setattr(model, name, getattr(scene, name))
    ac = scene.beta != 0.0 or scene.gamma != 0.0
    model.pull_in_c = 2.0 / (3.0 * scene.R)
    model.load_forcing, model.ac = scene.Delta != 0.0, ac
    model.electrostatics = scene.alpha != 0.0 or ac
    memory, span = 2.0 / scene.mu if scene.mu > 0.0 else math.inf, stop_time - start_time
    if span > 0.0 and span < memory:
        memory = span
    factor = min(max(ERROR_MEMORY_REFERENCE / memory, TOLERANCE_FACTOR_FLOOR), 1.0)
    rtol = settings.rtol if factor == 1.0 else max(MIN_RTOL, settings.rtol * factor)
    fastest = max(scene.omega if scene.Delta != 0.0 else 0.0, scene.Omega if scene.beta != 0.0 else 0.0,
                  2.0 * scene.Omega if scene.gamma != 0.0 else 0.0)
    plant.dop.rtol, plant.dop.atol = rtol, rtol * ATOL_PER_RTOL
    plant.dop.max_step = settings.max_step or (DRIVE_STEP_TURN / fastest if fastest > 0.0 else math.inf)
    notes = solver_tolerance(scene, settings, start_time, stop_time)[1] if factor < 1.0 else []
    solver = solver_entry(settings.solver)
    warnings = rk4_drive_warnings(scene, solver.step(settings.max_step)) if solver.drive_gains is not None else []
    return plant, (plant.dop.max_step if plant.solver == 0 else plant.rk4.max_step), warnings, notes


@functools.lru_cache(maxsize=64)
def _template(settings: Settings, start_time: float) -> np.ndarray:
    """The bytes of a kernel state structure with what the settings fix, as CompiledPlant sets it (the rest 0): each
    scene's structure starts as a copy."""
    plant = np.zeros(1, dtype=PLANT_DTYPE)
    plant["model"]["pull_in_gap"] = PULL_IN_GAP
    plant["model"]["polynomial"] = 0  # Eq. 7's scenes: compiled.fill_model sets 1
    plant["dop"]["step_budget"] = MAX_STEPS_PER_DOSTEP
    plant["rk4"]["max_step"] = settings.max_step or RK4_DEFAULT_STEP
    plant["solver"] = int(settings.solver)
    plant["time_tolerance"], plant["max_steps_per_dostep"] = TIME_TOLERANCE, MAX_STEPS_PER_DOSTEP
    plant["plant_t"], plant["U_input"], plant["enabled"] = start_time, 0.0, 1
    return plant.view(np.uint8).copy()


def _check_interval(ceilings: np.ndarray, interval: float, first: int, many: bool) -> None:
    """plant.check_step's rule of too many steps per doStep, for every scene (ceilings: their step ceilings)."""
    bad = np.flatnonzero(interval / ceilings > MAX_STEPS_PER_DOSTEP)
    if len(bad):
        i = int(bad[0])
        try:
            check_step(0.0, 0.0, interval, 0.0, float(ceilings[i]))
        except ParameterError as error:
            if many:
                error.add_note(f"in scene {first + i}")
            raise


def _stop(plant: VkPlant, code: int, t: float, interval: float) -> tuple[str, BaseException | None]:
    """(the log line, the exception) of a scene that stopped with `code`."""
    error = take_pending(plant)
    if error is None and code != compiled.VK_OK:  # a pre-check refused the step (nothing pending)
        try:
            check_step(plant.plant_t, t, interval, plant.U_input, _ceiling(plant))
        except ParameterError as refused:
            error = refused
        else:
            error = RuntimeError(f"vibrokernel refused the step with code {code} (a kernel bug)")
    if error is None:
        return "", None
    return f"{type(error).__name__}: {error}", error


def _ceiling(plant: VkPlant) -> float:
    slot = compiled.SOLVER_SLOTS[solver_entry(plant.solver).family]
    return getattr(plant, slot).max_step


def simulate_many(scenes, stop_time: float = 200.0, interval: float = 0.1, settings: Settings = Settings(),
                  start_time: float = 0.0, outputs=OUTPUTS) -> Batch:
    """Run every scene from start_time to stop_time on the compiled kernel, outputs every `interval`.

    scenes: a list of Scene, or a dict of arrays (and scalars) of Scene fields over the paper scene's values (the
    fast form: {"omega": np.linspace(0.9, 1.1, 1000)}). Raises ParameterError for the first scene that breaks a
    parameter rule (as `simulate` would, with a note naming the scene) or bad settings, stop time or interval.
    A scene that stops early (pull-in, a failed step) does not stop the others: see Batch.stopped.
    outputs: the outputs wanted; asked for no more than STATE (time, x, v), a run skips the model's x'' and forces
    at each point (the same x and v, cheaper), and a, F_contact, F_electrostatic, in_contact are None."""
    n = _steps(start_time, stop_time, interval)
    settings, clamp = _settings(settings)
    columns = scene_columns(scenes)
    _check(columns, settings)
    m = len(columns["mu"])
    unknown = sorted(set(outputs) - set(OUTPUTS))
    if unknown:
        raise ParameterError("outputs", unknown[0], f"unknown output; known: {', '.join(OUTPUTS)}")
    every = not set(outputs) <= set(STATE)  # else the lean steps (core/plant.c vk_run_xv)
    out = np.full((len(OUTPUTS) if every else len(STATE), m, n + 1), np.nan)
    n_done, codes = np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.int64)
    warnings, notes, stopped, errors = [], [], [""] * m, [None] * m
    plants = np.zeros(min(m, CHUNK), dtype=PLANT_DTYPE)  # reused for every chunk of scenes
    run_batch = default_library().vk_run_batch
    for first in range(0, m, CHUNK):
        last = min(first + CHUNK, m)
        chunk = {name: np.ascontiguousarray(column[first:last]) for name, column in columns.items()}
        part = plants[:last - first]
        ceilings, chunk_warnings, chunk_notes = fill_plants(part, chunk, settings, start_time, stop_time)
        _check_interval(ceilings, interval, first, m > 1)
        warnings += [list(clamp) + w for w in chunk_warnings]
        notes += chunk_notes
        run_batch(part.ctypes.data, last - first, start_time, chunk["x_start"].ctypes.data_as(_double_p),
                  chunk["v_start"].ctypes.data_as(_double_p), interval, n,
                  out[0, first:].ctypes.data_as(_double_p), m * (n + 1), n_done[first:].ctypes.data_as(_int_p),
                  codes[first:].ctypes.data_as(_int_p), int(every))
        for i in np.flatnonzero(n_done[first:last] < n + 1):
            plant = VkPlant.from_buffer(part, int(i) * PLANT_DTYPE.itemsize)
            k = max(int(n_done[first + i]) - 1, 0)
            stopped[first + i], errors[first + i] = _stop(plant, int(codes[first + i]), start_time + k * interval,
                                                          interval)
    columns_out = list(out) + [None] * (len(OUTPUTS) - len(out))
    return Batch(*columns_out, n_points=n_done, stopped=stopped, errors=errors, warnings=warnings, notes=notes)


def simulate(scene: Scene | None = None, stop_time: float = 200.0, interval: float = 0.1,
             settings: Settings = Settings(), start_time: float = 0.0, outputs=OUTPUTS) -> Run:
    """Run `scene` (default: the paper's) from start_time to stop_time on the compiled kernel, outputs every
    `interval` (the plant FMU's outputs, and its bits under a host that steps from start_time + k * interval).
    Raises ParameterError (naming the parameter and value, as the FMU logs it) for a bad scene, settings, stop time
    or interval; a run that stops early keeps the points before the stop and says why (Run.stopped). outputs: as
    simulate_many's."""
    scene = Scene() if scene is None else scene
    n = _steps(start_time, stop_time, interval)
    checked, clamp = _settings(settings)
    if (not isinstance(scene, Scene) or entry(checked.fidelity).c_model != CModel.EXACT
            or scene_broken(scene, int(checked.fidelity)) or not set(outputs) <= set(OUTPUTS)):
        # simulate_many's columns (and its errors, in its order)
        return simulate_many([scene], stop_time, interval, settings, start_time, outputs).run(0)
    # one scene of the exact model: simulate_many's steps in Python floats and ctypes scalars (its numpy arrays and
    # their ctypes pointers cost more than the run itself for a short scene)
    plant, ceiling, warnings, notes = fill_one(scene, checked, start_time, stop_time)
    if interval / ceiling > MAX_STEPS_PER_DOSTEP:
        _check_interval(np.array([ceiling]), interval, 0, False)
    every = not set(outputs) <= set(STATE)
    out = np.empty((len(OUTPUTS) if every else len(STATE), n + 1))  # only the points reached are returned
    n_done, code = ctypes.c_int64(), ctypes.c_int64()
    default_library().vk_run_batch(ctypes.addressof(plant), 1, start_time, ctypes.byref(ctypes.c_double(scene.x_start)),
                                   ctypes.byref(ctypes.c_double(scene.v_start)), interval, n,
                                   (ctypes.c_double * out.size).from_buffer(out), n + 1, ctypes.byref(n_done),
                                   ctypes.byref(code), int(every))
    done, stopped, error = n_done.value, "", None
    if done < n + 1:
        k = max(done - 1, 0)
        stopped, error = _stop(plant, code.value, start_time + k * interval, interval)
    values = {name: out[j, :done] if j < len(out) else None for j, name in enumerate(OUTPUTS)}
    if values["in_contact"] is not None:
        values["in_contact"] = values["in_contact"] != 0.0
    return Run(**values, stopped=stopped, error=error, warnings=list(clamp) + warnings, notes=notes)


class Simulation:
    """One scene's plant on the compiled kernel, advanced in pieces: advance(n) runs n intervals and returns their
    outputs (a Run of n points or fewer); the host's grid continues across pieces (t = start_time + k interval)."""

    def __init__(self, scene: Scene | None = None, interval: float = 0.1, settings: Settings = Settings(),
                 start_time: float = 0.0, stop_time: float | None = None, library=None):
        """library: a loaded kernel (vibromodel.compiled.load_library; default: the one of this source tree)."""
        _steps(start_time, start_time + interval, interval)  # the interval's own checks
        settings, clamp = _settings(settings)
        columns = scene_columns([Scene() if scene is None else scene])
        _check(columns, settings)
        self._plants = np.zeros(1, dtype=PLANT_DTYPE)
        ceilings, warnings, notes = fill_plants(self._plants, columns, settings, start_time,
                                          math.nan if stop_time is None else stop_time)
        _check_interval(ceilings, interval, 0, False)
        self.warnings, self.notes = list(clamp) + warnings[0], notes[0]
        self.start_time, self.interval, self.k = start_time, interval, 0
        self._plant = VkPlant.from_buffer(self._plants)
        self._address = ctypes.addressof(self._plant)
        self._library = library or default_library()
        out, n_done, codes = np.zeros((len(OUTPUTS), 1)), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)
        self._library.vk_run_batch(self._address, 1, start_time, columns["x_start"].ctypes.data_as(_double_p),
                                   columns["v_start"].ctypes.data_as(_double_p), interval, 0,
                                   out.ctypes.data_as(_double_p), 1, n_done.ctypes.data_as(_int_p),
                                   codes.ctypes.data_as(_int_p), 1)
        self.stopped, self.error = "", None
        self.start = self._run(out, int(n_done[0]), int(codes[0]))

    def _run(self, out: np.ndarray, n: int, code: int) -> Run:
        values = {name: out[j, :n] for j, name in enumerate(OUTPUTS)}
        values["in_contact"] = values["in_contact"] != 0.0
        if not self.stopped:
            self.stopped, self.error = _stop(self._plant, code, self.start_time + self.k * self.interval,
                                             self.interval)
        return Run(**values, stopped=self.stopped, error=self.error)

    def advance(self, n: int) -> Run:
        """The outputs after each of the next n intervals (fewer if the plant stops: Run.stopped says why, and the
        plant then stays stopped: later calls return no points)."""
        out = np.empty((len(OUTPUTS), n))
        if self.stopped:
            return self._run(out, 0, compiled.VK_OK)
        code = ctypes.c_int()
        done = self._library.vk_run_from(self._address, self.start_time, self.k, self.interval, n,
                                         out.ctypes.data_as(_double_p), n, ctypes.byref(code))
        self.k += done
        return self._run(out, done, code.value)


__all__ = ["Batch", "OUTPUTS", "Run", "STATE", "Simulation", "simulate", "simulate_many"]
