"""The closed loop as an FMPy container FMU: the plant, the controller and the reference plant (the plant FMU at
fidelity 4, the OAFM analytic solution) packed into one FMU by `fmpy.container_fmu`.

The container (a compiled FMI 2.0 wrapper shipped with FMPy) instantiates the three FMUs from its resources and
steps them with a fixed internal step H (its `fixedStepSize`; a doStep must be a whole multiple of it):
each internal step, every FMU steps t -> t + H with its inputs held (Jacobi), then the connections are copied in
their listed order. The list here is reference -> controller, plant -> controller, then controller.U -> plant.U,
so U, which depends directly on the controller's inputs, is read after they were updated: the plant steps with
U(t_n) computed from x(t_n). This is the project's master's Jacobi ordering with the FMUs listed reference,
controller, plant (`master_scene`). At initialisation the container copies the connections before the FMUs
leave initialisation mode, i.e. from their start values (x = 0.04 from the plant's model description, not the
scene's x_start): the first step differs from the master's, which exchanges after initialisation.

`build_container(fmu_dir, out, H)` writes the container FMU, `run_container` runs it with FMPy; the comparison with
the monolithic closed-loop FMU and the master is analyses/container_check.py.
"""
from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from vibrofmu.fmus.archive import normalize_entries, publish, staging


CONTAINER_NAME = "HertzEAClosedLoopContainer"
DEFAULT_STEP = 0.1
STOP_TIME = 200.0
TOLERANCE = 1e-10  # rtol of the plant and of the reference, as the scene's setupExperiment tolerance
PLANT_START = {"x_start": 0.06, "v_start": 0.01}  # the closed-loop scene's plant (off the reference)
CONNECTIONS = (  # (source, output, target, input) in the order the container copies them
    ("reference", "x", "controller", "x_ref"),
    ("reference", "v", "controller", "v_ref"),
    ("reference", "a", "controller", "a_ref"),
    ("plant", "x", "controller", "x"),
    ("plant", "v", "controller", "v"),
    ("controller", "U", "plant", "U"),
)
# container outputs: (name, component, variable), the names of the monolithic closed-loop FMU; each output's
# description is its component variable's, with the component named
OUTPUTS = (("x", "plant", "x"), ("v", "plant", "v"), ("x_ref", "reference", "x"), ("U", "controller", "U"),
           ("e1", "controller", "e1"), ("e2", "controller", "e2"), ("V", "controller", "V"))
# container parameters: (name, type, start, [(component, variable)], description)
PARAMETERS = (
    ("x_start", "Real", PLANT_START["x_start"], [("plant", "x_start")], "plant initial displacement"),
    ("v_start", "Real", PLANT_START["v_start"], [("plant", "v_start")], "plant initial velocity"),
    ("rtol", "Real", TOLERANCE, [("plant", "rtol"), ("reference", "rtol")],
     "relative tolerance of the plant's and the reference's integrators"),
    ("law", "Integer", 0, [("controller", "law")], "control law: 0 paper-corrected, 1 damped, 2 paper-literal"),
    ("reference_fidelity", "Integer", 4, [("reference", "fidelity")],
     "fidelity of the reference plant: 4 = OAFM analytic solution (the reference generator)"),
)
FILES = {"reference": "HertzEAOscillator.fmu", "plant": "HertzEAOscillator.fmu",
         "controller": "AdaptiveLyapunovController.fmu"}


def build_container(fmu_dir: Path, out: Path, step: float = DEFAULT_STEP) -> Path:
    """Write the container FMU `out` from the plant and controller FMUs in fmu_dir; fixed step `step`."""
    from fmpy import read_model_description
    from fmpy.container_fmu.cli import create_container_fmu
    from fmpy.container_fmu.config import Component, Configuration, Connection
    from fmpy.model_description import CoSimulation, DefaultExperiment, ModelDescription, ModelVariable, Unknown

    fmu_dir, out = Path(fmu_dir), Path(out)
    components, variables = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, file in FILES.items():
            # each component needs its own copy: the container extracts resources/<file stem>/ per component
            copy = Path(tmp) / f"{name}.fmu"
            shutil.copyfile(fmu_dir / file, copy)
            md = read_model_description(str(copy))
            components[name] = Component(name=name, filename=copy, modelDescription=md)
            variables[name] = {v.name: v for v in md.modelVariables}
        time = ModelVariable(type="Real", variability="continuous", causality="independent", name="time",
                             description="time tau (dimensionless)")
        model_variables, mappings, outputs = [time], {}, []
        for name, kind, start, targets, description in PARAMETERS:
            v = ModelVariable(type=kind, variability="fixed", causality="parameter", initial="exact", name=name,
                              start=repr(start) if kind == "Real" else str(start), description=description)
            model_variables.append(v)
            mappings[v] = [(components[c], variables[c][var]) for c, var in targets]
        for name, component, variable in OUTPUTS:
            description = f"{variables[component][variable].description} (the {component} FMU's {variable})"
            v = ModelVariable(type="Real", variability="continuous", causality="output", initial="calculated",
                              name=name, description=description)
            model_variables.append(v)
            mappings[v] = [(components[component], variables[component][variable])]
            outputs.append(v)
        model_description = ModelDescription(
            fmiVersion="2.0", modelName=CONTAINER_NAME, instantiationToken="{" + CONTAINER_NAME + "}",
            description="Closed loop (plant + adaptive Lyapunov controller + OAFM reference plant) as an FMPy "
                        f"container FMU, fixed step {step:g}",
            generationTool="vibrofmu + fmpy.container_fmu",
            defaultExperiment=DefaultExperiment(startTime="0", stopTime=repr(STOP_TIME), stepSize=repr(step)),
            coSimulation=CoSimulation(modelIdentifier=CONTAINER_NAME, fixedInternalStepSize=step),
            modelVariables=model_variables,
        )
        model_description.outputs = [Unknown(index=model_variables.index(v) + 1, variable=v) for v in outputs]
        model_description.initialUnknowns = list(model_description.outputs)
        # fmpy 0.3.32 writes a connection's type as the component variable's ("Real"), which its container
        # binary does not know ("Float64"): the connectors are given as copies with the container's type name
        connections = [Connection(components[s], [_float64(variables[s][o])], components[t], [_float64(variables[t][i])])
                       for s, o, t, i in CONNECTIONS]
        configuration = Configuration(parallelDoStep=False, modelDescription=model_description,
                                      components=list(components.values()), connections=connections,
                                      variableMappings=mappings)
        unzip_dir = Path(tmp) / "container"
        unzip_dir.mkdir()
        with staging(out.parent) as stage:  # assembled beside out, moved to its name when complete
            staged = stage / out.name
            create_container_fmu(configuration, unzip_dir, staged.resolve())
            normalize_entries(staged)
            staged.chmod(0o644)
            return publish(staged, out)


def _float64(variable):
    import attrs

    return attrs.evolve(variable, type="Float64") if variable.type == "Real" else variable


def run_container(fmu: Path, step: float, stop_time: float = STOP_TIME) -> dict:
    """Run the container with FMPy's simulate_fmu at output interval `step` (its fixed step)."""
    import numpy as np
    from fmpy import simulate_fmu

    result = simulate_fmu(str(fmu), stop_time=stop_time, output_interval=step, step_size=step)
    return {name: np.asarray(result[name], dtype=float) for name in result.dtype.names}
