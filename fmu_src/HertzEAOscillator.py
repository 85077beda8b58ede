"""FMI 2.0 co-simulation slave of the plant (DESIGN.md contract): FMI variables <-> vibromodel.Plant.

No physics here. No Python exception may leave a callback (pythonfmu turns it into fmi2Fatal and
destroys the instance): errors are logged with the parameter and value, `fmi_status` is set to 3 and
the status shim (fmu_src/fmi2_status_shim.c) returns fmi2Error to the host.
"""
import math
from pathlib import Path

from pythonfmu import Boolean, DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Initial, Fmi2Status

from vibromodel.analytic import OafmSettings
from vibromodel.integrate import IntegrationError
from vibromodel.parameters import ParameterError, Scene, scene_names
from vibromodel.plant import DEFAULT_EXPERIMENT, Plant, Settings

STATUS_OK, STATUS_ERROR = 0, 3
OUTPUTS = ("x", "v", "a", "F_contact", "F_electrostatic")


class HertzEAOscillator(Fmi2Slave):
    author = "vibrofmu"
    description = "Hertzian-contact oscillator with two-sided electrostatic actuation (PAPER Eq. 3, ERRATA §3.1)"
    default_experiment = DefaultExperiment(*DEFAULT_EXPERIMENT)

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
        self._set_outputs(scene.x_start, scene.v_start, 0.0, 0.0, 0.0, True)
        for name in OUTPUTS:
            self.register_variable(Real(name, causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        self.register_variable(Boolean("in_contact", causality=Fmi2Causality.output,
                                       variability=Fmi2Variability.discrete, initial=Fmi2Initial.exact))
        self.fmi_status = STATUS_OK
        self.register_variable(Integer("fmi_status", causality=Fmi2Causality.local,
                                       variability=Fmi2Variability.discrete,
                                       description="0 ok, 3 error (read by the status shim)"))
        self.plant = None
        self.halted = "the FMU has not been initialised"  # why doStep refuses, or None
        self.start_time, self.stop_time, self.experiment_tolerance = 0.0, None, None

    def _parameter(self, kind, name, value, description=None):
        """A fixed parameter with its start value."""
        setattr(self, name, value)
        self.register_variable(kind(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                                    description=description))

    def _set_outputs(self, x, v, a, F_contact, F_electrostatic, in_contact):
        self.x, self.v, self.a = x, v, a
        self.F_contact, self.F_electrostatic, self.in_contact = F_contact, F_electrostatic, in_contact

    def _error(self, message):
        self.fmi_status = STATUS_ERROR
        self.log(message, Fmi2Status.error)

    def _halt(self, message):
        self.halted = message
        self._error(message)

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self.start_time, self.stop_time = start_time, stop_time
        self.experiment_tolerance = tolerance

    def exit_initialization_mode(self):
        try:
            scene = Scene(**{name: float(getattr(self, name)) for name in scene_names()})
            rtol = self.rtol if self.experiment_tolerance is None else self.experiment_tolerance
            oafm = OafmSettings(order=int(self.oafm_order), tau_star=float(self.tau_star),
                                tau_end=float(self.oafm_tau_end))
            settings = Settings(fidelity=int(self.fidelity), solver=int(self.solver),
                                rtol=float(rtol), max_step=float(self.max_step), oafm=oafm)
            self.plant = Plant(scene, settings, t0=float(self.start_time), stop_time=self.stop_time,
                               cache_dirs=self._cache_dirs())
            for note in self.plant.notes:
                self.log(note, Fmi2Status.ok)
            self._publish(self.plant.outputs())
            self.halted = None
        except ParameterError as error:
            self._halt(f"{error}")
        except Exception as error:  # never let an exception reach pythonfmu (fmi2Fatal)
            self._halt(f"initialisation failed: {error!r}")

    def _cache_dirs(self):
        """OAFM solutions packed at build time (resources/oafm_cache)."""
        return (Path(self.resources) / "oafm_cache",) if self.resources else ()

    def do_step(self, current_time, step_size):
        if self.halted is not None:
            self._error(f"doStep refused: {self.halted}")
            return False
        try:
            self._publish(self.plant.do_step(current_time, step_size, float(self.U)))
            return True
        except ParameterError as error:
            self._error(f"doStep refused: {error}")
        except IntegrationError as error:
            self._publish(self.plant.outputs_at(error.t, error.x, error.v))
            self._halt(f"simulation stopped: {error}")
        except Exception as error:
            self._halt(f"doStep failed at tau = {current_time!r}: {error!r}")
        return False

    def _publish(self, out):
        values = (out.x, out.v, out.a, out.F_contact, out.F_electrostatic)
        if all(math.isfinite(value) for value in values):
            self._set_outputs(*values, out.in_contact)
