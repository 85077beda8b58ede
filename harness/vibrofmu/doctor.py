"""Run a pythonfmu FMU from a host that is not Python: the environment it needs, and a check.

A pythonfmu library embeds this machine's Python: a C host must load libpython (LD_PRELOAD, as
pythonfmu's library does not link it), point Python at its installation (PYTHONHOME) and at the
site-packages holding what the FMU imports (PYTHONPATH).  `check` proves the environment by
compiling the minimal C host (tests/c_host/fmi2_host.c), running the FMU's default experiment
with it, and comparing its outputs with FMPy's `simulate_fmu` run of the same FMU.
"""
from __future__ import annotations

import ast
import importlib.util
import os
import shlex
import subprocess
import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu

from . import paths

FMU_SRC = paths.FMU_SRC
HOST_SOURCE = paths.C_HOST_DIR / "fmi2_host.c"
# Both hosts run the same Python code on the same inputs with the same communication points, so
# the outputs should agree to the last bit; 1e-15 absolute is the agreed bound (about 10 ulp at
# the |x| ~ 0.04 of the paper example).
MATCH_TOLERANCE = 1e-15


@dataclass
class HostRun:
    returncode: int
    stderr: str
    time: np.ndarray
    outputs: dict[str, np.ndarray]  # name -> values, as far as the host got


@dataclass
class CheckResult:
    ok: bool
    message: str


def _site_dir(module: str) -> Path | None:
    """The sys.path entry a top-level module is imported from (None: unknown or not importable)."""
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        return None
    if spec is None or spec.origin in (None, "built-in", "frozen"):
        return None
    if spec.submodule_search_locations:
        return Path(spec.submodule_search_locations[0]).parent
    return Path(spec.origin).parent


def _imported_modules(resources: Path) -> set[str]:
    """Top-level modules imported by the FMU's Python files that are neither packed nor stdlib."""
    packed = {p.stem for p in resources.iterdir() if p.suffix == ".py" or (p / "__init__.py").exists()}
    names = set()
    for source in resources.rglob("*.py"):
        for node in ast.walk(ast.parse(source.read_bytes())):
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return names - packed - set(sys.stdlib_module_names)


def host_environment(resources: Path) -> dict[str, str]:
    """LD_PRELOAD, PYTHONHOME, PYTHONPATH for running the FMU unpacked with these resources."""
    libpython = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("INSTSONAME")
    sites = sorted({str(d) for d in map(_site_dir, _imported_modules(resources)) if d is not None})
    return {"LD_PRELOAD": str(libpython), "PYTHONHOME": sys.base_prefix, "PYTHONPATH": os.pathsep.join(sites)}


def export_lines(env: dict[str, str]) -> str:
    return "\n".join(f"export {name}={shlex.quote(value)}" for name, value in env.items())


def compile_host(out_dir: Path) -> Path:
    host = Path(out_dir) / "fmi2_host"
    cmd = [*paths.c_compiler(), "-O2", "-Wall", "-Wextra", f"-I{FMU_SRC}", "-o", str(host), str(HOST_SOURCE),
           "-ldl", "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling the C host failed ({' '.join(cmd)}):\n{proc.stderr}")
    return host


def run_host(host: Path, unzip_dir: Path, outputs: list[str], start: float, stop: float, step: float,
             parameters: dict[str, float] | None = None, env: dict[str, str] | None = None,
             wrapper: list[str] | None = None, timeout: float = 600) -> HostRun:
    """Run the C host on an unpacked FMU; `wrapper` prefixes the command (e.g. valgrind)."""
    md = read_model_description(str(unzip_dir))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    library = Path(unzip_dir) / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    cmd = [*(wrapper or []), str(host), str(library), (Path(unzip_dir) / "resources").as_uri(), md.guid,
           repr(start), repr(stop), repr(step), ",".join(str(vr[n]) for n in outputs),
           *(f"{vr[name]}={value!r}" for name, value in (parameters or {}).items())]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, **(env or {})})
    lines = proc.stdout.splitlines()
    data = np.array([[float(x) for x in line.split(",")] for line in lines[1:]]).reshape(-1, len(outputs) + 1)
    return HostRun(proc.returncode, proc.stderr, data[:, 0], {n: data[:, j + 1] for j, n in enumerate(outputs)})


def _compare(run: HostRun, reference: np.ndarray, outputs: list[str]) -> CheckResult:
    if not np.array_equal(run.time, reference["time"]):
        return CheckResult(False, f"the C host's time points differ from FMPy's "
                                  f"({len(run.time)} vs {len(reference['time'])} rows)")
    diffs = {n: float(np.max(np.abs(run.outputs[n] - reference[n]))) for n in outputs}
    worst = max(diffs, key=diffs.get)
    detail = ", ".join(f"{n} {d:.1e}" for n, d in diffs.items())
    if not diffs[worst] <= MATCH_TOLERANCE:
        return CheckResult(False, f"the C host's {worst} differs from FMPy's by {diffs[worst]:.3e} "
                                  f"> {MATCH_TOLERANCE:g} (max |diff|: {detail})")
    return CheckResult(True, f"the C host matches FMPy on {len(run.time)} rows, max |diff|: {detail}")


def check(fmu: Path, work_dir: Path) -> tuple[dict[str, str], CheckResult]:
    """Environment for `fmu`, and whether the C host run with it reproduces FMPy's run."""
    unzip_dir = Path(extract(str(fmu), unzipdir=str(Path(work_dir) / "fmu")))
    env = host_environment(unzip_dir / "resources")
    md = read_model_description(str(unzip_dir))
    experiment = md.defaultExperiment
    times = (experiment.startTime, experiment.stopTime, experiment.stepSize) if experiment else (None,)
    if None in times:
        return env, CheckResult(False, "the FMU's modelDescription.xml has no DefaultExperiment with "
                                       "startTime, stopTime and stepSize")
    start, stop, step = map(float, times)
    outputs = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    run = run_host(compile_host(work_dir), unzip_dir, outputs, start, stop, step, env=env)
    if run.returncode != 0:
        return env, CheckResult(False, f"the C host failed with exit code {run.returncode}: "
                                       f"{run.stderr.strip() or 'no message'}")
    reference = simulate_fmu(str(fmu), start_time=start, stop_time=stop, output_interval=step, output=outputs)
    return env, _compare(run, reference, outputs)
