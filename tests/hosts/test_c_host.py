"""The plant FMU driven from C (tests/c_host/fmi2_host.c) as system-simulation tools drive it.

The host is compiled into the test's temporary folder and run in an empty environment (as `env -i`): the
FMU finds its Python itself (fmu_src/pyloader.c, resources/python_env.txt).
"""
from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu

from vibrofmu.cli import main
from vibrofmu.hosts.doctor import host_environment, run_host

VALGRIND_SUPPRESSIONS = Path(__file__).resolve().parents[1] / "c_host" / "valgrind.supp"
FMI2_ERROR = 3


@pytest.fixture(scope="module")
def run(c_host, unpacked):
    """run(stop, step, parameters, wrapper, extra_env) -> HostRun of the C host (x, v) from t = 0."""
    env = host_environment(unpacked / "resources")  # {}: nothing beyond an empty environment

    def run_(stop, step, parameters=None, wrapper=None, extra_env=None):
        return run_host(c_host, unpacked, ["x", "v"], 0.0, stop, step, parameters,
                        env={**env, **(extra_env or {})}, wrapper=wrapper)

    return run_


def test_c_host_matches_fmpy(run, plant_fmu):
    host = run(200.0, 0.1)
    assert host.returncode == 0, host.stderr
    fmpy = simulate_fmu(str(plant_fmu), start_time=0.0, stop_time=200.0, output_interval=0.1, output=["x", "v"])
    assert len(host.time) == 2001
    # bit identity is free: both hosts compute the same double operations, start + n * step
    np.testing.assert_array_equal(host.time, fmpy["time"])
    # Same Python code, inputs and communication points in both hosts: the results should be
    # bit-identical; 1e-15 absolute is the bound agreed in issue 7.
    for name in ("x", "v"):
        assert np.max(np.abs(host.outputs[name] - fmpy[name])) <= 1e-15, name
    assert np.ptp(host.outputs["x"]) > 0.01  # a real trajectory, not a constant


def test_bad_parameter_is_an_fmi2_error(run):
    host = run(1.0, 0.1, parameters={"R": -1.0})
    assert host.returncode == 2, host.stderr  # the host's own "FMI call failed" exit, not a crash
    assert f"fmi2ExitInitializationMode returned fmi2Error ({FMI2_ERROR})" in host.stderr
    logged = [line for line in host.stderr.splitlines() if line.startswith("[fmi2Error]")]
    assert any("R = -1" in line for line in logged), host.stderr  # the FMU's message reached the logger
    assert len(host.time) == 0


def test_pull_in_during_do_step_is_an_fmi2_error(run):
    host = run(5.0, 0.1, parameters={"x_start": 0.29, "R": 0.2})
    assert host.returncode == 2, host.stderr
    assert f"fmi2DoStep returned fmi2Error ({FMI2_ERROR})" in host.stderr
    assert any(line.startswith("[fmi2Error]") and "pull-in" in line for line in host.stderr.splitlines())
    assert 1 <= len(host.time) < 51  # the rows up to the failing step were printed


@pytest.mark.tools("valgrind")
def test_no_invalid_memory_access_up_to_process_exit(run):
    """pythonfmu 0.7.0 reads freed memory at exit in a C host (see fmi2_status_shim.c, "Process
    exit"); the shim works around it.  PYTHONMALLOC=malloc lets valgrind see Python's blocks.
    Uninitialised-value checks are off: CPython's own start-up (int.from_bytes while it sets up
    its codec registry) gives such reports, unrelated to the FMU; this test is about invalid
    reads and writes."""
    wrapper = ["valgrind", "--error-exitcode=99", "--undef-value-errors=no",
               f"--suppressions={VALGRIND_SUPPRESSIONS}"]
    host = run(1.0, 0.1, wrapper=wrapper, extra_env={"PYTHONMALLOC": "malloc"})
    assert "Invalid read" not in host.stderr and "Invalid write" not in host.stderr, host.stderr
    assert "ERROR SUMMARY: 0 errors" in host.stderr
    assert host.returncode == 0, host.stderr
    assert len(host.time) == 11


def test_doctor_needs_no_environment(plant_fmu, capsys, monkeypatch):
    """Issue 14: the FMU finds its Python itself, so the doctor has nothing to export on the building machine
    (it used to print LD_PRELOAD, PYTHONHOME and PYTHONPATH lines) and its check runs the host with an empty
    environment."""
    monkeypatch.delenv("VIBROFMU_PYTHON_ENV", raising=False)
    assert main(["doctor", str(plant_fmu)]) == 0
    out = capsys.readouterr().out
    assert "export " not in out
    assert "# nothing to set" in out
    assert "# ok: the C host matches FMPy" in out


def test_doctor_reports_a_broken_fmu(plant_fmu, tmp_path, capsys):
    broken = tmp_path / "broken.fmu"
    with zipfile.ZipFile(plant_fmu) as zin, zipfile.ZipFile(broken, "w") as zout:
        for info in zin.infolist():
            if not info.filename.endswith("_pythonfmu.so"):
                zout.writestr(info, zin.read(info.filename))
    assert main(["doctor", str(broken)]) == 1
    assert "cannot load inner library" in capsys.readouterr().err
