"""Issue 14, part 1: a pythonfmu FMU finds its Python itself in a C host started with an empty environment
(fmu_src/pyloader.c reads resources/python_env.txt, or the file VIBROFMU_PYTHON_ENV names), and says in one
log line what is missing when something is.

The C host (tests/c_host/fmi2_host.c) runs with env = {} (run_host passes nothing else), as `env -i`.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu

from vibrofmu.cli import main
from vibrofmu.hosts.doctor import recorded_environment, run_host
from vibrofmu.fmus.pythonenv import ENV_VARIABLE, env_text, parse_env

ROOT_CAUSE_HINT = "vibrofmu doctor"


def fmu_lines(stderr: str) -> list[str]:
    """The lines the FMU logged (the host prefixes them with [status])."""
    return [line for line in stderr.splitlines() if line.startswith("[")]


def _numpy_only_site(tmp_path: Path) -> Path:
    """A site-packages folder holding numpy (and its libraries and metadata) but not scipy: links into this
    Python's site-packages."""
    site = tmp_path / "site-packages"
    site.mkdir()
    numpy_home = Path(np.__file__).parents[1]
    for entry in numpy_home.iterdir():
        if entry.name == "numpy" or entry.name.startswith(("numpy.libs", "numpy-")):
            (site / entry.name).symlink_to(entry)
    assert not (site / "scipy").exists()
    return site


def _env_file(tmp_path: Path, recorded: dict, **changes) -> Path:
    record = {**recorded, **changes}
    versions = dict(item.split("==") if "==" in item else (item, None) for item in record["modules"].split())
    path = tmp_path / "python_env.txt"
    path.write_text(env_text({**record, "versions": versions}))
    return path


@pytest.mark.fmu  # asks for its FMU by name (request.getfixturevalue)
@pytest.mark.parametrize("name", ["plant", "controller", "closed_loop"])
def test_every_fmu_runs_in_an_empty_environment(name, request, c_host, tmp_path):
    fmu = request.getfixturevalue(f"{name}_fmu")
    unzip_dir = Path(extract(str(fmu), unzipdir=str(tmp_path / "fmu")))
    md = read_model_description(str(unzip_dir))
    outputs = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    # a short run: the point is that Python is found, the full experiment is test_c_host's
    host = run_host(c_host, unzip_dir, outputs, 0.0, 2.0, 0.5, env={})
    assert host.returncode == 0, host.stderr
    assert fmu_lines(host.stderr) == [], host.stderr
    ref = simulate_fmu(str(fmu), start_time=0.0, stop_time=2.0, output_interval=0.5, output=outputs)
    for output in outputs:  # the same Python code on the same inputs: the same bits (see test_c_host)
        np.testing.assert_array_equal(host.outputs[output], ref[output], err_msg=output)


def test_the_build_records_this_python(unpacked):
    recorded = recorded_environment(unpacked / "resources")
    assert recorded["python_version"] == "%d.%d" % sys.version_info[:2]
    assert recorded["home"] == sys.base_prefix
    assert Path(recorded["libpython"]).is_file()
    assert str(Path(np.__file__).parents[1]) in recorded["path"].split(":")
    modules = dict(item.split("==") for item in recorded["modules"].split())
    assert set(modules) == {"numpy", "scipy"}  # pythonfmu's Python part is packed in the FMU
    assert modules["numpy"] == np.__version__


def test_without_scipy_one_line_names_scipy(c_host, unpacked, tmp_path):
    env_file = _env_file(tmp_path, recorded_environment(unpacked / "resources"),
                         path=str(_numpy_only_site(tmp_path)))
    host = run_host(c_host, unpacked, ["x"], 0.0, 1.0, 0.1, env={ENV_VARIABLE: str(env_file)})
    assert host.returncode == 1, host.stderr  # the host's "fmi2Instantiate failed" (NULL instance)
    lines = fmu_lines(host.stderr)
    assert len(lines) == 1, host.stderr
    assert "scipy" in lines[0] and ROOT_CAUSE_HINT in lines[0] and "No module named 'scipy'" in lines[0]
    assert "Traceback" not in host.stderr and "AttributeError" not in host.stderr
    assert lines[0].startswith("[fmi2Error]")  # shown by a host's default log level


def test_without_libpython_one_line_names_it(c_host, unpacked, tmp_path):
    env_file = _env_file(tmp_path, recorded_environment(unpacked / "resources"),
                         libpython=str(tmp_path / "libpython3.11.so.1.0"))
    host = run_host(c_host, unpacked, ["x"], 0.0, 1.0, 0.1, env={ENV_VARIABLE: str(env_file)})
    assert host.returncode == 1
    lines = fmu_lines(host.stderr)
    assert len(lines) == 1, host.stderr
    assert "libpython is missing" in lines[0] and str(tmp_path) in lines[0] and ROOT_CAUSE_HINT in lines[0]


def test_a_version_mismatch_is_one_line(c_host, unpacked, tmp_path):
    recorded = recorded_environment(unpacked / "resources")
    other = "0.1.0"  # no numpy has this version: the check must see the difference
    modules = " ".join(f"numpy=={other}" if item.startswith("numpy==") else item
                       for item in recorded["modules"].split())
    env_file = _env_file(tmp_path, recorded, modules=modules)
    host = run_host(c_host, unpacked, ["x"], 0.0, 1.0, 0.1, env={ENV_VARIABLE: str(env_file)})
    assert host.returncode == 1
    lines = fmu_lines(host.stderr)
    assert len(lines) == 1, host.stderr
    assert "version mismatch" in lines[0] and f"numpy {other}" in lines[0] and np.__version__ in lines[0]


def test_a_missing_environment_file_is_one_line(c_host, unpacked, tmp_path):
    missing = tmp_path / "nowhere.txt"
    host = run_host(c_host, unpacked, ["x"], 0.0, 1.0, 0.1, env={ENV_VARIABLE: str(missing)})
    assert host.returncode == 1
    lines = fmu_lines(host.stderr)
    assert len(lines) == 1 and str(missing) in lines[0] and ROOT_CAUSE_HINT in lines[0], host.stderr


def test_doctor_env_file_for_another_machine(plant_fmu, c_host, unpacked, tmp_path, capsys):
    """`vibrofmu doctor --env-file` describes a Python (here this one); the FMU runs with it through
    VIBROFMU_PYTHON_ENV, giving the same bits as with the recorded environment."""
    env_file = tmp_path / "vibro.env"
    assert main(["doctor", "--env-file", str(env_file), "--python", sys.executable, str(plant_fmu)]) == 0
    assert f"export {ENV_VARIABLE}=" in capsys.readouterr().out
    written = parse_env(env_file.read_text())
    assert written["home"] == sys.base_prefix
    with_file = run_host(c_host, unpacked, ["x"], 0.0, 5.0, 0.1, env={ENV_VARIABLE: str(env_file)})
    recorded = run_host(c_host, unpacked, ["x"], 0.0, 5.0, 0.1, env={})
    assert with_file.returncode == 0 and recorded.returncode == 0, with_file.stderr + recorded.stderr
    # the same Python, the same FMU code and the same inputs, found through either file: the same bits
    np.testing.assert_array_equal(with_file.outputs["x"], recorded.outputs["x"])


def test_doctor_env_file_refuses_a_python_without_scipy(tmp_path, capsys):
    """A Python that lacks a module: exit 2 and one `error:` line naming it; no file written."""
    fake = tmp_path / "python"  # this Python, with sys.path reduced to the standard library
    fake.write_text(f"#!/bin/sh\nexec {sys.executable} -S -I \"$@\"\n")
    fake.chmod(0o755)
    out = tmp_path / "vibro.env"
    assert main(["doctor", "--env-file", str(out), "--python", str(fake)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "scipy" in err[0]
    assert not out.exists()


@pytest.mark.fmu  # asks for its FMU by name (request.getfixturevalue)
@pytest.mark.parametrize("name", ["plant", "controller", "closed_loop"])
def test_validate_fmu_is_silent(name, request):
    """FMPy's validation of the pythonfmu FMUs (with the recorded environment in resources/)."""
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(request.getfixturevalue(f"{name}_fmu"))) == []


def test_python_host_without_scipy_imports_it_from_the_recorded_site(plant_fmu, tmp_path):
    """A Python host (FMPy) of the FMU's Python version whose environment has fmpy and numpy but no scipy: the FMU
    appends the site-packages it recorded to sys.path (fmu_src/pyloader.c) and runs, with no log line (it used to
    fail with "scipy is missing"); the same bits as FMPy here (the same code, inputs and communication points)."""
    import json
    import subprocess

    import fmpy

    site = _numpy_only_site(tmp_path)
    home = Path(fmpy.__file__).parents[1]
    for entry in home.iterdir():  # fmpy and what it imports
        if entry.name in ("fmpy", "lxml", "attr", "attrs", "msgpack", "jinja2", "markupsafe"):
            (site / entry.name).symlink_to(entry)
    script = ("import sys; sys.path.insert(0, sys.argv[1])\n"
              "from fmpy import simulate_fmu\n"
              "import importlib.util; assert importlib.util.find_spec('scipy') is None\n"
              "lines = []\n"
              "r = simulate_fmu(sys.argv[2], stop_time=5.0, output=['x'], logger=lambda *a: lines.append(a[4].decode()))\n"
              "import json; print(json.dumps({'x': r['x'].tolist(), 'lines': lines,\n"
              "                               'scipy': importlib.util.find_spec('scipy') is not None}))\n")
    proc = subprocess.run([sys.executable, "-S", "-c", script, str(site), str(plant_fmu)], capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.splitlines()[-1])
    assert out["scipy"] and out["lines"] == [], out["lines"]
    ref = simulate_fmu(str(plant_fmu), stop_time=5.0, output=["x"])
    np.testing.assert_array_equal(out["x"], ref["x"])
