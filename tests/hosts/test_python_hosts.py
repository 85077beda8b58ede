"""Issue 23, items 2 and 3: the FMUs in third-party Python FMI hosts, libcosimpy 0.0.6 (DNV's libcosim) and ecospy
0.7.2 (Vico's ecos), started by another interpreter in a venv with numpy and scipy and in one without.

A pythonfmu FMU in a Python host of the version it was built with adds the site-packages it recorded
(resources/python_env.txt, `path`) to the host's sys.path when numpy, scipy or pythonfmu do not import there
(fmu_src/pyloader.c); in a host of another version it fails at fmi2Instantiate with one line stating both versions
and naming the native FMU. The native FMUs need no Python.

The venvs are real (`python -m venv --without-pip`, their own sys.prefix); the host packages come from this
interpreter's installation (the `hosts` extra: pip install -e '.[test,hosts]') through a .pth file, so that no
test downloads anything: links to libcosimpy, and a copy of ecospy whose bundled programs (ecos, proxyfmu: the
wheel ships them without the executable bit) are made executable; ecospy's library needs Debian's libtbb12.
With numpy: links to numpy and scipy as well. pyenv gives the interpreters of other versions (3.12.1, 3.13.0).

Expected values: FMPy's FMU2Slave driving the same FMU in this process through the host's own communication points.
The same binary with the same inputs at the same points computes the same operations in the same order: the
same bits (0 difference, stronger than the issue's 1e-15). The hosts' points are not FMPy's `simulate_fmu`
grid (n·h): libcosim counts integer nanoseconds and steps from t = n·10⁸/10⁹ by (n+1)·10⁸/10⁹ − t; ecos
accumulates t += h (7e-12 off n·h at τ = 200); x then differs from simulate_fmu's by |ẋ|·δt (libcosimpy 2e-16,
ecospy 5e-14 on the paper scene, measured: docs/using-the-fmus-in-other-tools.md).

Default suite: libcosimpy in a venv without numpy on the pythonfmu plant (about 2 s), and two forged records (another
Python version; recorded folders without scipy), a fraction of a second each. The rest is slow: `python3 -m pytest -m slow tests/hosts/test_python_hosts.py`.
"""
from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from vibrofmu.fmus.pythonenv import ENV_FILE, ENV_VARIABLE, parse_env

DRIVERS = Path(__file__).with_name("python_host_drivers.py")
STOP, STEP = 200.0, 0.1  # the paper scene's run: τ ∈ [0, 200], communication step 0.1 (2,000 steps)
HOSTS = ("libcosimpy", "ecospy")
OTHER_PYTHONS = ("3.12.1", "3.13.0")  # pyenv versions
NAMES = ("plant", "controller", "closed_loop")


def _installed(name: str) -> Path:
    spec = importlib.util.find_spec(name)
    assert spec is not None and spec.submodule_search_locations, (
        f"{name} is not installed in {sys.executable}: pip install -e '.[test,hosts]' (pyproject's hosts extra)")
    return Path(list(spec.submodule_search_locations)[0])


@pytest.fixture(scope="session")
def libcosim_packages(tmp_path_factory) -> Path:
    """A folder with libcosimpy (a link): the default suite's host, installed by the test extra."""
    folder = tmp_path_factory.mktemp("libcosim_packages")
    (folder / "libcosimpy").symlink_to(_installed("libcosimpy"))
    return folder


@pytest.fixture(scope="session")
def host_packages(tmp_path_factory) -> Path:
    """A folder with libcosimpy (a link) and ecospy (a copy, its programs executable): the slow tests' hosts (the
    hosts extra)."""
    folder = tmp_path_factory.mktemp("host_packages")
    (folder / "libcosimpy").symlink_to(_installed("libcosimpy"))
    ecospy = folder / "ecospy"
    shutil.copytree(_installed("ecospy"), ecospy, ignore=shutil.ignore_patterns("__pycache__"))
    for program in ("ecos", "proxyfmu"):
        (ecospy / "binaries" / program).chmod(0o755)
    return folder


@pytest.fixture(scope="session")
def numpy_packages(tmp_path_factory) -> Path:
    """A folder with links to this Python's numpy and scipy (and their libraries)."""
    folder = tmp_path_factory.mktemp("numpy_packages")
    for name in ("numpy", "scipy"):
        home = _installed(name).parent
        for entry in home.iterdir():
            if entry.name == name or entry.name.startswith((f"{name}.libs", f"{name}-")):
                (folder / entry.name).symlink_to(entry)
    return folder


def make_venv(python: str, folder: Path, *sites: Path) -> Path:
    """A venv of `python` in folder whose site-packages also reads `sites` (a .pth file); its interpreter."""
    subprocess.run([python, "-m", "venv", "--without-pip", str(folder)], check=True, capture_output=True)
    interpreter = folder / "bin" / "python"
    site = subprocess.run([str(interpreter), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                          check=True, capture_output=True, text=True).stdout.strip()
    Path(site, "vibrofmu_hosts.pth").write_text("".join(f"{s}\n" for s in sites))
    return interpreter


def pyenv_python(version: str) -> str:
    pyenv = shutil.which("pyenv")
    assert pyenv, f"pyenv is not on PATH: this test runs the hosts in Python {version} from pyenv"
    proc = subprocess.run([pyenv, "prefix", version], capture_output=True, text=True)
    assert proc.returncode == 0, f"pyenv has no Python {version} (pyenv install {version}): {proc.stderr.strip()}"
    return str(Path(proc.stdout.strip()) / "bin" / "python3")


def _bare_venv(folder: Path, packages: Path) -> Path:
    """A venv of this Python with the host packages in `packages` and no numpy, scipy or pythonfmu."""
    python = make_venv(sys.executable, folder, packages)
    for name in ("numpy", "scipy", "pythonfmu"):
        probe = subprocess.run([str(python), "-c", f"import {name}"], capture_output=True)
        assert probe.returncode != 0, f"the bare venv imports {name}"
    return python


@pytest.fixture(scope="session")
def bare_venv(host_packages, tmp_path_factory) -> Path:
    """Both hosts, no numpy, scipy or pythonfmu (the slow tests)."""
    return _bare_venv(tmp_path_factory.mktemp("venv") / "bare", host_packages)


@pytest.fixture(scope="session")
def libcosim_venv(libcosim_packages, tmp_path_factory) -> Path:
    """libcosimpy alone, no numpy, scipy or pythonfmu (the default suite: it needs only the test extra)."""
    return _bare_venv(tmp_path_factory.mktemp("venv") / "libcosim", libcosim_packages)


@pytest.fixture(scope="session")
def numpy_venv(host_packages, numpy_packages, tmp_path_factory) -> Path:
    python = make_venv(sys.executable, tmp_path_factory.mktemp("venv") / "numpy", host_packages, numpy_packages)
    assert subprocess.run([str(python), "-c", "import numpy, scipy"], capture_output=True).returncode == 0
    return python


def outputs_of(fmu: Path) -> list[str]:
    md = read_model_description(str(fmu))
    return [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]


def run_host(python: Path | str, host: str, fmu: Path, outputs: list[str], env: dict | None = None):
    """(process, {"time": [...], "values": {...}} or None)."""
    proc = subprocess.run([str(python), str(DRIVERS), host, str(fmu), repr(STOP), repr(STEP), *outputs],
                          capture_output=True, text=True, timeout=600, env=env, cwd=fmu.parent)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    return proc, (json.loads(lines[-1]) if proc.returncode == 0 and lines else None)


def host_points(host: str, n: int) -> tuple[list[float], list[float]]:
    """The (communication point, step size) of each doStep the host makes (see the module's text)."""
    if host == "libcosimpy":
        ns = round(STEP * 1e9)
        t = [i * ns / 1e9 for i in range(n + 1)]
        return t[:-1], [t[i + 1] - t[i] for i in range(n)]
    t = [0.0]
    for _ in range(n - 1):
        t.append(t[-1] + STEP)
    return t, [STEP] * n


def fmpy_on_points(fmu: Path, outputs: list[str], points, steps, tmp_path: Path) -> dict[str, np.ndarray]:
    """The outputs after each doStep(points[i], steps[i]), FMPy loading the FMU in this process."""
    md = read_model_description(str(fmu))
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = extract(str(fmu), unzipdir=str(tmp_path / "fmpy"))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="fmpy")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    rows = []
    for t, h in zip(points, steps):
        slave.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        rows.append(slave.getReal([vrs[name] for name in outputs]))
    slave.terminate()
    slave.freeInstance()
    return {name: np.array([row[i] for row in rows]) for i, name in enumerate(outputs)}


def check_same_as_fmpy(host: str, data: dict, fmu: Path, outputs: list[str], tmp_path: Path) -> None:
    n = round(STOP / STEP)
    assert data is not None and len(data["time"]) == n, "the host did not run the 2,000 steps"
    points, steps = host_points(host, n)
    # the host's clock is what host_points says (ecos reports it; libcosim's is the driver's i·10⁸·10⁻⁹)
    if host == "ecospy":
        np.testing.assert_array_equal(data["time"][:-1], points[1:])
    expected = fmpy_on_points(fmu, outputs, points, steps, tmp_path)
    for name in outputs:  # same binary, same inputs, same points: the same bits (module's text)
        np.testing.assert_array_equal(np.array(data["values"][name]), expected[name], err_msg=f"{host} {name}")


def one_line(stderr: str, fmu_id: str) -> list[str]:
    """The lines of stderr carrying the FMU's message (the raw line and any host log line quoting it)."""
    return [line for line in stderr.splitlines() if f"this FMU ({fmu_id}, pythonfmu)" in line]


def check_refusal(proc, fmu_id: str, needed: str, found: str) -> None:
    """The one line: both versions, the native FMU named, written once raw on stderr (a host may show FMU log lines
    at its debug level only: ecos does). What the host does next is its own: libcosimpy 0.0.6 dereferences the NULL
    instance (a segfault), ecospy 0.7.2 steps on with no instance (outputs 0)."""
    raw = [line for line in one_line(proc.stderr, fmu_id) if line.startswith("vibrofmu: ")]
    assert len(raw) == 1, proc.stderr[-3000:]
    line = raw[0]
    assert f"needs Python {needed} " in line and f"host runs Python {found}" in line, line
    # the native FMU named where `vibrofmu build` writes it, beside this one (not ./build/native: built anywhere)
    assert f"native FMU {fmu_id}.fmu from the native/ folder" in line and "build/native" not in line, line
    assert ENV_VARIABLE not in line, line
    assert "Traceback" not in proc.stderr


# ---- default suite ----

def test_libcosimpy_without_numpy_runs_the_pythonfmu_plant(libcosim_venv, plant_fmu, tmp_path):
    """The issue's failure: libcosimpy in a venv without numpy got NULL from fmi2Instantiate (then crashed). Now
    the FMU imports numpy and scipy from the folders it recorded and runs the paper scene, bit-equal to FMPy."""
    outputs = outputs_of(plant_fmu)
    proc, data = run_host(libcosim_venv, "libcosimpy", plant_fmu, outputs)
    assert proc.returncode == 0, proc.stderr[-3000:]
    check_same_as_fmpy("libcosimpy", data, plant_fmu, outputs, tmp_path)


def test_a_python_host_of_another_version_gets_one_line(libcosim_venv, plant_fmu, plant_unzipped, tmp_path):
    """The record says the FMU was built by Python 3.10 (VIBROFMU_PYTHON_ENV replaces resources/python_env.txt,
    in a Python host too): fmi2Instantiate fails with the one line; the real other versions are the slow test
    below."""
    record = (Path(plant_unzipped) / "resources" / ENV_FILE).read_text()
    assert parse_env(record)["python_version"] == "%d.%d" % sys.version_info[:2]
    forged = tmp_path / ENV_FILE
    forged.write_text(record.replace(f"python_version={sys.version_info[0]}.{sys.version_info[1]}\n",
                                     "python_version=3.10\n"))
    env = {"PATH": "/usr/bin:/bin", ENV_VARIABLE: str(forged)}
    proc, _ = run_host(libcosim_venv, "libcosimpy", plant_fmu, ["x"], env=env)
    found = "%d.%d.%d" % sys.version_info[:3]
    check_refusal(proc, "HertzEAOscillator", "3.10", found)
    # libcosim shows the FMU's log at its default level, on stdout: the same line, with status error
    logged = one_line(proc.stdout, "HertzEAOscillator")
    assert len(logged) == 1 and "[error]" in logged[0] and "status=error" in logged[0], proc.stdout[-3000:]


def test_a_module_missing_from_host_and_record_is_one_line(libcosim_venv, plant_unzipped, plant_fmu, tmp_path):
    """The host's version, but scipy neither in the host nor in the recorded folders (a record whose `path` holds
    numpy only): one line naming scipy, the host's Python and the native FMU."""
    site = tmp_path / "numpy_only"
    site.mkdir()
    home = _installed("numpy").parent
    for entry in home.iterdir():
        if entry.name == "numpy" or entry.name.startswith(("numpy.libs", "numpy-")):
            (site / entry.name).symlink_to(entry)
    record = parse_env((Path(plant_unzipped) / "resources" / ENV_FILE).read_text())
    forged = tmp_path / ENV_FILE
    forged.write_text("".join(f"{key}={site if key == 'path' else value}\n" for key, value in record.items()))
    proc, _ = run_host(libcosim_venv, "libcosimpy", plant_fmu, ["x"], env={"PATH": "/usr/bin:/bin",
                                                                         ENV_VARIABLE: str(forged)})
    raw = [line for line in proc.stderr.splitlines() if line.startswith("vibrofmu: ")]
    assert len(raw) == 1, proc.stderr[-3000:]
    assert raw[0].startswith("vibrofmu: scipy is missing") and "No module named 'scipy'" in raw[0], raw[0]
    assert "the host's Python %d.%d.%d" % sys.version_info[:3] in raw[0] and str(site) in raw[0], raw[0]
    assert "native FMU HertzEAOscillator.fmu from the native/ folder" in raw[0] and "build/native" not in raw[0]
    assert "Traceback" not in proc.stderr


# ---- slow: every FMU in both hosts, with and without numpy, and in other Pythons ----

@pytest.mark.slow
@pytest.mark.fmu  # asks for its FMU by name
@pytest.mark.parametrize("with_numpy", [False, True], ids=["without_numpy", "with_numpy"])
@pytest.mark.parametrize("native", [False, True], ids=["pythonfmu", "native"])
@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("host", HOSTS)
def test_every_fmu_in_every_python_host(host, name, native, with_numpy, request, tmp_path):
    fmu = Path(request.getfixturevalue(f"native_{name}_fmu" if native else f"{name}_fmu"))
    python = request.getfixturevalue("numpy_venv" if with_numpy else "bare_venv")
    outputs = outputs_of(fmu)
    proc, data = run_host(python, host, fmu, outputs)
    assert proc.returncode == 0, proc.stderr[-3000:]
    check_same_as_fmpy(host, data, fmu, outputs, tmp_path)


@pytest.mark.slow
@pytest.mark.fmu  # asks for its FMU by name
@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("host", HOSTS)
@pytest.mark.parametrize("version", OTHER_PYTHONS)
def test_a_host_of_another_python_refuses_the_pythonfmu_fmu_and_runs_the_native_one(
        version, host, name, request, host_packages, tmp_path):
    python = make_venv(pyenv_python(version), tmp_path / "venv", host_packages)
    fmu, native = (Path(request.getfixturevalue(f"{prefix}{name}_fmu")) for prefix in ("", "native_"))
    fmu_id = read_model_description(str(fmu)).coSimulation.modelIdentifier
    proc, _ = run_host(python, host, fmu, outputs_of(fmu))
    check_refusal(proc, fmu_id, "%d.%d" % sys.version_info[:2], version)
    outputs = outputs_of(native)
    proc, data = run_host(python, host, native, outputs)
    assert proc.returncode == 0, proc.stderr[-3000:]
    check_same_as_fmpy(host, data, native, outputs, tmp_path)
