"""Co-simulation master on FMPy's FMU2Slave: several FMUs connected output -> input, fixed communication step H.

Scene files (TOML or JSON) list the FMUs in order, their parameters, the connections, H, the stop time, the
ordering and the tolerance given to setupExperiment; `load_scene` checks them against the FMUs' model
descriptions and raises SceneError naming the problem.

At each communication point t_n the master sweeps the connections in the FMUs' order (each FMU's inputs from
its sources' current outputs: an output that depends directly on inputs, like the controller's U, is then
up to date) and records every output. Then:
- Jacobi: every FMU steps t_n -> t_n + H with those inputs;
- Gauss-Seidel: the FMUs step one after another in the listed order, each first taking its inputs from the
  sources' newest outputs (already at t_n + H for the sources that stepped before it).
- fmpy: FMPy's `fmpy.ssp.simulation.simulate_ssp` loop, reproduced call for call: setupExperiment without
  tolerance or stop time, parameters before enterInitializationMode; every input starts at 0; each step every
  FMU takes its inputs from the values the connections carried after the previous step (outputs read right
  after each FMU's doStep, so an output with direct feedthrough, like the controller's U, is one step late),
  and time advances by t += H while t < stop_time. Its rows are the values after each step, at t + H.
Inputs are held constant over a step (zero-order hold), so the coupling error is O(H).
A doStep that fails stops the run: the result keeps what was computed and says which FMU stopped and why,
with its log message.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from fmpy.fmi1 import FMICallException

from vibrofmu.hosts.run import FmuInstance, FmuLog, call_failure_reason
from vibrofmu.hosts.scene import (ORDERINGS, Connection, CosimScene, FmuSpec, SceneError, read_scene,  # noqa: F401
                                  scene_fmu)
from vibrofmu.hosts.ssp import load_ssp

# the scene's types are scene.py's; cosim.py re-exports them for the master's callers (ORDERINGS, CosimScene ...)


@dataclass
class CosimResult:
    time: np.ndarray
    outputs: dict[str, np.ndarray]  # "fmu.variable" -> values at the communication points
    completed: bool
    stop_reason: str | None
    log: dict[str, list[str]]
    wall_time: float


# ------------------------------------------------------------------------------------------- scene files

def load_scene(path: Path | str, fmu_dir: Path) -> CosimScene:
    """Read an SSP (.ssp, see ssp.py), TOML (.toml) or JSON scene (scene.read_scene). Relative FMU paths are resolved
    against the scene file's folder first, then against fmu_dir (the build folder)."""
    if Path(path).suffix == ".ssp":
        return load_ssp(path)
    return read_scene(path, fmu_dir)


def check_connections(scene: CosimScene, instances: dict[str, FmuInstance]) -> None:
    """Every connection joins an output to an input, and no input is driven twice."""
    driven = set()
    for c in scene.connections:
        for fmu, variable, causality in ((c.source, c.output, "output"), (c.target, c.input, "input")):
            found = instances[fmu].variables.get(variable)
            if found is None or found.causality != causality:
                raise SceneError(f"connection {c.source}.{c.output} -> {c.target}.{c.input}: "
                                 f"{fmu}.{variable} is not an {causality} of {scene_fmu(scene, fmu).path.name}")
        if (c.target, c.input) in driven:
            raise SceneError(f"input {c.target}.{c.input} is connected twice")
        driven.add((c.target, c.input))


# ------------------------------------------------------------------------------------------- the master

class Master:
    """The instances of a scene, their exchange and stepping."""

    def __init__(self, scene: CosimScene):
        self.scene = scene
        self.log = FmuLog()  # one for all: FMPy's logger proxy is process-wide
        self.instances = {spec.name: FmuInstance(spec.path, spec.name, self.log) for spec in scene.fmus}
        try:
            check_connections(scene, self.instances)
        except SceneError:
            self.close()
            raise
        self.inputs_of = {spec.name: [c for c in scene.connections if c.target == spec.name] for spec in scene.fmus}
        self.columns = [f"{name}.{v}" for name, inst in self.instances.items() for v in inst.output_columns()]

    def initialise(self) -> None:
        for spec in self.scene.fmus:
            fmu = self.instances[spec.name].fmu
            self._call(spec.name, lambda: fmu.setupExperiment(tolerance=self.scene.tolerance, startTime=0.0,
                                                              stopTime=self.scene.stop_time))
            self._call(spec.name, fmu.enterInitializationMode)
            self._call(spec.name, lambda: self.instances[spec.name].set(spec.parameters))
            self._call(spec.name, fmu.exitInitializationMode)

    def _call(self, name, function):
        try:
            function()
        except FMICallException as error:
            raise StepFailure(f"{name}: {call_failure_reason(error, self.log, name)}") from None

    def take_inputs(self, name: str) -> None:
        """Set an FMU's inputs from its sources' current outputs."""
        for c in self.inputs_of[name]:
            source = self.instances[c.source]
            value = source.fmu.getReal(source.value_references([c.output]))[0]
            self._call(name, lambda: self.instances[name].set({c.input: value}))

    def exchange(self) -> None:
        for name in self.instances:
            self.take_inputs(name)

    def read(self) -> list[float]:
        return [value for inst in self.instances.values() for value in inst.read_outputs()]

    def step(self, t: float, h: float) -> None:
        for name, inst in self.instances.items():
            if self.scene.ordering == "gauss-seidel":
                self.take_inputs(name)
            self._call(name, lambda: inst.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h))

    def close(self) -> None:
        for inst in self.instances.values():
            inst.close()


class StepFailure(RuntimeError):
    """An FMU call failed; the message names the FMU and carries its log message."""


def _finish(master: Master, times: list, rows: list, stop_reason: str | None, t0: float) -> CosimResult:
    """Close `master` and gather its rows and logs into a CosimResult (timed from perf_counter `t0`)."""
    wall_time = time.perf_counter() - t0
    log = {name: master.log.of(name) for name in master.instances}
    columns = master.columns
    master.close()
    data = np.array(rows, dtype=float).reshape(len(rows), len(columns))
    return CosimResult(time=np.array(times), outputs={c: data[:, j] for j, c in enumerate(columns)},
                       completed=stop_reason is None, stop_reason=stop_reason, log=log, wall_time=wall_time)


def run_cosim(scene: CosimScene, progress=None) -> CosimResult:
    """Simulate the scene from 0 to stop_time with communication step scene.step."""
    if scene.ordering == "fmpy":
        return _run_fmpy_ordering(scene, progress)
    master = Master(scene)
    n_steps = int(round(scene.stop_time / scene.step))
    times, rows, stop_reason = [], [], None
    t0 = time.perf_counter()
    try:
        master.initialise()
        for i in range(n_steps + 1):
            t = i * scene.step
            master.exchange()
            times.append(t)
            rows.append(master.read())
            if i == n_steps:
                break
            master.step(t, scene.step)
            if progress is not None:
                progress(i + 1, n_steps)
    except StepFailure as failure:
        stop_reason = f"stopped at tau = {times[-1] if times else 0.0:g}: {failure}"
    return _finish(master, times, rows, stop_reason, t0)


def _run_fmpy_ordering(scene: CosimScene, progress=None) -> CosimResult:
    """The loop of FMPy 0.3.32's simulate_ssp (see the module's docstring), on the project's instances."""
    master = Master(scene)
    held = {(c.target, c.input): 0.0 for c in scene.connections}
    times, rows, stop_reason = [], [], None
    n_steps = int(math.ceil(scene.stop_time / scene.step))
    t0 = time.perf_counter()
    t = 0.0
    try:
        for spec in scene.fmus:
            inst = master.instances[spec.name]
            master._call(spec.name, lambda: inst.fmu.setupExperiment(startTime=0.0))
            master._call(spec.name, lambda: inst.set(spec.parameters))
            master._call(spec.name, inst.fmu.enterInitializationMode)
            master._call(spec.name, inst.fmu.exitInitializationMode)
        while t < scene.stop_time:
            for name, inst in master.instances.items():
                for c in master.inputs_of[name]:
                    master._call(name, lambda: inst.set({c.input: held[(c.target, c.input)]}))
                master._call(name, lambda: inst.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=scene.step))
            for c in scene.connections:
                source = master.instances[c.source]
                held[(c.target, c.input)] = source.fmu.getReal(source.value_references([c.output]))[0]
            times.append(t + scene.step)
            rows.append(master.read())
            t += scene.step
            if progress is not None:
                progress(len(times), n_steps)
    except StepFailure as failure:
        stop_reason = f"stopped at tau = {t:g}: {failure}"
    return _finish(master, times, rows, stop_reason, t0)
