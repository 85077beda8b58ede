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

import json
import math
import time
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException

from vibrofmu.hosts.run import FmuInstance, FmuLog, _reason

ORDERINGS = ("gauss-seidel", "jacobi", "fmpy")
SCENE_KEYS = {"stop_time", "step", "ordering", "tolerance", "connections", "fmu"}
FMU_KEYS = {"name", "path", "parameters"}


class SceneError(ValueError):
    """A scene file that cannot be run; the message names the file and the problem."""


@dataclass(frozen=True)
class FmuSpec:
    name: str
    path: Path
    parameters: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Connection:
    source: str  # FMU name
    output: str
    target: str
    input: str


@dataclass(frozen=True)
class CosimScene:
    fmus: tuple[FmuSpec, ...]
    connections: tuple[Connection, ...]
    step: float
    stop_time: float
    ordering: str = "gauss-seidel"
    tolerance: float | None = None

    def with_settings(self, step: float | None = None, ordering: str | None = None,
                      stop_time: float | None = None) -> "CosimScene":
        scene = replace(self, step=step or self.step, ordering=ordering or self.ordering,
                        stop_time=stop_time or self.stop_time)
        _check_numbers(scene, "settings")
        return scene


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
    """Read an SSP (.ssp, see ssp.py), TOML (.toml) or JSON scene. Relative FMU paths are resolved against the scene file's folder
    first, then against fmu_dir (the build folder)."""
    path = Path(path)
    if path.suffix == ".ssp":
        from vibrofmu.hosts.ssp import load_ssp
        return load_ssp(path)
    try:
        text = path.read_text()
    except OSError as error:
        raise SceneError(f"scene {path}: cannot read it ({error.strerror})") from None
    try:
        data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as error:
        raise SceneError(f"scene {path}: not valid {'TOML' if path.suffix == '.toml' else 'JSON'}: {error}") from None
    try:
        scene = parse_scene(data, path.parent, fmu_dir)
    except SceneError as error:
        raise SceneError(f"scene {path}: {error}") from None
    return scene


def parse_scene(data: dict, scene_dir: Path, fmu_dir: Path) -> CosimScene:
    if not isinstance(data, dict):
        raise SceneError("the scene must be a table (TOML) or an object (JSON)")
    _no_unknown(data, SCENE_KEYS, "the scene")
    for key in ("fmu", "connections", "step", "stop_time"):
        if key not in data:
            raise SceneError(f"missing '{key}'")
    fmus = tuple(_fmu_spec(i, entry, scene_dir, fmu_dir) for i, entry in enumerate(_list(data, "fmu")))
    names = [spec.name for spec in fmus]
    if len(set(names)) != len(names):
        raise SceneError(f"FMU names must be unique: {names}")
    connections = tuple(_connection(text, names) for text in _list(data, "connections"))
    scene = CosimScene(fmus=fmus, connections=connections, step=_number(data, "step"),
                       stop_time=_number(data, "stop_time"), ordering=data.get("ordering", "gauss-seidel"),
                       tolerance=_number(data, "tolerance") if "tolerance" in data else None)
    _check_numbers(scene, "the scene")
    return scene


def _check_numbers(scene: CosimScene, where: str) -> None:
    for key in ("step", "stop_time"):
        value = getattr(scene, key)
        if not (math.isfinite(value) and value > 0):
            raise SceneError(f"{where}: '{key}' = {value!r} must be a finite number > 0")
    if scene.ordering not in ORDERINGS:
        raise SceneError(f"{where}: 'ordering' = {scene.ordering!r}; known: {', '.join(ORDERINGS)}")
    if scene.tolerance is not None and not (math.isfinite(scene.tolerance) and scene.tolerance > 0):
        raise SceneError(f"{where}: 'tolerance' = {scene.tolerance!r} must be a finite number > 0")


def _no_unknown(table: dict, known: set, where: str) -> None:
    unknown = sorted(set(table) - known)
    if unknown:
        raise SceneError(f"unknown key '{unknown[0]}' in {where}; known: {', '.join(sorted(known))}")


def _list(data: dict, key: str) -> list:
    value = data[key]
    if not isinstance(value, list) or not value:
        raise SceneError(f"'{key}' must be a non-empty list")
    return value


def _number(data: dict, key: str) -> float:
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"'{key}' = {value!r} must be a number")
    return float(value)


def _fmu_spec(index: int, entry, scene_dir: Path, fmu_dir: Path) -> FmuSpec:
    where = f"fmu #{index + 1}"
    if not isinstance(entry, dict):
        raise SceneError(f"{where} must be a table with name, path, parameters")
    _no_unknown(entry, FMU_KEYS, where)
    for key in ("name", "path"):
        if not isinstance(entry.get(key), str) or not entry[key]:
            raise SceneError(f"{where}: '{key}' must be a non-empty string")
    name = entry["name"]
    candidates = [Path(entry["path"])] if Path(entry["path"]).is_absolute() else \
        [scene_dir / entry["path"], fmu_dir / entry["path"]]
    path = next((p for p in candidates if p.is_file()), None)
    if path is None:
        raise SceneError(f"FMU '{name}': no file {entry['path']} (looked in {', '.join(str(p) for p in candidates)};"
                         " `vibrofmu build` writes the FMUs to build/)")
    parameters = entry.get("parameters", {})
    if not isinstance(parameters, dict):
        raise SceneError(f"FMU '{name}': 'parameters' must be a table")
    variables = {v.name: v for v in read_model_description(str(path)).modelVariables}
    for key, value in parameters.items():
        if key not in variables or variables[key].causality not in ("parameter", "input"):
            raise SceneError(f"FMU '{name}': '{key}' is not a parameter of {path.name}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"FMU '{name}': parameter {key} = {value!r} must be a number")
    return FmuSpec(name=name, path=path, parameters=dict(parameters))


def _connection(text, names: list[str]) -> Connection:
    """'source.output -> target.input'."""
    if not isinstance(text, str) or text.count("->") != 1:
        raise SceneError(f"connection {text!r} must read 'source.output -> target.input'")
    ends = []
    for end in (part.strip() for part in text.split("->")):
        fmu, dot, variable = end.partition(".")
        if not dot or not variable:
            raise SceneError(f"connection {text!r}: '{end}' must read 'fmu.variable'")
        if fmu not in names:
            raise SceneError(f"connection {text!r}: no FMU named '{fmu}' (FMUs: {', '.join(names)})")
        ends.append((fmu, variable))
    return Connection(*ends[0], *ends[1])


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


def scene_fmu(scene: CosimScene, name: str) -> FmuSpec:
    return next(spec for spec in scene.fmus if spec.name == name)


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
            raise StepFailure(f"{name}: {_reason(error, self.log, name)}") from None

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
    wall_time = time.perf_counter() - t0
    log = {name: master.log.of(name) for name in master.instances}
    columns = master.columns
    master.close()
    data = np.array(rows, dtype=float).reshape(len(rows), len(columns))
    return CosimResult(time=np.array(times), outputs={c: data[:, j] for j, c in enumerate(columns)},
                       completed=stop_reason is None, stop_reason=stop_reason, log=log, wall_time=wall_time)


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
    wall_time = time.perf_counter() - t0
    log = {name: master.log.of(name) for name in master.instances}
    columns = master.columns
    master.close()
    data = np.array(rows, dtype=float).reshape(len(rows), len(columns))
    return CosimResult(time=np.array(times), outputs={c: data[:, j] for j, c in enumerate(columns)},
                       completed=stop_reason is None, stop_reason=stop_reason, log=log, wall_time=wall_time)
