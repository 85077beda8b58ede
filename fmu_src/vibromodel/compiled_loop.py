"""The controller on the compiled kernel (fmu_src/core/controller.c): ctypes front end.

CompiledEstimator has control.HeldInputEstimator's interface and gives the same bits (controller.c ports
control.py operation for operation, with control._dot's summation order). Its whole state is one ctypes
structure without pointers (VcController), so a snapshot is the structure's bytes, and the FMU's C fast path
(fast_path.py) can step it and read its outputs directly. The controller FMU's inputs and outputs live in that
structure too (`value`, `set_value`, `variable_address`).

Packed inside the FMU: imports nothing beyond vibromodel, numpy and the standard library.
"""
from __future__ import annotations

import ctypes

import numpy as np

from . import forces
from .closedloop import ClosedLoop
from .compiled import ATOL_PER_RTOL, SOLVER_SLOTS, FastPathModel, check_structure, fill_model, take_pending
from .compiled_open_loop import OafmProgram, oafm_hints
# controller.h's and closedloop.h's constants and structures, generated from the headers (core_layouts.py)
from .core_layouts import (VC_GAINS, VC_N, VC_NON_FINITE, VC_OK, VC_RAISED, VL_BAD_STEP, VL_BAD_TIME, VL_OK, VL_TOO_MANY_STEPS, VcController,
                           VlLoop)
from .control import ESTIMATE_NAMES, Controller, Gains, HeldInputEstimator, validate_estimates, validate_law
from .fidelities import entry
from .parameters import ParameterError, Scene, check_finite, validate
from .plant import MAX_STEPS_PER_DOSTEP, RK4_DEFAULT_STEP, TIME_TOLERANCE, Kernel
from .solvers import solver_entry

N = VC_N
CONTROLLER_INPUTS = ("x", "v", "x_ref", "v_ref", "a_ref")
CONTROLLER_OUTPUTS = ("U", "e1", "e2", "V", *ESTIMATE_NAMES)

_double, _int = ctypes.c_double, ctypes.c_int64


def _check_layout(library, function, structure) -> str | None:
    """None if the library's structure has this module's size and field offsets, else what differs."""
    fields = structure._fields_
    offsets = (ctypes.c_size_t * len(fields))()
    size = function(offsets, len(fields))
    if size != ctypes.sizeof(structure):
        return f"{structure.__name__}: size {size} in the library, {ctypes.sizeof(structure)} here"
    for (name, _), offset in zip(fields, offsets):
        if getattr(structure, name).offset != offset:
            return f"{structure.__name__}.{name} is at offset {offset} in the library, here elsewhere"
    return None


def declare(library) -> str | None:
    """Declare the controller's functions on the kernel library (vibromodel.compiled.load_library); None if the
    library has them with this module's layout, else why not."""
    address, d, status = ctypes.c_void_p, _double, ctypes.c_int
    doubles = ctypes.POINTER(_double)
    signatures = {
        "vk_controller_layout": (ctypes.c_size_t, [ctypes.POINTER(ctypes.c_size_t), ctypes.c_size_t]),
        "vk_controller_advance": (status, [address, d, d, d, d, doubles]),
        "vk_controller_publish": (status, [address]),
        "vk_controller_do_step": (status, [address, d, d]),
        "vk_controller_outputs": (status, [address, d, doubles, doubles]),
        "vk_controller_constants": (None, [address, d, d, d, d, d, d, doubles, doubles, ctypes.c_int64, doubles, d, d]),
    }
    try:
        for name, (restype, argtypes) in signatures.items():
            function = getattr(library, name)
            function.restype, function.argtypes = restype, argtypes
    except AttributeError as error:
        return f"the kernel has no controller: {error}"
    return _check_layout(library, library.vk_controller_layout, VcController)


def fill_controller(structure: VcController, controller: Controller, scene: Scene, library) -> None:
    """The constants of a control.Controller into a VcController, by the kernel's vk_controller_constants: the one C
    derivation of them, which the native FMUs use too (control.Controller derives the same bits in Python)."""
    library.vk_controller_constants(ctypes.addressof(structure), scene.mu, scene.Delta, scene.omega, scene.Omega, scene.beta,
                         scene.gamma, (_double * 6)(*forces.coefficients(scene.alpha, scene.gamma, scene.R)),
                         (_double * 6)(*controller.phi.g3), int(controller.law),
                         (_double * VC_GAINS)(*controller.gains.lambdas), controller.gains.k_damping, TIME_TOLERANCE)


def raise_from(code: int) -> None:
    """The Python exception for a kernel code where Python would raise: math.cos/sin of an infinity."""
    if code == VC_RAISED:
        raise ValueError("math domain error")
    if code != VC_OK:
        raise RuntimeError(f"the compiled controller returned code {code} (a kernel bug)")


class CompiledEstimator(FastPathModel):
    """control.HeldInputEstimator on the kernel `library` (declared by `declare`), plus the controller FMU's
    inputs and outputs. Raises ParameterError for bad arguments."""

    STEP_FUNCTION = "vk_controller_do_step"  # vk_controller_do_step(VcController *, t, h)

    def __init__(self, scene: Scene, gains: Gains, law: int, estimates: tuple[float, ...], library,
                 t0: float = 0.0):
        validate(scene)
        validate_law(law)
        validate_estimates(estimates)
        self.controller = Controller(scene, gains, law)
        self._library = library
        self._c = self._struct = VcController()
        self.address = ctypes.addressof(self._c)
        fill_controller(self._c, self.controller, scene, library)
        self._c.t = t0
        self._c.theta_hat = (_double * N)(*estimates)
        self._c.out[4:] = list(estimates)
        self._c.enabled = 1
        self.notes, self.warnings = [], []

    @property
    def t(self) -> float:
        return self._c.t

    @property
    def theta_hat(self) -> np.ndarray:
        return np.array(self._c.theta_hat[:])

    def advance(self, t: float, h: float, x: float, v: float, ref) -> None:
        """HeldInputEstimator.advance."""
        raise_from(self._library.vk_controller_advance(self.address, t, h, x, v, (_double * 3)(*ref)))

    def publish(self) -> None:
        """The FMU's outputs U, e1, e2, V, estimates from the inputs at t (written only when all finite; else
        NonFiniteOutput naming the first that is not, as StatusSlave._set_finite)."""
        code = self._library.vk_controller_publish(self.address)
        if code == VC_NON_FINITE:
            out = (_double * len(CONTROLLER_OUTPUTS))()
            raise_from(self._library.vk_controller_outputs(self.address, self._c.t, self._c.theta_hat, out))
            check_finite(dict(zip(CONTROLLER_OUTPUTS, out)))
        raise_from(code)

    # -- the FMU's variables in the structure, and what the C fast path needs ------------------------------
    @staticmethod
    def _slot(name: str) -> tuple[str, int]:
        if name in CONTROLLER_INPUTS:
            return "in", CONTROLLER_INPUTS.index(name)
        return "out", CONTROLLER_OUTPUTS.index(name)

    def value(self, name: str) -> float:
        field, index = self._slot(name)
        return getattr(self._c, field)[index]

    def set_value(self, name: str, value: float) -> None:
        field, index = self._slot(name)
        getattr(self._c, field)[index] = value

    def variable_address(self, name: str) -> int:
        field, index = self._slot(name)
        return self.address + getattr(VcController, field).offset + index * ctypes.sizeof(_double)

    @property
    def inputs_function(self) -> int:
        """Address of vk_controller_publish(VcController *): the outputs after the inputs changed (fmi2SetReal in C)."""
        return ctypes.cast(self._library.vk_controller_publish, ctypes.c_void_p).value

    # -- snapshots -----------------------------------------------------------------------------------------
    def snapshot(self) -> dict:
        return {"kernel": ctypes.string_at(self.address, ctypes.sizeof(VcController)).hex()}

    def restore(self, snapshot: dict) -> None:
        """ValueError for anything but a snapshot of a compiled controller with the same parameters."""
        restore_bytes(self.address, VcController, VcController.t.offset, snapshot)


def restore_bytes(address: int, structure, constants: int, snapshot: dict) -> None:
    """memmove a snapshot's bytes over a structure whose first `constants` bytes (the parameters) must match."""
    try:
        data = bytes.fromhex(snapshot["kernel"]) if set(snapshot) == {"kernel"} else b""
    except (TypeError, ValueError):
        data = b""
    if len(data) != ctypes.sizeof(structure):
        raise ValueError(f"not a snapshot of a compiled {structure.__name__}")
    if data[:constants] != ctypes.string_at(address, constants):
        raise ValueError("the snapshot is of a compiled model with other parameters or settings")
    check_structure(structure, data, ((0, constants),))  # every other field in range (issue 15)
    ctypes.memmove(address, data, len(data))


def make_estimator(scene: Scene, gains: Gains, law: int, estimates, t0: float, kernel: int, library):
    """CompiledEstimator when kernel == 0 and the library has the controller, else HeldInputEstimator."""
    if kernel not in (0, 1):
        raise ParameterError("kernel", kernel, "must be 0 (compiled) or 1 (pure Python)")
    if kernel == 0 and library is not None and declare(library) is None:
        return CompiledEstimator(scene, gains, law, estimates, library, t0)
    return HeldInputEstimator(scene, gains, law, estimates, t0)




# -- the closed loop -------------------------------------------------------------------------------------------
LOOP_OUTPUTS = ("x", "v", "x_ref", "U", "e1", "e2", "V", "V_rate", "V_rate_promised", *ESTIMATE_NAMES)


def declare_loop(library) -> str | None:
    """Declare the closed loop's functions on the kernel library; None if it has them with this module's layout."""
    problem = declare(library)
    if problem is not None:
        return problem
    address, d, status = ctypes.c_void_p, _double, ctypes.c_int
    try:
        for name, restype, argtypes in (("vk_loop_layout", None, [ctypes.POINTER(ctypes.c_size_t)]),
                                        ("vk_oafm_state", None, [address, d, ctypes.POINTER(_double)]),
                                        ("vk_loop_init", status, [address, d, ctypes.POINTER(_double)]),
                                        ("vk_loop_do_step", status, [address, d, d]),
                                        ("vk_loop_publish", status, [address]),
                                        ("vk_loop_outputs_at", status, [address, d, ctypes.POINTER(_double),
                                                                   ctypes.POINTER(_double)])):
            function = getattr(library, name)
            function.restype, function.argtypes = restype, argtypes
    except AttributeError as error:
        return f"the kernel has no closed loop: {error}"
    sizes = (ctypes.c_size_t * 8)()
    library.vk_loop_layout(sizes)
    expected = (ctypes.sizeof(VlLoop), VlLoop.dop.offset, VlLoop.t.offset, VlLoop.out.offset, VlLoop.enabled.offset,
                VlLoop.error.offset, VlLoop.message.offset, VlLoop.reference.offset)
    if tuple(sizes) != expected:
        return f"VlLoop layout {tuple(sizes)} in the kernel, {expected} in vibromodel.compiled_loop"
    return None


class CompiledClosedLoop(FastPathModel):
    """closedloop.ClosedLoop on the kernel: built from a ClosedLoop that did the set-up (validation, warnings,
    model, controller, reference); `problem` says why it cannot run (then use the Python loop)."""

    STEP_FUNCTION = "vk_loop_do_step"  # vk_loop_do_step(VlLoop *, t, h)

    def __init__(self, python, library):
        self.python = python
        self.notes, self.warnings = list(python.notes), python.warnings
        self._library, self.problem = library, None
        self._program = OafmProgram(python.reference, *oafm_hints(python.scene))
        if self._program.reason is not None:
            self.problem = f"the reference's sums cannot be evaluated by recurrence: {self._program.reason}"
            return
        self._structure = VlLoop
        self._l = self._struct = self._structure()
        self.address = ctypes.addressof(self._l)
        l, settings = self._l, python.settings
        c_model = entry(settings.fidelity).c_model  # the plant level's compiled model
        if c_model is None:
            self.problem = f"the compiled core has no model of fidelity {settings.fidelity}"
            return
        fill_model(l.model, python.model)
        fill_controller(l.controller, python.controller, python.scene, library)
        l.solver, l.time_tolerance = int(settings.solver), TIME_TOLERANCE
        l.dop.rtol, l.dop.atol = settings.rtol, settings.rtol * ATOL_PER_RTOL  # as ClosedLoop gives Dop853
        l.dop.max_step = settings.max_step or python.drive_ceiling  # as ClosedLoop gives Dop853
        l.dop.step_budget = MAX_STEPS_PER_DOSTEP  # as the plant
        l.rk4.max_step = settings.max_step or RK4_DEFAULT_STEP
        l.reference = self._program.struct
        l.enabled = 1
        self._slot = SOLVER_SLOTS[solver_entry(settings.solver).family]
        y0 = (_double * 11)(python.scene.x_start, python.scene.v_start, *python.loop.estimates)
        self._check(library.vk_loop_init(self.address, python.t, y0))

    @property
    def t(self) -> float:
        return self._l.t

    @property
    def integrator(self):
        """The solver's structure (Dop853State or Rk4State: t, y, nfev, n_steps)."""
        return getattr(self._l, self._slot)

    def do_step(self, t: float, h: float) -> dict:
        """ClosedLoop.do_step: raises ParameterError, IntegrationError (TerminalEvent) as it does."""
        self._raise_pending()
        code = self._library.vk_loop_do_step(self.address, t, h)
        if code in (VL_BAD_STEP, VL_TOO_MANY_STEPS, VL_BAD_TIME):
            self.python.t = self._l.t
            self.python.check_step(t, h)
            raise RuntimeError(f"the compiled closed loop refused the step with code {code}, but ClosedLoop "
                               "accepts it (a kernel bug)")
        self._check(code)
        return self._outputs()

    def outputs(self) -> dict:
        """ClosedLoop.outputs: computed at t into the kernel's out[] (there only when all are finite)."""
        self._raise_pending()
        self._check(self._library.vk_loop_publish(self.address))
        return self._outputs()

    def _outputs(self) -> dict:
        out = self._l.out[:]
        values = dict(zip(LOOP_OUTPUTS[:9], out[:9]))
        values["estimates"] = tuple(out[9:])
        return values

    def outputs_at(self, t: float, x: float, v: float, theta_hat) -> dict:
        y = (_double * 11)(x, v, *theta_hat)
        out = (_double * len(LOOP_OUTPUTS))()
        fault = self._library.vk_loop_outputs_at(self.address, t, y, out)
        if fault:
            raise {1: ZeroDivisionError, 2: ValueError, 3: OverflowError}.get(fault, RuntimeError)(
                "raised by the compiled closed loop's outputs")
        values = dict(zip(LOOP_OUTPUTS[:9], out[:9]))
        values["estimates"] = tuple(out[9:])
        return values

    # -- the FMU's variables in the structure, and what the C fast path needs --------------------------------
    def value(self, name: str) -> float:
        return self._l.out[LOOP_OUTPUTS.index(name)]

    def set_value(self, name: str, value: float) -> None:
        self._l.out[LOOP_OUTPUTS.index(name)] = value

    def variable_address(self, name: str) -> int:
        return self.address + self._structure.out.offset + LOOP_OUTPUTS.index(name) * ctypes.sizeof(_double)

    # -- snapshots: the structure's bytes up to the reference (which holds pointers and is rebuilt) -------------
    def snapshot(self) -> dict:
        return {"kernel": ctypes.string_at(self.address, self._structure.reference.offset).hex()}

    def restore(self, snapshot: dict) -> None:
        """ValueError for anything but a snapshot of a compiled closed loop with the same parameters."""
        S = self._structure
        constants = S.dop.offset + type(self._l.dop).t.offset
        try:
            data = bytes.fromhex(snapshot["kernel"]) if set(snapshot) == {"kernel"} else b""
        except (TypeError, ValueError):
            data = b""
        if len(data) != S.reference.offset:
            raise ValueError("not a snapshot of a compiled closed loop")
        rk4_config = (S.rk4.offset, S.rk4.offset + type(self._l.rk4).t.offset)
        current = ctypes.string_at(self.address, S.reference.offset)
        if data[:constants] != current[:constants] or \
                data[rk4_config[0]:rk4_config[1]] != current[rk4_config[0]:rk4_config[1]]:
            raise ValueError("the snapshot is of a compiled closed loop with other parameters or settings")
        check_structure(S, data, ((0, constants), rk4_config))  # every other field in range (issue 15)
        ctypes.memmove(self.address, data, len(data))

    # -- errors ------------------------------------------------------------------------------------------------
    def _check(self, code: int) -> None:
        if code != VL_OK:
            self._raise_pending()
            raise RuntimeError(f"the compiled closed loop returned code {code} without a pending error (a kernel bug)")

    def _raise_pending(self) -> None:
        """Raise the kernel's pending error, if any, and clear it."""
        error = take_pending(self._l, "the compiled closed loop")
        if error is not None:
            raise error


def make_closed_loop(scene: Scene, settings, loop, t0: float, stop_time, cache_dirs, library):
    """The closed loop of `settings` (plant.Settings: fidelity, solver, rtol, max_step, kernel) and `loop`
    (closedloop.LoopSettings): on the compiled kernel where settings.kernel asks for it and library =
    (vibromodel.compiled.load_library's result) holds one, else closedloop.ClosedLoop. Raises ParameterError."""
    python = ClosedLoop(scene, settings, loop, t0=t0, stop_time=stop_time, cache_dirs=cache_dirs)
    if settings.kernel != Kernel.COMPILED:
        return python
    compiled, reason = library
    problem = reason if compiled is None else declare_loop(compiled)
    if problem is None:
        loop_c = CompiledClosedLoop(python, compiled)
        problem = loop_c.problem
        if problem is None:
            loop_c.notes.append("compiled closed loop (fmu_src/core/closedloop.c)")
            return loop_c
    python.notes.append(f"pure-Python closed loop: the compiled one cannot run it ({problem})")
    return python
