"""Packaging: the wheel works from any folder; the build without a C compiler; the FMU files themselves
(descriptions, units, validation, file mode)."""
import glob
import os
import shutil
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from vibrofmu.hosts.run import run_fmu

REPOSITORY = Path(__file__).resolve().parents[2]
# what a fresh clone does not have: copied trees leave it out (any virtual environment, by its usual names, and the
# tools' caches; symbolic links are copied as links, never followed, so a link to a venv elsewhere costs nothing --
# one such link once made each CI copy 1.3 GB and filled the disk)
NOT_IN_A_CLONE = shutil.ignore_patterns(".git", ".venv*", "venv", ".setuptools-build", "*.egg-info", "__pycache__",
                                        ".benchmarks", ".pytest_cache", ".ruff_cache", ".import_linter_cache", "out",
                                        "ci-python-*.log")


def build_wheel(tmp_path: Path) -> subprocess.CompletedProcess:
    """`pip wheel` into tmp_path/dist from a copy of the checkout (without its ./build): setuptools builds in the
    source tree (setup.py's build_base), so two wheel builds at once -- pytest-xdist workers, CI's Python
    versions side by side -- must not share one tree."""
    source = tmp_path / "source"
    shutil.copytree(REPOSITORY, source, symlinks=True, ignore=lambda folder, names: NOT_IN_A_CLONE(folder, names) | (
        {"build"} if Path(folder) == REPOSITORY else set()))
    return subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"),
                           str(source)], capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def all_fmus(plant_fmu, controller_fmu, closed_loop_fmu):
    return plant_fmu, controller_fmu, closed_loop_fmu


def test_every_variable_has_a_description_and_every_real_the_unit_1(all_fmus):
    for fmu in all_fmus:
        md = read_model_description(str(fmu))
        assert [u.name for u in md.unitDefinitions] == ["1"]
        for variable in md.modelVariables:
            assert variable.description and variable.description.strip(), (fmu.name, variable.name)
            assert variable.unit == ("1" if variable.type == "Real" else None), (fmu.name, variable.name)


def test_fmus_validate_silently_and_are_readable_by_all(all_fmus):
    for fmu in all_fmus:
        assert validate_fmu(str(fmu)) == []
        assert stat.S_IMODE(fmu.stat().st_mode) == 0o644


def test_build_without_a_c_compiler(tmp_path, plant_fmu):
    """No $CC and no cc/gcc on PATH: the plant FMU is built without the kernel and without the status shim,
    `build` says so in one line, and the FMU computes the same numbers (the kernel is bit-identical to the
    Python plant, so the outputs must be equal, not close)."""
    env = {k: v for k, v in os.environ.items() if k != "CC"}
    env["PATH"] = str(tmp_path / "empty")  # no programs at all: sys.executable is called by its full path
    proc = subprocess.run([sys.executable, "-m", "vibrofmu.cli", "build", "--out-dir", "fmus"], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    warnings = [line for line in proc.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "without their compiled parts" in warnings[0]
    fmu = tmp_path / "fmus" / "HertzEAOscillator.fmu"
    with zipfile.ZipFile(fmu) as archive:
        names = archive.namelist()
    assert "binaries/linux64/HertzEAOscillator.so" in names
    assert not any(name.endswith(("_pythonfmu.so", "vibrokernel.so")) for name in names)
    assert validate_fmu(str(fmu)) == []
    python_only = run_fmu(fmu, {}, 20.0, 0.1)
    compiled = run_fmu(plant_fmu, {}, 20.0, 0.1)
    assert python_only.completed and compiled.completed
    # bit identity is free: the compiled kernel performs the pure-Python plant's operations in the same order
    # (-ffp-contract=off, no -ffast-math; tests/core/test_plant_kernel.py checks it case by case)
    assert np.array_equal(python_only.outputs["x"], compiled.outputs["x"])


# slow tier: a wheel build and a whole `vibrofmu build` (kernel included) of its own, one of the default suite's
# longest tests; test_wheel_installs_and_builds_anywhere below checks more (the wheel installed into a fresh venv,
# then build and demo from an unrelated folder), and CI runs it for Python 3.12 and 3.13
@pytest.mark.slow
@pytest.mark.fmu  # builds the FMUs
def test_the_wheel_alone_builds_the_fmus(tmp_path):
    """The wheel's files suffice: unpacked, and imported without this checkout (python -S: no .pth files, so
    not the editable install; the dependencies from this venv's site-packages), `vibrofmu build` makes
    the three FMUs from the files in the wheel (a file the build reads that the wheel lacks fails here)."""
    built = build_wheel(tmp_path)
    assert built.returncode == 0, built.stderr
    site = tmp_path / "site"
    with zipfile.ZipFile(next((tmp_path / "dist").glob("*.whl"))) as wheel:
        wheel.extractall(site)
    dependencies = [p for p in sys.path if p.endswith("site-packages")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), *dependencies])}
    work = tmp_path / "work"
    work.mkdir()
    where = subprocess.run([sys.executable, "-S", "-c", "import vibrofmu.paths as p; print(p.FMU_SRC, p.C_HOST_DIR)"],
                           cwd=work, env=env, capture_output=True, text=True, check=True)
    assert all(Path(folder).is_relative_to(site) for folder in where.stdout.split())
    proc = subprocess.run([sys.executable, "-S", "-m", "vibrofmu.cli", "build", "--out-dir", "X"], cwd=work, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    for name in ("HertzEAOscillator.fmu", "AdaptiveLyapunovController.fmu", "HertzEAClosedLoop.fmu"):
        assert validate_fmu(str(work / "X" / name)) == []


@pytest.mark.slow
def test_wheel_installs_and_builds_anywhere(tmp_path):
    """`pip wheel .`, the wheel into a fresh venv, then from an unrelated folder `vibrofmu build --out-dir X`
    and `vibrofmu demo` (which builds its plant FMU into ./build). $VIBROFMU_WHEEL_PYTHON picks the
    interpreter of the venv (default: this one), so CI runs the same test for 3.12 and 3.13."""
    python = os.environ.get("VIBROFMU_WHEEL_PYTHON", sys.executable)

    def run(cmd, cwd=tmp_path):
        return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=1800)

    wheel = build_wheel(tmp_path)
    assert wheel.returncode == 0, wheel.stderr
    venv = tmp_path / "venv"
    assert run([python, "-m", "venv", str(venv)]).returncode == 0
    install = run([str(venv / "bin" / "pip"), "install", "-q", *glob.glob(str(tmp_path / "dist" / "*.whl"))])
    assert install.returncode == 0, install.stderr
    work = tmp_path / "x"
    work.mkdir()
    vibrofmu = str(venv / "bin" / "vibrofmu")
    # --no-win64: the native FMUs' win64 DLLs do not depend on the Python (the tools tier builds and runs them); left
    # out, this build compiles half as much
    built = run([vibrofmu, "build", "--out-dir", "X", "--no-win64"], cwd=work)
    assert built.returncode == 0, built.stderr
    names = ("HertzEAOscillator.fmu", "AdaptiveLyapunovController.fmu", "HertzEAClosedLoop.fmu")
    for name in names:
        assert f"built {Path('X') / name}" in built.stdout
        assert validate_fmu(str(work / "X" / name)) == []
        with zipfile.ZipFile(work / "X" / "native" / name) as native:
            platforms = {entry.split("/")[1] for entry in native.namelist() if entry.startswith("binaries/")}
        assert platforms == {"linux64"}, platforms
    demo = run([vibrofmu, "demo"], cwd=work)
    assert demo.returncode == 0, demo.stderr
    assert (work / "build" / names[0]).is_file() and (work / "out" / "demo" / "x.png").is_file()
    # the demo: the FMU (DOP853, rtol 1e-10) against the rtol 1e-12 reference, the bound of
    # test_accuracy.test_adaptive_rtol_1e10_is_within_1e9_of_the_reference (the same run, installed elsewhere)
    error = float(demo.stdout.split("max |x_FMU - x_ref| on [0, 200] = ")[1].split()[0])
    assert error <= 1e-9
    # the FMUs were built from the installed package, not from this checkout
    assert "/fmu_src/" not in built.stdout + built.stderr
    site = run([str(venv / "bin" / "python"), "-c", "import vibrofmu.paths as p; print(p.FMU_SRC)"])
    assert Path(site.stdout.strip()).is_relative_to(venv)
