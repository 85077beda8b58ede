"""The co-simulation scene as an SSP file and the closed loop as an FMPy container FMU.

- fmpy.ssp.simulate_ssp runs the written .ssp; the project's master with the same ordering ('fmpy': FMPy's loop
  reproduced call for call) gives the same numbers. Both drive the same FMU binaries with the same inputs in the
  same order, so the only admissible difference is none at all: the bound 1e-12 is far below any coupling effect
  (which is O(H) ~ 1e-3 here) and above nothing but a change of call sequence.
- The .ssp read back is the scene that was written (FMUs, parameters, connections, step, ordering).
- The container FMU passes fmpy.validate_fmu, runs its default experiment, and equals the master run with the
  container's call sequence (the connections copied during initialisation, then Jacobi + ordered copies) to 1e-12;
  against the master's own Jacobi and the monolithic FMU it differs by O(H).
"""
from dataclasses import replace

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from vibrofmu.hosts import container, ssp
from vibrofmu.analyses import container_check
from vibrofmu.paths import DEFAULT_SCENE
from vibrofmu.hosts.cosim import SceneError, load_scene, run_cosim
from zip_entries import assert_regular_0644

STOP = 20.0  # 200 communication steps at H = 0.1: every FMU and connection is exercised, about 1 s per run


@pytest.fixture(scope="module")
def fmu_dir(plant_fmu, controller_fmu, closed_loop_fmu):
    return plant_fmu.parent


@pytest.fixture(scope="module")
def scene(fmu_dir):
    return load_scene(DEFAULT_SCENE, fmu_dir).with_settings(stop_time=STOP)


@pytest.fixture(scope="module")
def ssp_file(scene, tmp_path_factory):
    return ssp.write_ssp(scene, tmp_path_factory.mktemp("ssp") / "closed_loop.ssp")


def test_ssp_round_trip(scene, ssp_file):
    back = ssp.load_ssp(ssp_file)
    assert [f.name for f in back.fmus] == [f.name for f in scene.fmus]
    for written, read in zip(scene.fmus, back.fmus):
        expected = dict(written.parameters)
        if written.name != "controller":  # the scene's tolerance travels as the integrators' rtol
            expected["rtol"] = scene.tolerance
        assert read.parameters == expected
        assert read.path.read_bytes() == written.path.read_bytes()
    assert back.connections == scene.connections
    assert (back.step, back.stop_time, back.ordering, back.tolerance) == \
        (scene.step, scene.stop_time, scene.ordering, scene.tolerance)


def test_fmpy_simulate_ssp_equals_the_master_with_fmpy_ordering(ssp_file):
    theirs = ssp.simulate_with_fmpy(ssp_file)
    ours = run_cosim(replace(ssp.load_ssp(ssp_file), ordering="fmpy"))
    assert ours.completed
    # both loops compute the grid with FMPy's arithmetic (ordering 'fmpy' reproduces it call for call): equal
    np.testing.assert_array_equal(theirs["time"], ours.time)
    columns = [c for c in ours.outputs if c in theirs]
    assert {"plant.x", "controller.U", "reference.x", "controller.V"} <= set(columns)
    worst = max(ssp.max_difference(theirs, ours.outputs, columns).values())
    assert worst <= 1e-12, worst
    # and the loop is a real closed loop: the controller moved the plant away from its free response
    assert np.max(np.abs(ours.outputs["controller.U"])) > 1e-3


def test_master_runs_the_ssp_with_its_own_ordering(ssp_file, scene):
    """`closed-loop --mode cosim --scene closed_loop.ssp` reads the same scene as the TOML: identical results."""
    from_ssp = run_cosim(load_scene(ssp_file, None))
    from_toml = run_cosim(scene)
    # the same scene read from either file: the same FMUs, calls and inputs in the same order, so the same bits
    np.testing.assert_array_equal(from_ssp.outputs["plant.x"], from_toml.outputs["plant.x"])


def test_bad_ssp_is_a_scene_error(tmp_path):
    bad = tmp_path / "bad.ssp"
    bad.write_text("not a zip")
    with pytest.raises(SceneError, match="not a valid SSP file"):
        load_scene(bad, tmp_path)


@pytest.fixture(scope="module")
def container_fmu(fmu_dir, tmp_path_factory):
    return container.build_container(fmu_dir, tmp_path_factory.mktemp("container") / "c.fmu", 0.1)


def test_container_validates_and_runs_its_default_experiment(container_fmu):
    assert validate_fmu(str(container_fmu)) == []
    assert_regular_0644(container_fmu)  # FMPy's container writer leaves 0600 entries: normalized (issue 23)
    from fmpy import read_model_description, simulate_fmu

    md = read_model_description(str(container_fmu))
    result = simulate_fmu(str(container_fmu))  # default experiment: tau 0..200, step 0.1
    assert md.defaultExperiment.stopTime == "200.0"
    # 2000 steps of 0.1 summed by FMPy: rounding <= 2000 x ulp(200) = 6e-11, inside 1e-9
    assert result["time"][-1] == pytest.approx(200.0, abs=1e-9)
    for name in ("x", "x_ref", "U", "e1", "V"):
        assert np.all(np.isfinite(result[name])), name
    # the adaptive controller tracks the reference: |e1| at the end far below its start (0.02)
    assert abs(result["e1"][-1]) < 2e-3


def test_container_equals_the_master_with_its_call_sequence(fmu_dir, container_fmu):
    H = 0.1
    ours = container_check.run_master_like_container(container_check.with_rtol(container_check.master_scene(fmu_dir, H, STOP)))
    theirs = container.run_container(container_fmu, H, STOP)
    n = len(ours["x"])
    assert len(theirs["x"]) == n
    assert np.max(np.abs(theirs["x"] - ours["x"])) <= 1e-12
    assert np.max(np.abs(theirs["x_ref"] - ours["x_ref"])) <= 1e-12


def test_ssp_with_an_unknown_parameter_names_it(ssp_file, tmp_path):
    import zipfile

    bad = tmp_path / "bad_parameter.ssp"
    with zipfile.ZipFile(ssp_file) as source, zipfile.ZipFile(bad, "w") as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == ssp.SSD_NAME:
                data = data.replace(b'name="x_start"', b'name="x_begin"')
            target.writestr(item, data)
    with pytest.raises(SceneError, match="'x_begin' is not a parameter"):
        ssp.load_ssp(bad)


def test_vibrofmu_ssp_writes_the_shipped_scene(fmu_dir, tmp_path, capsys):
    """`vibrofmu ssp` writes closed_loop.ssp: the default scene, readable by FMPy's SSD reader (schema-validated)."""
    from fmpy.ssp.ssd import read_ssd

    from vibrofmu.cli import main

    assert main(["ssp", "--fmu-dir", str(fmu_dir), "--out-dir", str(tmp_path)]) == 0
    path = tmp_path / "closed_loop.ssp"
    assert f"wrote {path}" in capsys.readouterr().out
    assert [c.name for c in read_ssd(str(path)).system.elements] == ["reference", "plant", "controller"]
    shipped, scene = ssp.load_ssp(path), load_scene(DEFAULT_SCENE, fmu_dir)
    assert shipped.connections == scene.connections and shipped.step == scene.step
    assert path.stat().st_mode & 0o777 == 0o644
    assert_regular_0644(path)  # and so are its entries (issue 23)
