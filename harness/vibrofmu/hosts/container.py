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

`build_container(fmu_dir, out, H)` writes the container FMU; `compare(fmu_dir, steps)` runs it beside the
monolithic closed-loop FMU and the master and returns max |x_container - x| per H.
"""
from __future__ import annotations

import shutil
import tempfile
from dataclasses import replace
from pathlib import Path


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
# container outputs: (name, component, variable, description); the names of the monolithic closed-loop FMU
OUTPUTS = (
    ("x", "plant", "x", "plant displacement x (dimensionless)"),
    ("v", "plant", "v", "plant velocity x' (dimensionless)"),
    ("x_ref", "reference", "x", "reference x~ (the plant FMU at fidelity 4: OAFM analytic solution)"),
    ("U", "controller", "U", "control force U"),
    ("e1", "controller", "e1", "tracking error e1 = x - x~"),
    ("e2", "controller", "e2", "filtered error e2 = x' - x~' + c e1"),
    ("V", "controller", "V", "Lyapunov function V"),
)
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
        for name, component, variable, description in OUTPUTS:
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
        out.parent.mkdir(parents=True, exist_ok=True)
        if out.exists():
            out.unlink()
        create_container_fmu(configuration, unzip_dir, out.resolve())
    out.chmod(0o644)
    return out


def _float64(variable):
    import attrs

    return attrs.evolve(variable, type="Float64") if variable.type == "Real" else variable


def run_container(fmu: Path, step: float, stop_time: float = STOP_TIME) -> dict:
    """Run the container with FMPy's simulate_fmu at output interval `step` (its fixed step)."""
    import numpy as np
    from fmpy import simulate_fmu

    result = simulate_fmu(str(fmu), stop_time=stop_time, output_interval=step, step_size=step)
    return {name: np.asarray(result[name], dtype=float) for name in result.dtype.names}


def master_scene(fmu_dir: Path, step: float, stop_time: float = STOP_TIME):
    """The container's loop as a scene of the project's master: FMUs in the order reference, controller, plant;
    Jacobi; the same parameters and tolerance."""
    from vibrofmu.cli import DEFAULT_SCENE
    from vibrofmu.hosts.cosim import load_scene

    scene = load_scene(DEFAULT_SCENE, Path(fmu_dir))
    specs = {spec.name: spec for spec in scene.fmus}
    fmus = tuple(specs[name] for name in ("reference", "controller", "plant"))
    return replace(scene, fmus=fmus, step=step, stop_time=stop_time, ordering="jacobi", tolerance=TOLERANCE)


def _with_rtol(scene):
    """The scene with rtol as a parameter of the plant and the reference instead of setupExperiment's tolerance
    (as in the container)."""
    fmus = tuple(replace(spec, parameters={**spec.parameters, "rtol": TOLERANCE}) if spec.name != "controller"
                 else spec for spec in scene.fmus)
    return replace(scene, fmus=fmus, tolerance=None)


def run_master_like_container(scene) -> dict:
    """The container's call sequence on the project's master instances: parameters, setupExperiment (stop time,
    no tolerance) and enterInitializationMode for every FMU, the connections copied in CONNECTIONS' order while
    the FMUs are still in initialisation mode, exitInitializationMode; then per step: every FMU steps (Jacobi),
    the connections are copied in order. Returns {"time", "x", "x_ref"} at the communication points."""
    import numpy as np

    from vibrofmu.hosts.cosim import Master

    master = Master(scene)
    inst = master.instances

    def copy_connections():
        for source, output, target, input_ in CONNECTIONS:
            value = inst[source].fmu.getReal(inst[source].value_references([output]))[0]
            inst[target].set({input_: value})

    try:
        for spec in scene.fmus:
            inst[spec.name].set(spec.parameters)
            inst[spec.name].fmu.setupExperiment(startTime=0.0, stopTime=scene.stop_time)
            inst[spec.name].fmu.enterInitializationMode()
        copy_connections()
        for spec in scene.fmus:
            inst[spec.name].fmu.exitInitializationMode()
        n = int(round(scene.stop_time / scene.step))
        read = lambda: (inst["plant"].fmu.getReal(inst["plant"].value_references(["x"]))[0],
                        inst["reference"].fmu.getReal(inst["reference"].value_references(["x"]))[0])
        times, xs, refs = [0.0], *([v] for v in read())
        t = 0.0
        for i in range(n):
            for name in inst:
                inst[name].fmu.doStep(currentCommunicationPoint=t, communicationStepSize=scene.step)
            copy_connections()
            t += scene.step  # the container's clock: time += fixedStepSize
            x, ref = read()
            times.append(t), xs.append(x), refs.append(ref)
    finally:
        master.close()
    return {"time": np.array(times), "x": np.array(xs), "x_ref": np.array(refs)}


def compare(fmu_dir: Path, steps=(0.1, 0.05, 0.01), stop_time: float = STOP_TIME, work_dir: Path | None = None) -> list[dict]:
    """max |x_container - x| against the monolithic closed-loop FMU and against the master (Jacobi, same order),
    at the communication points, for each H."""
    import numpy as np

    from vibrofmu.analyses import closed_loop
    from vibrofmu.hosts.cosim import run_cosim

    fmu_dir = Path(fmu_dir)
    work_dir = Path(work_dir or tempfile.mkdtemp(prefix="vibrofmu_container_"))
    rows = []
    for H in steps:
        container = run_container(build_container(fmu_dir, work_dir / f"{CONTAINER_NAME}_{H:g}.fmu", H), H,
                                  stop_time)
        scene = master_scene(fmu_dir, H, stop_time)
        master = run_cosim(scene)
        mono = closed_loop.monolithic(fmu_dir / "HertzEAClosedLoop.fmu", closed_loop.monolithic_equivalent(scene),
                                      stop_time, H)
        twin = run_master_like_container(_with_rtol(scene))
        n = min(len(container["x"]), len(master.time), len(mono["time"]), len(twin["x"]))
        x = container["x"][:n]
        rows.append({
            "H": H, "points": n,
            "vs_master_container_sequence": float(np.max(np.abs(x - twin["x"][:n]))),
            "vs_master": float(np.max(np.abs(x - master.outputs["plant.x"][:n]))),
            "vs_monolithic": float(np.max(np.abs(x - mono["series"]["x"][:n]))),
            "master_vs_monolithic": float(np.max(np.abs(master.outputs["plant.x"][:n] - mono["series"]["x"][:n]))),
            "x_ref_vs_master": float(np.max(np.abs(container["x_ref"][:n] - master.outputs["reference.x"][:n]))),
        })
    return rows


def table_lines(rows: list[dict]) -> list[str]:
    """max |Δx| over the run, per H, as a Markdown table."""
    lines = ["| H | container − master, container's call sequence | container − master (Jacobi, same order) "
             "| container − monolithic FMU | master − monolithic FMU |",
             "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['H']:g} | {r['vs_master_container_sequence']:.1e} | {r['vs_master']:.2e} "
                     f"| {r['vs_monolithic']:.2e} | {r['master_vs_monolithic']:.2e} |")
    return lines




def add_parser(sub) -> None:
    """`vibrofmu container`: the closed loop as an FMPy container FMU (hooked into cli.py)."""
    p = sub.add_parser("container", help="write the closed loop as an FMPy container FMU "
                                         f"(default: build/{CONTAINER_NAME}.fmu)")
    p.add_argument("--fmu-dir", default=None, help="where the FMUs are (default: build/; built when missing)")
    p.add_argument("--out-dir", default=None, help="where to write the container (default: the FMU folder)")
    p.add_argument("--H", type=float, default=DEFAULT_STEP, help=f"fixed communication step (default {DEFAULT_STEP})")
    p.add_argument("--compare", type=float, nargs="*", default=None, metavar="H",
                   help="compare with the monolithic FMU and the master at these H (default: no comparison; "
                        "no value: 0.1 0.05 0.01)")
    p.set_defaults(func=cmd_container)


def cmd_container(args) -> int:
    import math
    import sys

    from vibrofmu.fmus.build import build_all
    from vibrofmu.hosts.ssp import default_build_dir

    steps = tuple(args.compare or (0.1, 0.05, 0.01)) if args.compare is not None else ()
    for H in (args.H, *steps):
        if not (math.isfinite(H) and H > 0 and abs(STOP_TIME / H - round(STOP_TIME / H)) < 1e-9):
            print(f"error: H = {H!r} must be > 0 and divide the stop time {STOP_TIME:g}", file=sys.stderr)
            return 2
    fmu_dir = Path(args.fmu_dir or default_build_dir())
    if not all((fmu_dir / name).exists() for name in set(FILES.values()) | {"HertzEAClosedLoop.fmu"}):
        print(f"building the FMUs into {fmu_dir} ...", file=sys.stderr)
        build_all(fmu_dir)
    out = build_container(fmu_dir, Path(args.out_dir or fmu_dir) / f"{CONTAINER_NAME}.fmu", args.H)
    print(f"wrote {out}")
    if steps:
        for line in table_lines(compare(fmu_dir, steps)):
            print(line)
    return 0
