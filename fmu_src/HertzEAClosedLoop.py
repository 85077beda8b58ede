"""FMI 2.0 co-simulation slave of plant + adaptive controller + reference in one FMU (the contract in docs/fmu-reference.md):
FMI variables <-> vibromodel.closedloop.ClosedLoop. The plant, the nine estimates and the reference are
integrated together by the plant's integrators (adaptive DOP853 or RK4, `solver`).
No physics here; the FMI error handling and the FMU state are slave_support.StatusSlave's; the state's model
part is ClosedLoop.snapshot() (integrator with the estimates), the loop is rebuilt from the parameters.

On the compiled kernel (parameter kernel = 0; vibromodel.compiled_loop.CompiledClosedLoop on
fmu_src/core/closedloop.c) the outputs live in the kernel's memory and the model state is the kernel structure's
state bytes: the status shim's fast path (fast_path.py) runs doStep and answers the output getters without Python.
"""
from pathlib import Path

from pythonfmu import DefaultExperiment, Integer, Real

import fast_path

fast_path.use_packed_packages(Path(__file__).parent)  # before any vibromodel import
from slave_support import StatusSlave
from vibromodel.closedloop import ERRATA_SCENE, LoopSettings
from vibromodel.compiled import load_library
from vibromodel.compiled_loop import make_closed_loop
from vibromodel.control import ESTIMATE_NAMES
from vibromodel.fidelities import description, integrated
from vibromodel.plant import DEFAULT_EXPERIMENT, Settings
from vibromodel.tracking import ReferenceSettings

OUTPUTS = ("x", "v", "x_ref", "U", "e1", "e2", "V", "V_rate", "V_rate_promised")


class HertzEAClosedLoop(fast_path.CompiledModelSlave, StatusSlave):
    author = "vibrofmu"
    description = "Hertzian-contact oscillator under adaptive Lyapunov tracking control, monolithic (corrected laws: docs/model.md)"
    default_experiment = DefaultExperiment(*DEFAULT_EXPERIMENT)
    state_format = "HertzEAClosedLoop state 2"
    MEMORY = FAST_OUTPUTS = OUTPUTS + ESTIMATE_NAMES

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        scene, settings, reference = ERRATA_SCENE, Settings(), ReferenceSettings()
        self._plant_parameters(scene, settings, f"plant: {description(integrated())}")  # "plant: 0 exact Eq. 3, ..."
        self._parameter(Integer, "reference", int(reference.kind),
                        "0 OAFM analytic solution, 1 the corrected closed form x0 + X_f cos(w t - psi), 2 the same + tones "
                        "(persistent excitation)")
        self._parameter(Real, "x_ref_start", reference.x_start, "reference's initial x")
        self._parameter(Real, "v_ref_start", reference.v_start, "reference's initial x'")
        self._controller_parameters()
        self._parameter(Integer, "kernel", 0, "0 compiled C closed loop (pure Python where it is missing), 1 pure Python")
        self._outputs(OUTPUTS, (scene.x_start, scene.v_start) + (0.0,) * (len(OUTPUTS) - 2))
        self._outputs(ESTIMATE_NAMES, [getattr(self, f"{name}_start") for name in ESTIMATE_NAMES], "estimate")

    def _make_model(self):
        """The closed loop of the current parameters and experiment; raises ParameterError for bad ones."""
        scene, settings = self._plant_values()
        law, gains, estimates = self._controller_settings()
        reference = ReferenceSettings(kind=int(self.reference), x_start=float(self.x_ref_start),
                                      v_start=float(self.v_ref_start))
        loop = LoopSettings(law=law, gains=gains, estimates=estimates, reference=reference)
        library, reason = load_library((Path(self.resources),) if self.resources else ())
        return make_closed_loop(scene, settings, loop, float(self.start_time), self.stop_time, self._cache_dirs(),
                                (library, reason))

    def do_step(self, current_time, step_size):
        return self._guarded_step(current_time, lambda: self._publish(self.model.do_step(current_time, step_size)))

    def _publish(self, out):
        self._set_finite({**{name: out[name] for name in OUTPUTS}, **dict(zip(ESTIMATE_NAMES, out["estimates"]))})


for _name in HertzEAClosedLoop.MEMORY:  # the outputs, in the kernel's memory when it runs the loop
    setattr(HertzEAClosedLoop, _name, fast_path.memory_variable(_name))
