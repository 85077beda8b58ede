"""FMI 2.0 co-simulation slave of the adaptive Lyapunov controller alone (docs/fmu-reference.md contract, docs/model.md, Adaptive controller).

Inputs x, v (plant) and x_ref, v_ref, a_ref (reference x~, x~', x~''); outputs U, e1, e2, V and the nine
estimates. U, e1, e2 and V are algebraic in the inputs (direct feedthrough): they are recomputed whenever an
input is set. The estimates are the controller's states. Method: inside doStep(t, H) the inputs are held
(zero-order hold), so the update law's right-hand side lambda2 Lambda^-1 phi(x, v, tau) e2 depends on tau
only and is integrated exactly in closed form (vibromodel.control.Controller.increment). V uses the true
theta of the model parameters (a diagnostic; only paper-literal also reads the true Delta, as Eq. 78 does).
No physics here; the FMI error handling and the FMU state are slave_support.StatusSlave's; the state's model
part is the estimates and the controller's time (HeldInputEstimator.snapshot), the inputs held over a step
are FMI variables, the controller is rebuilt from the parameters.

On the compiled kernel (parameter kernel = 0; vibromodel.compiled_loop.CompiledEstimator on
fmu_src/core/controller.c) the inputs, outputs and estimates live in the kernel's memory: the status shim's fast
path (fast_path.py) runs doStep, sets the inputs (recomputing U, e1, e2, V) and answers the output getters there
without Python.
"""
from pathlib import Path

import numpy as np
from pythonfmu import DefaultExperiment, Fmi2Causality, Integer, Real

import fast_path

fast_path.use_packed_packages(Path(__file__).parent)  # before any vibromodel import
from slave_support import MODEL_PARAMETERS, StatusSlave
from vibromodel.compiled import load_library
from vibromodel.compiled_loop import CONTROLLER_INPUTS, CONTROLLER_OUTPUTS, make_estimator
from vibromodel.control import ESTIMATE_NAMES
from vibromodel.parameters import ParameterError, Scene, check_parameters
from vibromodel.plant import DEFAULT_EXPERIMENT, TIME_TOLERANCE

INPUTS = ("x", "v", "x_ref", "v_ref", "a_ref")
OUTPUTS = ("U", "e1", "e2", "V")


class AdaptiveLyapunovController(fast_path.CompiledModelSlave, StatusSlave):
    author = "vibrofmu"
    description = "Adaptive Lyapunov tracking controller of the Hertzian-contact oscillator (corrected laws: docs/model.md)"
    default_experiment = DefaultExperiment(*DEFAULT_EXPERIMENT)
    state_format = "AdaptiveLyapunovController state 2"
    MEMORY = CONTROLLER_INPUTS + CONTROLLER_OUTPUTS
    FAST_OUTPUTS = CONTROLLER_OUTPUTS
    FAST_INPUTS = CONTROLLER_INPUTS
    x, v, x_ref, v_ref, a_ref, U, e1, e2, V = (fast_path.memory_variable(name) for name in INPUTS + OUTPUTS)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        scene = Scene()
        for name in MODEL_PARAMETERS:
            self._parameter(Real, name, getattr(scene, name), "plant model parameter (regressor, true theta for V)")
        self._controller_parameters()
        self._parameter(Integer, "kernel", 0, "0 compiled C controller (pure Python if it is missing), 1 pure Python")
        for name in INPUTS:
            setattr(self, name, 0.0)
            self.register_variable(Real(name, causality=Fmi2Causality.input,
                                        setter=lambda value, name=name: self._set_input(name, value)))
        self._outputs(OUTPUTS, (0.0, 0.0, 0.0, 0.0))
        self._outputs(ESTIMATE_NAMES, [getattr(self, f"{name}_start") for name in ESTIMATE_NAMES], "estimate")

    def _start(self):
        self.model = self._make_model()
        self._publish()

    def _make_model(self):
        """The estimator of the current parameters and experiment; raises ParameterError for bad ones."""
        # no initial state here: x_start = 0 keeps the scene's check on the electrodes about R alone
        scene = Scene(**{name: float(getattr(self, name)) for name in MODEL_PARAMETERS}, x_start=0.0, v_start=0.0)
        law, gains, estimates = self._controller_settings()
        library, _ = load_library((Path(self.resources),) if self.resources else ())
        return make_estimator(scene, gains, law, estimates, float(self.start_time), int(self.kernel), library)

    def _set_input(self, name, value):
        try:  # U, e1, e2 follow the inputs at once: a value out of range would make them overflow
            check_parameters({name: value})
        except ParameterError as error:
            self._error(f"{error}")
            return
        setattr(self, name, value)
        if self.halted is None:
            try:
                self._publish()
            except Exception as error:  # a setter must not raise either
                self._halt(f"input {name} = {value!r}: {error!r}")

    def _reference(self):
        return (float(self.x_ref), float(self.v_ref), float(self.a_ref))

    def _publish(self):
        """U, e1, e2, V at the controller's time from the current inputs and estimates."""
        if self._kernel is not None:
            self._kernel.publish()
            return
        model, x, v, ref = self.model, float(self.x), float(self.v), self._reference()
        c, theta_hat = model.controller, model.theta_hat
        e1, e2 = c.errors(x, v, ref)
        values = {"U": c.control(model.t, x, v, ref, theta_hat), "e1": e1, "e2": e2,
                  "V": c.lyapunov(e1, e2, theta_hat)}
        self._set_finite({**values, **dict(zip(ESTIMATE_NAMES, map(float, theta_hat)))})

    def do_step(self, current_time, step_size):
        return self._guarded_step(current_time, lambda: self._step(current_time, step_size))

    def _step(self, t, h):
        """theta^(t + h) = theta^(t) + the exact integral of the update law with the inputs held."""
        if not (np.isfinite(h) and h > 0.0):
            raise ParameterError("communicationStepSize", h, "must be a finite number > 0")
        if not (np.isfinite(t) and abs(t - self.model.t) <= TIME_TOLERANCE * max(1.0, abs(t))):
            raise ParameterError("currentCommunicationPoint", t, f"the controller is at tau = {self.model.t!r}")
        for name in INPUTS:
            if not np.isfinite(getattr(self, name)):
                raise ParameterError(name, getattr(self, name), "input must be a finite number")
        self.model.advance(t, h, float(self.x), float(self.v), self._reference())
        self._publish()


for _name in ESTIMATE_NAMES:  # the estimates' outputs, in the kernel's memory like the others
    setattr(AdaptiveLyapunovController, _name, fast_path.memory_variable(_name))
