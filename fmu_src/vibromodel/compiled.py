"""The plant of the integrated fidelities (0, 1 and 2) with DOP853 or RK4 on the compiled core (fmu_src/core, vibrokernel.so).

CompiledPlant has plant.Plant's interface and gives the same bits: the core ports integrate.Dop853 and Rk4, the
models and Plant.do_step operation for operation. Its whole state is one ctypes structure without pointers
(VkPlant of core/plant.h), so a snapshot is the structure's bytes, and the FMU's C fast path can step it
directly at `address`. Errors the kernel meets are left pending in the structure and raised here as the
Python plant raises them (TerminalEvent, IntegrationError, or the plain exception Python lets escape).

Packed inside the FMU: imports nothing beyond vibromodel, numpy and the standard library.
"""
from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np

from . import error_estimates, settings as plant, slowflow_kernel
# core/plant.h's return codes, core/dop853.h's array sizes and the structures: generated from the headers
# (core_layouts.py by harness/vibrofmu/fmus/layouts.py); Dop853State and Rk4State are dop853.h's Dop853, rk4.h's Rk4
from .core_layouts import (DOP_MAX_EVENTS, DOP_STAGES, VK_BAD_INPUT, VK_BAD_STEP, VK_BAD_TIME, VK_FAILED,
                           VK_OK, VK_RAISED, VK_TERMINAL, VK_TOO_MANY_STEPS, Dop853 as Dop853State,
                           Rk4 as Rk4State, VkModel, VkPlant)
from .fidelities import REGISTRY, entry
from .integrate import ATOL_PER_RTOL, IntegrationError, TerminalEvent
from .models import drive_step_ceiling, solver_tolerance
from .parameters import NonFiniteOutput, validate
from .settings import Outputs, Settings, check_step, checked_settings
from .solvers import BY_VALUE as SOLVERS_BY_VALUE, solver_entry

# solvers.SolverEntry.family -> the field of VkPlant and VlLoop that holds that solver family's state
SOLVER_SLOTS = {"adaptive": "dop", "fixed": "rk4"}

LIBRARY_NAME = "vibrokernel.so"

PRE_CHECK_CODES = {VK_BAD_STEP: "VK_BAD_STEP", VK_BAD_INPUT: "VK_BAD_INPUT", VK_TOO_MANY_STEPS: "VK_TOO_MANY_STEPS",
                   VK_BAD_TIME: "VK_BAD_TIME"}
# VK_RAISED's message is "<type>: <text>": the exception Python raises there, with the C twin's text as its argument.
RAISED_TYPES = {kind.__name__: kind for kind in (ZeroDivisionError, ValueError, OverflowError, RuntimeError)}

_double, _int = ctypes.c_double, ctypes.c_int64


# Valid values of the compiled models' integer fields (core/*.h), by field name, checked by check_structure on
# restore: a state whose counts or switches are out of range would index the stage arrays out of bounds (issue 15:
# n_stages = 20 with dense_ready = 0 crashed the next doStep). A field without an entry is only read as a number.
INT_FIELD_RANGES = {
    "has_old": (0, 1), "n_stages": (0, DOP_STAGES), "dense_ready": (0, 1), "stopped": (0, DOP_MAX_EVENTS),
    "side": (0, 1), "nfev": (0, 2**62), "n_steps": (0, 2**62), "in_contact": (0, 1), "enabled": (0, 1),
    "error": (VK_OK, 15),
}
# Doubles that hold a host's input as given (checked when used: a doStep refuses a non-finite input)
HOST_VALUE_FIELDS = {"U_input", "in"}


def structure_leaves(structure, base: int = 0, prefix: str = ""):
    """(path, field name, ctypes type, offset) of every scalar of a ctypes structure, nested ones and arrays
    unrolled (a char array is one leaf)."""
    for name, kind in structure._fields_:
        yield from _unroll(kind, base + getattr(structure, name).offset, prefix + name, name)


def _unroll(kind, offset: int, path: str, name: str):
    if issubclass(kind, ctypes.Structure):
        yield from structure_leaves(kind, offset, path + ".")
    elif issubclass(kind, ctypes.Array) and kind._type_ is not ctypes.c_char:
        for i in range(kind._length_):
            yield from _unroll(kind._type_, offset + i * ctypes.sizeof(kind._type_), f"{path}[{i}]", name)
    else:
        yield path, name, kind, offset


def check_structure(structure, data: bytes, constant_ranges=()) -> None:
    """Raise ValueError unless `data` (a compiled model's state: the first len(data) bytes of `structure`) could be
    one its kernel left: every integer in its range (INT_FIELD_RANGES), every double finite but the host's inputs
    (HOST_VALUE_FIELDS), every text NUL-terminated. Bytes in constant_ranges (parameters and settings, compared
    with the current model's by the caller) are skipped. Goes by the ctypes field lists, so fields added to the
    structures are covered without offsets written here."""
    for path, name, kind, offset in structure_leaves(structure):
        size = ctypes.sizeof(kind)
        if offset + size > len(data) or any(low <= offset < high for low, high in constant_ranges):
            continue
        raw = data[offset:offset + size]
        if kind is _double:
            value = _double.from_buffer_copy(raw).value
            if not math.isfinite(value) and name not in HOST_VALUE_FIELDS:
                raise ValueError(f"kernel field {path} = {value!r} is not finite")
        elif kind is _int:
            value = _int.from_buffer_copy(raw).value
            low, high = INT_FIELD_RANGES.get(name, (-2**63, 2**63 - 1))
            if not low <= value <= high:
                raise ValueError(f"kernel field {path} = {value} outside [{low}, {high}]")
        elif issubclass(kind, ctypes.Array) and b"\0" not in raw:
            raise ValueError(f"kernel field {path} is not NUL-terminated")


def check_state(data: bytes) -> None:
    """check_structure for a VkPlant (the compiled plant's snapshot)."""
    check_structure(VkPlant, data, constant_ranges())


def _declare(library) -> None:
    """Argument and result types of the kernel's functions (the plant goes by address)."""
    address, d, status, doubles = ctypes.c_void_p, _double, ctypes.c_int, ctypes.POINTER(_double)
    signatures = {
        "vk_layout": (ctypes.c_size_t, [ctypes.POINTER(ctypes.c_size_t), ctypes.c_size_t]),
        "vk_sizes": (None, [ctypes.POINTER(ctypes.c_size_t)]),
        "vk_init": (status, [address, d, d, d]),
        "vk_restart": (status, [address, d, d, d, d]),
        "vk_set_input": (status, [address, d, d]),
        "vk_advance": (status, [address, d]),
        "vk_value_at": (status, [address, d, doubles, doubles]),
        "vk_accel": (d, [address, d, d, d, d]),
        "vk_outputs_at": (status, [address, d, d, d, doubles]),
        "vk_plant_state": (status, [address, doubles]),
        "vk_plant_advance": (status, [address, d, doubles]),
        "vk_do_step": (status, [address, d, d]),
        "vk_do_step_state": (status, [address, d, d]),
        "vk_step_outputs": (status, [address]),
        "vk_outputs_bounded": (status, [address]),
        "vk_run": (status, [address, d, ctypes.c_size_t, doubles]),
        "vk_run_from": (ctypes.c_size_t, [address, d, ctypes.c_size_t, d, ctypes.c_size_t, doubles, ctypes.c_size_t,
                                          ctypes.POINTER(ctypes.c_int)]),
        "vk_run_xv": (ctypes.c_size_t, [address, d, ctypes.c_size_t, d, ctypes.c_size_t, doubles, ctypes.c_size_t,
                                        ctypes.POINTER(ctypes.c_int)]),
        "vk_run_batch": (None, [address, ctypes.c_size_t, d, doubles, doubles, d, ctypes.c_size_t, doubles,
                                ctypes.c_size_t, ctypes.POINTER(_int), ctypes.POINTER(_int), _int]),
    }
    for name, (restype, argtypes) in signatures.items():
        function = getattr(library, name)
        function.restype, function.argtypes = restype, argtypes


def check_layout(library) -> str | None:
    """None if the library's VkPlant has this module's size and field offsets (and its solver structures theirs),
    else what differs."""
    fields = VkPlant._fields_
    offsets = (ctypes.c_size_t * len(fields))()
    size = library.vk_layout(offsets, len(fields))
    if size == 0:
        return f"the kernel's VkPlant has not {len(fields)} fields"
    if size != ctypes.sizeof(VkPlant):
        return f"sizeof(VkPlant) is {size} in the kernel, {ctypes.sizeof(VkPlant)} in vibromodel.compiled"
    for (name, _), offset in zip(fields, offsets):
        if getattr(VkPlant, name).offset != offset:
            return f"VkPlant.{name} is at offset {offset} in the kernel, {getattr(VkPlant, name).offset} here"
    sizes = (ctypes.c_size_t * 5)()
    library.vk_sizes(sizes)
    expected = (ctypes.sizeof(Dop853State), ctypes.sizeof(Rk4State), ctypes.sizeof(VkModel), Dop853State.t.offset,
                Rk4State.t.offset)
    if tuple(sizes) != expected:
        return f"the solver structures' sizes are {tuple(sizes)} in the kernel, {expected} here"
    return None


def load_library(directories) -> tuple[ctypes.CDLL | None, str]:
    """(the kernel library, what was loaded) from the first of `directories` holding vibrokernel.so, or
    (None, why not): missing, not loadable, or a structure layout other than this module's."""
    directories = [Path(folder) for folder in directories]
    path = next((folder / LIBRARY_NAME for folder in directories if (folder / LIBRARY_NAME).is_file()), None)
    if path is None:
        return None, f"no {LIBRARY_NAME} in {', '.join(map(str, directories)) or 'no folder'}"
    try:
        library = ctypes.CDLL(str(path))
        _declare(library)
    except (OSError, AttributeError) as error:
        return None, f"cannot use {path}: {error}"
    problem = check_layout(library)
    if problem is not None:
        return None, f"{path} does not match vibromodel.compiled: {problem}"
    error_estimates.use_kernel(library)  # fidelities 1 and 2's estimate in C (core/estimate.c), the same bits
    slowflow_kernel.use_kernel(library)  # fidelity 3's table in C (core/slowflow_table.c)
    return library, f"compiled kernel {path}"


def supports(settings: Settings) -> bool:
    """CompiledPlant runs the integrated fidelities with a compiled model (fidelities registry) with a solver the
    compiled core has (solvers registry)."""
    level, solver = entry(settings.fidelity), SOLVERS_BY_VALUE.get(settings.solver)
    return level.integrated and level.c_model is not None and solver is not None and solver.compiled


def fill_model(structure: VkModel, model) -> None:
    """Fill a VkModel from a model object (models.ExactModel / PolynomialModel): its compiled_fields(), the constants
    of its own scene, so the C computes what the model's accel does (the registry's model is the one source)."""
    known = {name for name, _ in type(structure)._fields_}
    for name, value in model.compiled_fields().items():
        if name not in known:  # ctypes would keep it as a Python attribute, which the C never sees
            raise ValueError(f"core/model.h's VkModel has no field {name} (add it there and regenerate "
                             "vibromodel/core_layouts.py: python3 -m vibrofmu.fmus.layouts)")
        setattr(structure, name, value if isinstance(value, (int, float)) else (_double * 6)(*value))


def constant_ranges():
    """Byte ranges of VkPlant that parameters and settings fix: model and settings, each solver's configuration."""
    return ((0, VkPlant.dop.offset + Dop853State.t.offset),
            (VkPlant.rk4.offset, VkPlant.rk4.offset + Rk4State.t.offset))


def _reader(part: str, field: str) -> property:
    """A read-only property: field `field` of the object's attribute `part` (a kernel structure)."""
    return property(lambda self: getattr(getattr(self, part), field))


def _flag(field: str) -> property:
    """A bool property on int64 field `field` of the object's kernel structure `_struct`."""
    return property(lambda self: bool(getattr(self._struct, field)),
                    lambda self, value: setattr(self._struct, field, bool(value)))


class FastPathModel:
    """What the FMU's C fast path (fmu_src/fast_path.py) reads and writes of a compiled model: the kernel structure
    `_struct` (whose `enabled` flag the kernel clears at an error) at `address`, and the address of the kernel's
    doStep function named STEP_FUNCTION (f(struct *, t, h)); the model sets `_library` and `address`."""

    STEP_FUNCTION = ""

    @property
    def enabled_address(self) -> int:
        return ctypes.addressof(self._struct) + type(self._struct).enabled.offset

    @property
    def step_function(self) -> int:
        return ctypes.cast(getattr(self._library, self.STEP_FUNCTION), ctypes.c_void_p).value

    fast_path_enabled = _flag("enabled")  # whether the C fast path may call the step function (cleared at an error)


class PlantFastPath(FastPathModel):
    """FastPathModel of a model whose `_struct` is a VkPlant (the compiled plant, the open-loop levels' plant): its
    outputs, in_contact and held input, as the plant FMU's slave reads and writes them."""

    def field_address(self, name: str, index: int = 0) -> int:
        """Address of VkPlant field `name`, or of element `index` of a double array field (out)."""
        return ctypes.addressof(self._struct) + getattr(VkPlant, name).offset + index * ctypes.sizeof(_double)

    def output(self, index: int) -> float:
        """out[index]: x, v, a, F_contact, F_electrostatic after the last step."""
        return self._struct.out[index]

    def set_output(self, index: int, value: float) -> None:
        self._struct.out[index] = value

    in_contact = _flag("in_contact")
    next_input = property(lambda self: self._struct.U_input,  # the input U the next step holds (the FMU's input)
                          lambda self, value: setattr(self._struct, "U_input", value))


class CompiledPlant(PlantFastPath):
    """plant.Plant for the integrated fidelities with a compiled model (supports) with either solver, on the kernel `library` (load_library)."""

    STEP_FUNCTION = "vk_do_step"  # vk_do_step(VkPlant *, t, h): one doStep with the held next_input

    def __init__(self, scene, settings: Settings, library, t0: float = 0.0, stop_time: float | None = None):
        validate(scene)
        settings, self.warnings = checked_settings(scene, settings)  # what Plant runs with (rtol clamped)
        if not supports(settings):
            runs = [str(int(e.level)) for e in REGISTRY.values() if e.integrated and e.c_model is not None]
            raise ValueError(f"the compiled plant runs fidelities {', '.join(runs)}, not fidelity {settings.fidelity}")
        level = entry(settings.fidelity)
        model = level.model(scene)
        # the Python model the kernel's is filled from, kept: the error estimate (error_estimates.attach) reads its
        # coefficients instead of building it again (~15-40 us of a fidelity 1 FMU's ~2 ms initialisation)
        self.model = model
        self.scene, self.settings, self.notes = scene, settings, []
        self._library = library
        self._plant = VkPlant()
        self._struct = self._plant
        self.address = ctypes.addressof(self._plant)  # of the VkPlant, which the kernel's functions take
        max_step = settings.max_step or drive_step_ceiling(scene)  # as Plant gives Dop853
        rtol, notes = solver_tolerance(scene, settings, t0, stop_time)  # as Plant gives its integrator
        self.notes += notes
        fill_model(self._plant.model, model)
        dop, rk4 = self._plant.dop, self._plant.rk4
        dop.rtol, dop.atol, dop.max_step = rtol, rtol * ATOL_PER_RTOL, max_step
        dop.step_budget = plant.MAX_STEPS_PER_DOSTEP
        rk4.max_step = settings.max_step or plant.RK4_DEFAULT_STEP  # as Plant gives Rk4
        self._plant.solver = int(settings.solver)
        for name, value in dict(time_tolerance=plant.TIME_TOLERANCE, max_steps_per_dostep=plant.MAX_STEPS_PER_DOSTEP,
                                plant_t=t0, U_input=0.0, enabled=1).items():
            setattr(self._plant, name, value)
        self._check(library.vk_init(self.address, t0, scene.x_start, scene.v_start))

    @property
    def _solver(self):
        return getattr(self._plant, SOLVER_SLOTS[solver_entry(self._plant.solver).family])

    # the plant's time and input, the solver's step ceiling (inf: none, as integrator.max_step) and counters
    t = _reader("_plant", "plant_t")
    U = _reader("_plant", "U_input")
    max_step = _reader("_solver", "max_step")
    nfev = _reader("_solver", "nfev")
    n_steps = _reader("_solver", "n_steps")

    # -- stepping ---------------------------------------------------------------------------------------------
    def do_step(self, t: float, h: float, U: float) -> Outputs:
        """Plant.do_step: raises ParameterError, IntegrationError (TerminalEvent) as it does; a pending error
        (left by the FMU's C fast path) is raised first, without stepping."""
        self._raise_pending()
        previous, self._plant.U_input = self._plant.U_input, U
        code = self._library.vk_do_step(self.address, t, h)
        if code in PRE_CHECK_CODES:
            self._plant.U_input = previous
            self._refused(code, t, h, U)
        self._check(code)
        return self._outputs()

    def advance(self, t_end: float, U: float = 0.0) -> tuple[float, float, float]:
        """Plant.advance: to t_end with U held, (x, x', x'') there; a pending error is raised first."""
        self._raise_pending()
        self._plant.U_input = U
        xva = (_double * 3)()
        self._check(self._library.vk_plant_advance(self.address, t_end, xva))
        return tuple(xva)

    def run(self, dt: float, n: int) -> np.ndarray:
        """x after each of n do_steps of dt (each from the plant's time) with U held: the compiled floor."""
        self._raise_pending()
        x = np.empty(n)
        code = self._library.vk_run(self.address, dt, n, x.ctypes.data_as(ctypes.POINTER(_double)))
        if code in PRE_CHECK_CODES:
            self._refused(code, self.t, dt, self.U)
        self._check(code)
        return x

    # -- outputs ----------------------------------------------------------------------------------------------
    def state(self) -> tuple[float, float, float]:
        xva = (_double * 3)()
        self._check(self._library.vk_plant_state(self.address, xva))
        return tuple(xva)

    def outputs(self) -> Outputs:
        return self.outputs_at(self.t, *self.state())

    def outputs_at(self, t: float, x: float, v: float, a: float | None = None) -> Outputs:
        """Plant.outputs_at; the kernel's out[] and in_contact (what the FMU reads) take these outputs."""
        given = None if a is None else ctypes.byref(_double(a))
        self._check(self._library.vk_outputs_at(self.address, t, x, v, given))
        return self._outputs()

    def _outputs(self) -> Outputs:
        """Outputs from out[] (x, v, a, F_contact, F_electrostatic; a slice reads it in one go) and in_contact."""
        return Outputs(*self._plant.out[:], bool(self._plant.in_contact))

    # -- snapshots --------------------------------------------------------------------------------------------
    def snapshot(self) -> dict:
        """The kernel structure's bytes (hex), the whole state."""
        return {"kernel": ctypes.string_at(self.address, ctypes.sizeof(VkPlant)).hex()}

    def restore(self, snapshot: dict) -> None:
        """Return to the moment `snapshot` was taken; ValueError for anything but a snapshot of a compiled plant
        with the same parameters and settings."""
        try:
            data = bytes.fromhex(snapshot["kernel"]) if set(snapshot) == {"kernel"} else b""
        except (TypeError, ValueError):
            data = b""
        if len(data) != ctypes.sizeof(VkPlant):
            raise ValueError("not a snapshot of a CompiledPlant")
        current = ctypes.string_at(self.address, len(data))
        if any(data[start:end] != current[start:end] for start, end in constant_ranges()):
            raise ValueError("the snapshot is of a compiled plant with other parameters or settings")
        check_state(data)
        ctypes.memmove(self.address, data, len(data))

    # -- errors -----------------------------------------------------------------------------------------------
    def _check(self, code: int) -> None:
        if code != VK_OK:
            self._raise_pending()
            raise RuntimeError(f"vibrokernel returned code {code} without a pending error (a kernel bug)")

    def _refused(self, code: int, t: float, h: float, U: float) -> None:
        """A pre-check refused the step: raise Plant's ParameterError for it."""
        check_step(self.t, t, h, U, self.max_step)
        raise RuntimeError(f"vibrokernel refused the step with {PRE_CHECK_CODES[code]}, but plant.check_step "
                           f"accepts it (a kernel bug)")

    def _raise_pending(self) -> None:
        """Raise the kernel's pending error, if any, and clear it."""
        error = take_pending(self._plant)
        if error is not None:
            raise error


def take_pending(p, who: str = "vibrokernel") -> BaseException | None:
    """The exception the Python twin raises for the kernel's pending error in `p` (None: none), which is cleared.
    `p` is a VkPlant or a VlLoop: both carry error, error_t/x/v and message, with the same codes (core_layouts: the
    VK_ and VL_ codes are the DOP_ ones). NonFiniteOutput is written by the closed loop alone (closedloop.c)."""
    code = p.error
    if code == VK_OK:
        return None
    message, t, x, v = p.message.decode(), p.error_t, p.error_x, p.error_v
    p.error, p.error_t, p.error_x, p.error_v = 0, 0.0, 0.0, 0.0
    field = type(p).message
    ctypes.memset(ctypes.addressof(p) + field.offset, 0, field.size)
    if code == VK_TERMINAL:
        return TerminalEvent(message, t, x, v)
    if code == VK_FAILED:
        return IntegrationError(message, t, x, v)
    kind, _, text = message.partition(": ")
    if code == VK_RAISED and kind in RAISED_TYPES:
        return RAISED_TYPES[kind](text)
    if code == VK_RAISED and kind == "NonFiniteOutput":  # "output <name> = <value> is not finite; ..."
        name, _, rest = text.removeprefix("output ").partition(" = ")
        return NonFiniteOutput(name, float(rest.partition(" ")[0]))
    return RuntimeError(f"{who} left error code {code}: {message}")
