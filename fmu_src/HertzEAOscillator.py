"""FMI 2.0 co-simulation slave of the plant (the contract in docs/fmu-reference.md): FMI variables <-> vibromodel.Plant.

No physics here; the FMI error handling, the rules for setting variables and the FMU state are
slave_support.StatusSlave's. The state's model part is the plant's snapshot (integrator included); the
plant itself is rebuilt from the parameters on restore.

On the compiled kernel (vibromodel.compiled, parameter kernel = 0) the plant's outputs and next input live in
the kernel's memory: the status shim's fast path (fast_path.py) steps it and reads the outputs there without
Python, so the output and input variables below are properties on that memory.
"""
import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

from pythonfmu import Boolean, DefaultExperiment, Fmi2Causality, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Initial

import fast_path

fast_path.use_packed_packages(Path(__file__).parent)  # before any vibromodel import
from slave_support import StatusSlave
from vibromodel.analytic import OafmSettings
from vibromodel.auto import DEFAULT_TOLERANCE, auto_plant, is_auto
from vibromodel.compiled import CompiledPlant, load_library
from vibromodel.compiled_open_loop import CompiledOpenLoopPlant
from vibromodel.fidelities import AUTO, Fidelity, description, entry
from vibromodel.parameters import Scene, check_finite, check_parameters, scene_names, validate
from vibromodel.plant import DEFAULT_EXPERIMENT, Plant, Settings, make_plant

OUTPUTS = ("x", "v", "a", "F_contact", "F_electrostatic")
NO_ESTIMATE = -1.0  # error_estimate before initialisation, or when the rung cannot estimate (it then warns)
NOT_CHOSEN = -1  # fidelity_chosen before initialisation (its start value, as error_estimate's)


def _output(index: int):
    """Output OUTPUTS[index], or in_contact (index None): in the compiled plant's memory when there is one."""
    name = "in_contact" if index is None else OUTPUTS[index]

    def get(self):
        kernel = self._kernel
        if kernel is None:
            return self._values[name]
        return kernel.in_contact if index is None else kernel.output(index)

    def set(self, value):
        self._values[name] = value
        if self._kernel is not None:
            if index is None:
                self._kernel.in_contact = value
            else:
                self._kernel.set_output(index, value)

    return property(get, set)


class HertzEAOscillator(fast_path.FastPathSwitch, StatusSlave):
    author = "vibrofmu"
    description = "Hertzian-contact oscillator with two-sided electrostatic actuation (Eq. 3 with the corrected formulas: docs/model.md)"
    default_experiment = DefaultExperiment(*DEFAULT_EXPERIMENT)
    state_format = "HertzEAOscillator state 3"

    x, v, a, F_contact, F_electrostatic = (_output(i) for i in range(len(OUTPUTS)))
    in_contact = _output(None)

    def __init__(self, **kwargs):
        self._values = {}  # outputs and input without a compiled plant
        super().__init__(**kwargs)
        self._shim = fast_path.shim_attach(self.resources, type(self).__name__)
        scene, settings, oafm = Scene(), Settings(), OafmSettings()
        self._plant_parameters(scene, settings,  # "0 exact Eq. 3, 1 polynomial Eq. 7, ..., -1 auto: ..."
                               f"{description()}, {AUTO} auto: the cheapest rung whose error estimate meets tolerance")
        self._parameter(Real, "tolerance", DEFAULT_TOLERANCE,
                        "fidelity auto: the bound on max|x - x_exact| in x's units (docs/rungs.md, Choosing by "
                        "tolerance)")
        self._parameter(Integer, "kernel", int(settings.kernel),
                        "0 compiled C kernel (fidelities 0-2 with both solvers; 3 and 4: their per-output evaluation; "
                        "pure Python where it is missing), 1 pure Python")
        self._parameter(Integer, "oafm_order", oafm.order, "fidelity 4: order of the harmonic OAFM basis")
        self._parameter(Real, "tau_star", oafm.tau_star, "fidelity 4: end of the transient domain; 0 = automatic")
        self._parameter(Real, "oafm_tau_end", oafm.tau_end,
                        "fidelity 4: end of the fit; 0 = automatic, at least the stop time")
        self.U = 0.0
        self.register_variable(Real("U", causality=Fmi2Causality.input, description="control force"))
        self._outputs(OUTPUTS, (scene.x_start, scene.v_start, 0.0, 0.0, 0.0))
        self.error_estimate = NO_ESTIMATE
        self.register_variable(Real("error_estimate", causality=Fmi2Causality.output,
                                    variability=Fmi2Variability.discrete, initial=Fmi2Initial.exact,
                                    description="estimate of max|x - x_exact| over the run (x's units), set at "
                                                "initialisation (docs/rungs.md, Error estimates); -1: none"))
        self.fidelity_chosen = NOT_CHOSEN
        self.register_variable(Integer("fidelity_chosen", causality=Fmi2Causality.output,
                                       variability=Fmi2Variability.discrete, initial=Fmi2Initial.exact,
                                       description="the fidelity the plant runs, set at initialisation: `fidelity`, or "
                                                   "the one fidelity auto chose (docs/rungs.md); -1 before"))
        self.in_contact = True
        self.register_variable(Boolean("in_contact", causality=Fmi2Causality.output,
                                       variability=Fmi2Variability.discrete, initial=Fmi2Initial.exact))

    def _make_model(self):
        """The plant of the current parameters and experiment; raises ParameterError for bad ones."""
        oafm = OafmSettings(order=int(self.oafm_order), tau_star=float(self.tau_star), tau_end=float(self.oafm_tau_end))
        scene, settings = self._plant_values(oafm=oafm)

        def build(settings):
            return make_plant(scene, settings, t0=float(self.start_time), stop_time=self.stop_time,
                              cache_dirs=self._cache_dirs(), library=self._library())

        if is_auto(settings.fidelity):  # the choice's settings replace fidelity, solver, rtol and max_step
            span = None if self.stop_time is None else float(self.stop_time) - float(self.start_time)
            return auto_plant(scene, replace(settings, fidelity=int(Fidelity.EXACT)), float(self.tolerance), build,
                              span=span, t0=float(self.start_time), cache_dirs=self._cache_dirs())
        return build(settings)

    def _library(self):
        """(the compiled kernel packed in resources, or None; why not)."""
        return load_library((Path(self.resources),) if self.resources else ())

    # -- the compiled plant and the shim's fast path -------------------------------------------------------
    @property
    def U(self):
        return self._values["U"]

    @U.setter
    def U(self, value):
        self._values["U"] = value
        if self._kernel is not None:
            self._kernel.next_input = float(value)

    @fast_path.FastPathSwitch.model.setter
    def model(self, model):
        """A new model: its error estimate published; a compiled one takes over the outputs and input (below)."""
        fast_path.FastPathSwitch.model.fset(self, model)
        estimate = getattr(model, "error_estimate", None)
        value = NO_ESTIMATE if estimate is None else estimate["estimate"]
        self.error_estimate = value if math.isfinite(value) else NO_ESTIMATE
        self.fidelity_chosen = NOT_CHOSEN if model is None else int(model.settings.fidelity)

    @staticmethod
    def _compiled(model):
        return model if isinstance(model, (CompiledPlant, CompiledOpenLoopPlant)) else None

    def _into_kernel(self, kernel):
        for name in (*OUTPUTS, "in_contact", "U"):
            setattr(self, name, self._values[name])  # through the properties, into the kernel's memory

    def _attach(self, kernel, references):
        fast_path.attach(self._shim, kernel, {references[name]: i for i, name in enumerate(OUTPUTS)},
                         {references["in_contact"]: 0})

    def _start(self):
        """exitInitializationMode: the first outputs are those at the start time without input (U = 0: no step has
        held an input yet; the pure-Python plant and the native FMU do the same); U is held from the first doStep."""
        U, self.U = self.U, 0.0
        try:
            super()._start()
        finally:
            self.U = U

    def _initial_output(self, name):
        """Outputs in Initialization Mode (FMI 2.0: computed from the start values set so far): x = x_start,
        v = v_start, a and the forces of the fidelity's model at the start time with U = 0, as exitInitializationMode
        will publish them (fidelities 3 and 4: Eq. 3 at the start state; their solution replaces them at exit).
        ParameterError when the scene breaks a rule (the parameter named)."""
        if name == "error_estimate":  # set at exitInitializationMode, with the plant
            return NO_ESTIMATE
        if name == "fidelity_chosen":  # likewise (fidelity auto chooses then)
            return NOT_CHOSEN
        values = self._parameter_values()
        check_parameters({key: values[key] for key in ("fidelity", *scene_names())})
        fidelity = int(values["fidelity"])
        scene = Scene(**{key: float(values[key]) for key in scene_names()})
        validate(scene)
        # fidelity auto: Eq. 3 (every candidate's forces are the exact model's: auto.candidates)
        plant = SimpleNamespace(model=entry(Fidelity.EXACT if is_auto(fidelity) else fidelity).model(scene), U=0.0)
        out = Plant.outputs_at(plant, float(self.start_time), scene.x_start, scene.v_start)  # one implementation
        value = getattr(out, name)
        if name != "in_contact":
            check_finite({name: value})
        return value

    def do_step(self, current_time, step_size):
        return self._guarded_step(
            current_time, lambda: self._publish(self.model.do_step(current_time, step_size, float(self.U))),
            lambda error: self._publish(self.model.outputs_at(error.t, error.x, error.v)))

    def _publish(self, out):
        self._set_finite({**dict(zip(OUTPUTS, (out.x, out.v, out.a, out.F_contact, out.F_electrostatic))),
                          "in_contact": out.in_contact})
