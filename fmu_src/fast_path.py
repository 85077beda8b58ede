"""Hand a compiled model to the status shim's C fast path (fmu_src/fmi2_status_shim.c, "Fast path").

The shim then runs fmi2DoStep on the model's C step function (the plant's vk_do_step, the controller's
vk_controller_do_step, the closed loop's vk_loop_do_step) and answers fmi2GetReal/fmi2GetBoolean of the outputs from the
model's memory, without calling Python. Any model will do that gives a step function int step(void *model,
double t, double h), its address, the address of its int64 "enabled" flag and those of its outputs (and, for
inputs set in C, a function int inputs_set(void *model) and the inputs' addresses). The shim accepts a model only
during a call it forwarded to this slave (exitInitializationMode, setFMUstate); outside one (no shim, a Python
host driving the slave object directly) attaching does nothing and every call takes the Python path.
"""
from __future__ import annotations

import ctypes
import sys
from pathlib import Path


def use_packed_packages(resources: Path, names=("vibromodel",)) -> None:
    """Let this FMU's packed copy of each package in `names` serve the modules not yet imported.

    Every pythonfmu FMU packs vibromodel in its resources, and a Python process has one `vibromodel` in
    sys.modules: the first FMU's (or the host's own). A second, different FMU in the same process imports its
    modules from that package's folder, which the host may already have deleted with the first FMU (FMPy's
    simulate_fmu does): then `vibromodel.compiled_loop`, which the plant never imported, is not found and the
    controller failed to instantiate. Appending this FMU's folder to the package's search path keeps the modules
    already imported (the host's, or the first FMU's, in memory) and finds every other one here. The slaves call
    this before their first vibromodel import (fast_path itself imports only the standard library)."""
    for name in names:
        package = sys.modules.get(name)
        folder = str(Path(resources) / name)
        if package is not None and hasattr(package, "__path__") and folder not in list(package.__path__):
            package.__path__.append(folder)

FAST_MAX = 32  # the shim's FAST_MAX: most Real (and Boolean) outputs it serves
_vr_array = ctypes.c_uint * FAST_MAX
_address_array = ctypes.c_void_p * FAST_MAX


def _shim_function(resources: str | None, model_identifier: str, name: str, argtypes: list):
    """The shim's C function `name` (returning int, taking `argtypes`), or None (no resources, no shim, or a shim
    without that function)."""
    if not resources:
        return None
    path = Path(resources).parent / "binaries" / "linux64" / f"{model_identifier}.so"
    try:
        function = getattr(ctypes.CDLL(str(path)), name)
    except (OSError, AttributeError):
        return None
    function.restype = ctypes.c_int
    function.argtypes = argtypes
    return function


def shim_attach(resources: str | None, model_identifier: str):
    """The shim's vibro_fast_path_attach, or None (no resources, no shim, or a shim without a fast path)."""
    return _shim_function(resources, model_identifier, "vibro_fast_path_attach",
                          [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                           ctypes.c_size_t, _vr_array, _address_array, ctypes.c_size_t, _vr_array, _address_array])


def shim_inputs(resources: str | None, model_identifier: str):
    """The shim's vibro_fast_path_inputs, or None."""
    return _shim_function(resources, model_identifier, "vibro_fast_path_inputs",
                          [ctypes.c_void_p, ctypes.c_size_t, _vr_array, _address_array])


def attach(shim, plant, real_outputs: dict[int, int], boolean_outputs: dict[int, int]) -> bool:
    """Attach `plant` (a vibromodel.compiled.CompiledPlant) to the shim: real_outputs / boolean_outputs map
    value references to the index of the plant's output. plant None detaches. True if the shim took it."""
    if plant is None:
        return attach_addresses(shim, None, None, None, {}, {})
    return attach_addresses(shim, plant.step_function, plant.address, plant.field_address("enabled"),
                            {vr: plant.field_address("out", i) for vr, i in real_outputs.items()},
                            {vr: plant.field_address("in_contact") for vr in boolean_outputs})


def attach_addresses(shim, step_function, address, enabled_address, reals: dict[int, int],
                     booleans: dict[int, int]) -> bool:
    """Attach any compiled model: its step function, address and enabled flag's address; reals / booleans map
    value references to the addresses of the outputs (double / int64). step_function None detaches."""
    if shim is None:
        return False
    if step_function is None:
        return bool(shim(None, None, None, 0, _vr_array(), _address_array(), 0, _vr_array(), _address_array()))
    return bool(shim(step_function, address, enabled_address,
                     len(reals), _vr_array(*reals), _address_array(*reals.values()),
                     len(booleans), _vr_array(*booleans), _address_array(*booleans.values())))


def memory_variable(name: str):
    """An FMI variable that lives in the compiled model's memory when there is one (model.value / set_value by
    name), else in the slave's `_values`."""

    def get(self):
        kernel = self._kernel
        return self._values[name] if kernel is None else kernel.value(name)

    def set(self, value):
        self._values[name] = value
        if self._kernel is not None:
            self._kernel.set_value(name, value)

    return property(get, set)


class FastPathSwitch:
    """Mixin (before slave_support.StatusSlave) of a slave whose model may be compiled (`_kernel`): the shim may
    step the compiled model only while the slave is initialised and without error, so the switch follows every
    change of those (initialisation, state restore, error)."""

    _kernel = None  # the model when it is compiled
    _model = None
    _shim = None  # the status shim's attach function (shim_attach), if any

    @property
    def model(self):
        return self._model

    @model.setter
    def model(self, model):
        """A new model: a compiled one (`_compiled`) takes over the variables kept in its memory (`_into_kernel`);
        the shim's fast path gets it, or is detached (`_attach`, given the value references by name)."""
        self._model = model
        self._kernel = self._compiled(model)
        if self._kernel is not None:
            self._into_kernel(self._kernel)
        if self._shim is not None:
            self._attach(self._kernel, {var.name: vr for vr, var in self.vars.items()})

    def _enable_fast_path(self):
        if self._kernel is not None:
            self._kernel.fast_path_enabled = self.halted is None and self.fmi_status == 0  # STATUS_OK

    def exit_initialization_mode(self):
        super().exit_initialization_mode()
        self._enable_fast_path()

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self._enable_fast_path()

    def _error(self, message):
        super()._error(message)
        self._enable_fast_path()


class CompiledModelSlave(FastPathSwitch):
    """Mixin (before slave_support.StatusSlave) of a slave whose model may be compiled: a model with a
    `step_function` takes over the variables named in MEMORY (declared with memory_variable) and is handed to
    the shim's fast path, which then steps it and serves the outputs named in FAST_OUTPUTS. The fast path runs
    only while the slave is initialised and without error (the model's `fast_path_enabled`)."""

    MEMORY: tuple[str, ...] = ()
    FAST_OUTPUTS: tuple[str, ...] = ()
    FAST_INPUTS: tuple[str, ...] = ()  # set in C when the model has an `inputs_function` (0: done)

    def __init__(self, **kwargs):
        self._values = {}
        super().__init__(**kwargs)
        self._shim = shim_attach(self.resources, type(self).__name__)
        self._shim_inputs = shim_inputs(self.resources, type(self).__name__) if self.FAST_INPUTS else None

    @staticmethod
    def _compiled(model):
        return model if hasattr(model, "step_function") else None

    def _into_kernel(self, kernel):
        for name in self.MEMORY:
            kernel.set_value(name, self._values[name])

    def _attach(self, kernel, references):
        if kernel is None:
            attach_addresses(self._shim, None, None, None, {}, {})
            return
        attached = attach_addresses(self._shim, kernel.step_function, kernel.address, kernel.enabled_address,
                                    {references[name]: kernel.variable_address(name) for name in self.FAST_OUTPUTS},
                                    {})
        if attached and self._shim_inputs is not None:
            names = self.FAST_INPUTS
            self._shim_inputs(kernel.inputs_function, len(names), _vr_array(*(references[n] for n in names)),
                              _address_array(*(kernel.variable_address(n) for n in names)))
