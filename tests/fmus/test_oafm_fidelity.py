"""Plant FMU at fidelity 4: the OAFM closed form, fitted (or cached) at initialisation."""
import json

import numpy as np
import pytest

from vibromodel.analytic import OafmSettings, covering, solve
from vibromodel.compiled_open_loop import OafmProgram, oafm_hints
from vibromodel.parameters import Scene
from vibrofmu.cli import main
from vibrofmu.analyses.oafm_study import fmu_check
from vibrofmu.hosts.run import run_fmu


def test_default_scene_uses_the_packed_fit_and_matches_the_harness(run_plant):
    scene = Scene()
    solution = solve(scene, covering(scene, OafmSettings(), 200.0))
    for kernel in (1, 0):
        run = run_plant(200.0, 0.1, fidelity=4, kernel=kernel)
        assert run.completed
        assert "resources/oafm_cache" in run.log[0]  # no fit at initialisation for the default scene
        expected = solution(run.time)
        if kernel == 1:  # same closed form, same C_i, same times (the FMU's clock t + h), same summation: same bits
            for name, values in zip(("x", "v", "a"), expected):
                assert np.array_equal(run.outputs[name], values), name
        else:  # the C evaluator's recurrences: within their derived bound (tests/core/test_open_loop_kernel.py)
            program = OafmProgram(solution, *oafm_hints(scene))
            bound = np.array([program.error_bound(t) for t in run.time])
            for name, values in zip(("x", "v", "a"), expected):
                assert np.all(np.abs(run.outputs[name] - values) <= bound), name


def test_other_scene_is_fitted_at_initialisation_and_covers_the_stop_time(run_plant):
    run = run_plant(400.0, 0.5, fidelity=4, x_start=0.1, tau_star=30.0)
    assert run.completed and "fitted" in run.log[0] and "fit to tau = 400" in run.log[0]


def test_oafm_command_checks_the_fmu(tmp_path, plant_fmu, capsys):
    out = tmp_path / "oafm"
    code = main(["oafm", "--fmu", str(plant_fmu), "--study-max-order", "2", "--out", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "OAFM valid on both domains" in printed and "x fidelity 0" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fmu_check"]["max_abs_difference_x"] <= 1e-12  # the bound; measured 0
    assert summary["fmu_check"]["cost_ratio_4_over_0"] > 0
    assert [r["order"] for r in summary["convergence"]] == [1, 2]
    for name in ("summary.json", "oafm.csv", "oafm.png", "convergence.png"):
        assert (out / name).stat().st_size > 0


@pytest.mark.parametrize("fidelity", [3, 4])
def test_input_force_is_refused_by_the_open_loop_fidelities(plant_fmu, fidelity):
    run = run_fmu(plant_fmu, {"fidelity": fidelity, "U": 0.01}, 10.0, 0.1)
    assert not run.completed and run.end_time == 0.0
    assert "parameter U = 0.01" in run.stop_reason and "open loop" in run.stop_reason


def test_fmu_check_reports_a_stop(plant_fmu):
    check = fmu_check(plant_fmu, Scene(), OafmSettings(order=0), solve(Scene(), OafmSettings(order=1)), 50.0)
    assert "oafm_order = 0" in check["error"]
