"""The speed-accuracy ladder of `vibrofmu bench`: cost per output and error of x of every rung a user can pick.

A rung is one FMU configuration: exact f0 (Eq. 3, C kernel), polynomial f1, averaged f3, analytic f4, RK4 at
h = 0.01 (fidelity 0), and the closed-loop FMU (plant + adaptive controller). Each runs the paper example over
tau in [0, stop] in two hosts:
  - a plain C FMI host (timing_host.c, compiled here; the pythonfmu binary gets `vibrofmu doctor`'s
    environment: libpython preloaded, PYTHONHOME, PYTHONPATH), at output intervals 0.1 and 1;
  - FMPy in this process, at output interval 1.
The cost per output is the wall time of the doStep + getReal(x) loop divided by the outputs, best of
`repeats` runs from fresh instances. The error of x is the largest |x - x_ref| on the output grid: for the
plant's rungs against the exact model's reference (DOP853, rtol 1e-13); for the closed loop against the
closed loop itself run in vibromodel at rtol 1e-12 (its x is a different trajectory: the plant under control).
"""
from __future__ import annotations

import math
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description

from vibromodel.integrate import ATOL_PER_RTOL
from vibromodel.models import Fidelity
from vibromodel.parameters import Scene

from . import paths
from .doctor import host_environment
from .reference import reference_solution
from .run import FmuInstance

TIMING_HOST_SOURCE = Path(__file__).with_name("timing_host.c")
FMU_SRC = paths.FMU_SRC  # the checkout's fmu_src/ or the installed vibrofmu/fmu_src/
REFERENCE_RTOL = 1e-13
CLOSED_LOOP_REFERENCE_RTOL = 1e-12
C_INTERVALS = (0.1, 1.0)
FMPY_INTERVAL = 1.0
BASE = "exact f0"
RUNGS = (  # (name, FMU, start values)
    (BASE, "plant", {}),
    ("polynomial f1", "plant", {"fidelity": 1}),
    ("averaged f3", "plant", {"fidelity": 3}),
    ("analytic f4", "plant", {"fidelity": 4}),
    ("RK4 h = 0.01", "plant", {"solver": 1, "max_step": 0.01}),
    ("closed loop", "closed_loop", {}),
)
# issue 13's acceptance: cost per output of a rung over exact f0's, at most
LIMITS = {"averaged f3": 0.5, "analytic f4": 0.5, "RK4 h = 0.01": 4.0, "closed loop": 3.0}


def compile_timing_host(out_dir: Path) -> Path:
    host = Path(out_dir) / "timing_host"
    cmd = [*paths.c_compiler(), "-O2", "-Wall", "-Wextra", f"-I{FMU_SRC}", "-o", str(host), str(TIMING_HOST_SOURCE), "-ldl", "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling the timing host failed ({' '.join(cmd)}):\n{proc.stderr}")
    return host


def host_run(host: Path, unzip_dir: Path, start: dict, stop: float, step: float, repeats: int) -> dict:
    """One rung in the C host: {"loop": [seconds per run], "init": [...], "t": grid, "x": x of the last run}."""
    md = read_model_description(str(unzip_dir))
    variables = {v.name: v for v in md.modelVariables}
    library = Path(unzip_dir) / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    arguments = [("i" if variables[name].type == "Integer" else "r") + f"{variables[name].valueReference}={value!r}"
                 for name, value in start.items()]
    cmd = [str(host), str(library), (Path(unzip_dir) / "resources").as_uri(), md.guid, repr(stop), repr(step),
           str(repeats), str(variables["x"].valueReference), *arguments]
    env = {**os.environ, **host_environment(Path(unzip_dir) / "resources")}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1800)
    if proc.returncode != 0:
        raise RuntimeError(f"timing host failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
    record = {"loop": [], "init": [], "t": [], "x": []}
    for line in proc.stdout.splitlines():
        kind, *values = line.split()
        if kind == "init":
            record["init"].append(float(values[0]))
        elif kind == "loop":
            record["loop"].append(float(values[0]))
            record["outputs"] = int(values[1])
        elif kind == "x":
            record["t"].append(float(values[0]))
            record["x"].append(float(values[1]))
    record["t"], record["x"] = np.array(record["t"]), np.array(record["x"])
    return record


def fmpy_run(fmu: Path, unzip_dir: str, start: dict, stop: float, step: float, repeats: int) -> dict:
    """One rung under FMPy in this process, the same loop as the C host's."""
    record = {"loop": [], "init": [], "t": None, "x": None}
    n = len(communication_points(stop, step))
    for _ in range(repeats):
        started = time.perf_counter()
        with FmuInstance(fmu, instance_name="ladder", unzip_dir=unzip_dir) as instance:
            f = instance.fmu
            f.setupExperiment(startTime=0.0, stopTime=stop)
            f.enterInitializationMode()
            instance.set(start)
            f.exitInitializationMode()
            refs = instance.value_references(["x"])
            xs = np.empty(n)
            points = communication_points(stop, step)
            do_step, get_real = f.doStep, f.getReal
            loop_started = time.perf_counter()
            t = 0.0
            for i, next_t in enumerate(points):
                do_step(t, next_t - t)
                xs[i] = get_real(refs)[0]
                t = next_t
            finished = time.perf_counter()
        record["init"].append(loop_started - started)
        record["loop"].append(finished - loop_started)
    record["t"], record["x"], record["outputs"] = np.array(points), xs, n
    return record


def communication_points(stop: float, step: float) -> list[float]:
    """n step for n = 1, 2, ..., the last clipped to stop: timing_host.c's points (and FMPy's simulate_fmu's)."""
    points, n, t = [], 1, 0.0
    while not (t > stop or math.isclose(t, stop)):
        t = n * step
        if t > stop and not math.isclose(t, stop):
            t = stop
        points.append(t)
        n += 1
    return points


def closed_loop_reference(stop: float):
    """x of the closed loop with the FMU's defaults, run in vibromodel at rtol 1e-12, as a function of the grid."""
    from vibromodel.closedloop import ERRATA_SCENE, ClosedLoop, LoopSettings
    from vibromodel.plant import Settings

    loop = ClosedLoop(ERRATA_SCENE, Settings(rtol=CLOSED_LOOP_REFERENCE_RTOL), LoopSettings(), 0.0, stop)
    step = min(C_INTERVALS)
    n = int(round(stop / step))
    xs = np.array([loop.do_step(i * step, step)["x"] for i in range(n)])
    grid = step * np.arange(1, n + 1)

    def at(t):
        index = np.rint(np.asarray(t) / step).astype(int) - 1
        if not np.allclose(grid[index], t, rtol=1e-9, atol=0.0):
            raise ValueError("the closed loop's reference is on the 0.1 grid only")
        return xs[index]

    return at


def run_ladder(plant_fmu: Path, closed_loop_fmu: Path, stop: float = 200.0, repeats: int = 3,
               progress=None) -> dict:
    """Every rung in both hosts: the ladder's record for bench.json (see the module docstring)."""
    say = progress or (lambda line: None)
    scene = Scene()
    exact = reference_solution(scene, Fidelity.EXACT, stop, rtol=REFERENCE_RTOL, atol=ATOL_PER_RTOL * REFERENCE_RTOL)
    references = {"plant": lambda t: exact(t)[0], "closed_loop": closed_loop_reference(stop)}
    fmus = {"plant": Path(plant_fmu), "closed_loop": Path(closed_loop_fmu)}
    columns = [("C host", interval) for interval in C_INTERVALS] + [("FMPy", FMPY_INTERVAL)]
    rungs = []
    with tempfile.TemporaryDirectory(prefix="vibrofmu-ladder-") as work:
        host = compile_timing_host(Path(work))
        unzipped = {name: extract(str(path), str(Path(work) / name)) for name, path in fmus.items()}
        for name, which, start in RUNGS:
            rung = {"rung": name, "fmu": which, "start_values": start, "columns": []}
            for host_name, interval in columns:
                if host_name == "C host":
                    run = host_run(host, Path(unzipped[which]), start, stop, interval, repeats)
                else:
                    run = fmpy_run(fmus[which], unzipped[which], start, stop, interval, repeats)
                error = float(np.max(np.abs(run["x"] - references[which](run["t"]))))
                best = min(run["loop"])
                rung["columns"].append({
                    "host": host_name, "interval": interval, "outputs": run["outputs"],
                    "cost_per_output_seconds": best / run["outputs"],
                    "loop_seconds_runs": run["loop"], "instantiation_seconds_runs": run["init"],
                    "instantiation_warm_seconds": min(run["init"][1:] or run["init"]),
                    "linf_x": error})
                say(f"ladder: {name}, {host_name} interval {interval:g}: {1e6 * best / run['outputs']:.3g} us per "
                    f"output, max |x error| {error:.2e}")
            rungs.append(rung)
    base = {(c["host"], c["interval"]): c["cost_per_output_seconds"] for c in rungs[0]["columns"]}
    for rung in rungs:
        for column in rung["columns"]:
            column["over_exact_f0"] = column["cost_per_output_seconds"] / base[column["host"], column["interval"]]
    acceptance = [{"rung": r["rung"], "host": c["host"], "interval": c["interval"], "ratio": c["over_exact_f0"],
                   "limit": LIMITS[r["rung"]], "met": c["over_exact_f0"] <= LIMITS[r["rung"]]}
                  for r in rungs if r["rung"] in LIMITS for c in r["columns"]
                  if (c["host"], c["interval"]) in (("C host", 0.1), ("FMPy", FMPY_INTERVAL))]
    return {"stop_time": stop, "repeats": repeats, "scene": scene.as_dict(),
            "timing": "cost per output = wall time of the doStep + getReal(x) loop / outputs, minimum over the runs "
                      "(each from a fresh instance); instantiation = instantiate .. exitInitializationMode (the C "
                      "host's first run also starts the embedded Python)",
            "errors": f"max |x - x_ref| on the output grid; plant rungs against the exact model (DOP853 rtol "
                      f"{REFERENCE_RTOL:g}), the closed loop against itself in vibromodel at rtol "
                      f"{CLOSED_LOOP_REFERENCE_RTOL:g}",
            "rungs": rungs, "acceptance": acceptance}


def ladder_lines(ladder: dict) -> list[str]:
    """The ladder as a table and the acceptance ratios, for the command's output."""
    columns = [(c["host"], c["interval"]) for c in ladder["rungs"][0]["columns"]]
    head = "  rung            " + "".join(f"{h} {i:g}".rjust(26) for h, i in columns)
    lines = [f"speed-accuracy ladder (paper example, tau in [0, {ladder['stop_time']:g}], best of "
             f"{ladder['repeats']}; us per output, x error):", head]
    for rung in ladder["rungs"]:
        cells = "".join(f"{1e6 * c['cost_per_output_seconds']:9.3g} us {c['over_exact_f0']:5.2g}x {c['linf_x']:7.1e}"
                        .rjust(26) for c in rung["columns"])
        lines.append(f"  {rung['rung']:<16}{cells}")
    for a in ladder["acceptance"]:
        lines.append(f"  {a['rung']} / exact f0 ({a['host']}, interval {a['interval']:g}): {a['ratio']:.3g} "
                     f"(limit {a['limit']:g}: {'met' if a['met'] else 'NOT met'})")
    return lines


def plot_ladder(path: Path, ladder: dict) -> None:
    """Error of x against cost per output, one marker per rung, one panel per host and interval."""
    from . import export

    plt = export.plt
    columns = [(c["host"], c["interval"]) for c in ladder["rungs"][0]["columns"]]
    fig, axes = plt.subplots(1, len(columns), figsize=(6 * len(columns), 5), squeeze=False)
    markers = "osD^vP*X"
    for ax, (host, interval) in zip(axes[0], columns):
        for k, rung in enumerate(ladder["rungs"]):
            c = next(c for c in rung["columns"] if (c["host"], c["interval"]) == (host, interval))
            ax.loglog(1e6 * c["cost_per_output_seconds"], max(c["linf_x"], 1e-17), markers[k % len(markers)],
                      ms=9, label=rung["rung"])
            ax.annotate(rung["rung"], (1e6 * c["cost_per_output_seconds"], max(c["linf_x"], 1e-17)),
                        textcoords="offset points", xytext=(6, 4), fontsize=8)
        ax.set_xlabel("cost per output: doStep + getReal(x) [us]")
        ax.set_ylabel("max |x - x_ref| on the output grid")
        ax.set_title(f"{host}, output interval {interval:g}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.suptitle(f"Speed-accuracy ladder, paper example, tau in [0, {ladder['stop_time']:g}]: pick a rung")
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
