"""Run a vibrofmu FMU from a host that is not Python: what it needs, and a check.

A pythonfmu FMU embeds a Python.  Its C layer (fmu_src/pyloader.c) finds that Python itself from the
environment recorded at build time (resources/python_env.txt: libpython, PYTHONHOME, the site-packages
holding numpy and scipy): on the building machine a C host needs no set-up at all, even when started with an
empty environment.  On another machine (or with another Python) the environment variable
VIBROFMU_PYTHON_ENV names an environment file of the same format, which `write_env_file` (`vibrofmu doctor
--env-file FILE --python PYTHON`) writes for a Python that has what the FMU imports.  A native FMU
(build/native/) needs nothing: it has no Python in it.

`check` proves it: it compiles the minimal C host (tests/c_host/fmi2_host.c), runs the FMU's default
experiment with it in an empty environment (plus VIBROFMU_PYTHON_ENV if set) and compares its outputs with
FMPy's `simulate_fmu` run of the same FMU.
"""
from __future__ import annotations

import os
import shlex
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu

from vibrofmu import paths
from vibrofmu.fmus import toolchain
from vibrofmu.fmus.pythonenv import ENV_FILE, ENV_VARIABLE, describe, env_text, imported_modules, missing, parse_env, record_for

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


def host_environment(resources: Path) -> dict[str, str]:
    """What a C host must add to an empty environment to run the FMU unpacked with these resources: nothing
    when the FMU records its Python (resources/python_env.txt) or has no Python; VIBROFMU_PYTHON_ENV when this
    process has it set (the user's override is passed on)."""
    override = os.environ.get(ENV_VARIABLE)
    return {ENV_VARIABLE: override} if override else {}


def recorded_environment(resources: Path) -> dict[str, str] | None:
    """The FMU's resources/python_env.txt as a dict (None: the FMU records no Python)."""
    path = Path(resources) / ENV_FILE
    return parse_env(path.read_text()) if path.is_file() else None


def write_env_file(out: Path, python: str | None = None, fmu: Path | None = None) -> dict:
    """Write the environment file (VIBROFMU_PYTHON_ENV) for `python` (default: this interpreter), for the modules
    `fmu` imports (default: those of the vibrofmu FMUs); returns the record. Raises RuntimeError when that Python
    lacks one of them (nothing is written)."""
    if fmu is not None:
        with tempfile.TemporaryDirectory() as tmp:
            unzip_dir = Path(extract(str(fmu), unzipdir=tmp))
            record = record_for(unzip_dir / "resources", python)
    else:  # the vibrofmu FMUs pack pythonfmu's Python part themselves
        record = describe([name for name in imported_modules(FMU_SRC) if name != "pythonfmu"], python)
    if missing(record):
        raise RuntimeError(f"{python or sys.executable} lacks {', '.join(missing(record))}: install it there "
                           f"(pip install {' '.join(missing(record))}) or name another Python with --python")
    from vibrofmu.output import export  # (matplotlib: only when writing)

    export.write_text(Path(out), env_text(record))  # atomic
    return record


def export_lines(env: dict[str, str]) -> str:
    if not env:
        return "# nothing to set: the FMU finds its Python itself (or has none)"
    return "\n".join(f"export {name}={shlex.quote(value)}" for name, value in env.items())


def compile_host(out_dir: Path) -> Path:
    return toolchain.compile_host(HOST_SOURCE, Path(out_dir) / "fmi2_host")


def compile_windows_host(out_dir: Path) -> Path:
    """The same host for Windows (mingw-w64), to run win64 binaries under wine."""
    host = Path(out_dir) / "fmi2_host.exe"
    cmd = [toolchain.WIN64_COMPILER, *toolchain.HOST_WIN64, *toolchain.host_includes(), "-o", str(host),
           str(HOST_SOURCE)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling the Windows C host failed ({' '.join(cmd)}):\n{proc.stderr}")
    return host


def run_host(host: Path, unzip_dir: Path, outputs: list[str], start: float, stop: float, step: float,
             parameters: dict[str, float] | None = None, env: dict[str, str] | None = None,
             wrapper: list[str] | None = None, timeout: float = 600) -> HostRun:
    """Run the C host on an unpacked FMU in an environment holding only `env` (as `env -i`); `wrapper`
    prefixes the command (e.g. valgrind)."""
    md = read_model_description(str(unzip_dir))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    library = Path(unzip_dir) / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    cmd = [*(wrapper or []), str(host), str(library), (Path(unzip_dir) / "resources").as_uri(), md.guid,
           repr(start), repr(stop), repr(step), ",".join(str(vr[n]) for n in outputs),
           *(f"{vr[name]}={value!r}" for name, value in (parameters or {}).items())]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                          env=dict(env or {}))
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
    result = _compare(run, reference, outputs)
    return env, CheckResult(result.ok, f"{result.message}; {python_summary(unzip_dir / 'resources')}")


def python_summary(resources: Path) -> str:
    """What the unpacked FMU needs of Python, in a few words."""
    recorded = recorded_environment(resources)
    if recorded is None:
        return "no Python recorded (a native FMU needs none)"
    return (f"its Python (resources/{ENV_FILE}): {recorded['python_version']} at {recorded['home']}, "
            f"{recorded['modules'] or 'no modules'}")
