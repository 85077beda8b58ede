"""FMI 2.0 co-simulation slave of the plant (DESIGN.md contract): FMI variables <-> vibromodel.Plant.

No physics here; the FMI error handling, the rules for setting variables and the FMU state are
slave_support.StatusSlave's. The state's model part is the plant's snapshot (integrator included); the
plant itself is rebuilt from the parameters on restore.
"""
from pythonfmu import Boolean, DefaultExperiment, Fmi2Causality, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Initial

from slave_support import StatusSlave
from vibromodel.analytic import OafmSettings
from vibromodel.parameters import Scene, scene_names
from vibromodel.plant import DEFAULT_EXPERIMENT, Plant, Settings

OUTPUTS = ("x", "v", "a", "F_contact", "F_electrostatic")


class HertzEAOscillator(StatusSlave):
    author = "vibrofmu"
    description = "Hertzian-contact oscillator with two-sided electrostatic actuation (PAPER Eq. 3, ERRATA §3.1)"
    default_experiment = DefaultExperiment(*DEFAULT_EXPERIMENT)
    state_format = "HertzEAOscillator state 2"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        scene, settings, oafm = Scene(), Settings(), OafmSettings()
        for name in scene_names():
            self._parameter(Real, name, getattr(scene, name))
        self._parameter(Integer, "fidelity", int(settings.fidelity),
                        "0 exact Eq. 3, 1 polynomial Eq. 7, 2 Eq. 7 printed coefficients, 3 averaged slow flow, "
                        "4 OAFM analytic")
        self._parameter(Integer, "solver", int(settings.solver), "0 adaptive DOP853, 1 fixed-step RK4")
        self._parameter(Real, "rtol", settings.rtol, "relative tolerance (setupExperiment's tolerance wins)")
        self._parameter(Real, "max_step", settings.max_step, "RK4 step / adaptive step ceiling; 0 = automatic")
        self._parameter(Integer, "oafm_order", oafm.order, "fidelity 4: order of the harmonic OAFM basis")
        self._parameter(Real, "tau_star", oafm.tau_star, "fidelity 4: end of the transient domain; 0 = automatic")
        self._parameter(Real, "oafm_tau_end", oafm.tau_end,
                        "fidelity 4: end of the fit; 0 = automatic, at least the stop time")
        self.U = 0.0
        self.register_variable(Real("U", causality=Fmi2Causality.input, description="control force"))
        self._outputs(OUTPUTS, (scene.x_start, scene.v_start, 0.0, 0.0, 0.0))
        self.in_contact = True
        self.register_variable(Boolean("in_contact", causality=Fmi2Causality.output,
                                       variability=Fmi2Variability.discrete, initial=Fmi2Initial.exact))

    def _make_model(self):
        """The plant of the current parameters and experiment; raises ParameterError for bad ones."""
        scene = Scene(**{name: float(getattr(self, name)) for name in scene_names()})
        rtol = self.rtol if self.experiment_tolerance is None else self.experiment_tolerance
        oafm = OafmSettings(order=int(self.oafm_order), tau_star=float(self.tau_star),
                            tau_end=float(self.oafm_tau_end))
        settings = Settings(fidelity=int(self.fidelity), solver=int(self.solver),
                            rtol=float(rtol), max_step=float(self.max_step), oafm=oafm)
        return Plant(scene, settings, t0=float(self.start_time), stop_time=self.stop_time,
                     cache_dirs=self._cache_dirs())

    def do_step(self, current_time, step_size):
        return self._guarded_step(
            current_time, lambda: self._publish(self.model.do_step(current_time, step_size, float(self.U))),
            lambda error: self._publish(self.model.outputs_at(error.t, error.x, error.v)))

    def _publish(self, out):
        self._set_finite({**dict(zip(OUTPUTS, (out.x, out.v, out.a, out.F_contact, out.F_electrostatic))),
                          "in_contact": out.in_contact})
