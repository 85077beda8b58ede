"""The container FMU checked against the project's own co-simulation master and the monolithic closed-loop FMU
(`vibrofmu container --compare`, the report's container block); the container itself is hosts/container.py.

`compare(fmu_dir, steps)` runs the container beside the monolithic closed-loop FMU and the master and returns
max |x_container - x| per H; `run_master_like_container` repeats the container's call sequence on the master's
instances, which separates the container's ordering from FMPy's wrapper.
"""
from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path

from vibrofmu.hosts.container import CONNECTIONS, CONTAINER_NAME, STOP_TIME, TOLERANCE, build_container, run_container


def master_scene(fmu_dir: Path, step: float, stop_time: float = STOP_TIME):
    """The container's loop as a scene of the project's master: FMUs in the order reference, controller, plant;
    Jacobi; the same parameters and tolerance."""
    from vibrofmu.paths import DEFAULT_SCENE
    from vibrofmu.hosts.cosim import load_scene

    scene = load_scene(DEFAULT_SCENE, Path(fmu_dir))
    specs = {spec.name: spec for spec in scene.fmus}
    fmus = tuple(specs[name] for name in ("reference", "controller", "plant"))
    return replace(scene, fmus=fmus, step=step, stop_time=stop_time, ordering="jacobi", tolerance=TOLERANCE)


def with_rtol(scene):
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

        def read():
            return (inst["plant"].fmu.getReal(inst["plant"].value_references(["x"]))[0],
                    inst["reference"].fmu.getReal(inst["reference"].value_references(["x"]))[0])

        times, xs, refs = [0.0], *([v] for v in read())
        t = 0.0
        for _ in range(n):
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
        twin = run_master_like_container(with_rtol(scene))
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
