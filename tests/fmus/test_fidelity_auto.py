"""Fidelity auto inside both plant FMUs (fidelity = -1 with the parameter `tolerance`; vibromodel.auto): at
initialisation each picks the cheapest rung and setting whose error estimate meets the tolerance, logs the choice
(fmi2OK), publishes `fidelity_chosen` and `error_estimate`, and refuses naming `tolerance` when nothing meets it. The
pythonfmu FMU chooses over every rung, the native one over those it runs (the exact model at DOP853's rtols)."""
import numpy as np
import pytest
from fmpy.validation import validate_fmu

from vibrofmu.hosts.run import run_fmu
from vibromodel.auto import choose
from vibromodel.fidelities import AUTO, Fidelity
from vibromodel.parameters import Scene
from vibromodel.plant import Settings, make_plant

STOP, H = 50.0, 0.1
FMI2_ERROR = 3


def auto(tolerance, **scene):
    return {**scene, "fidelity": AUTO, "tolerance": tolerance}


def reference(native_plant_fmu, scene: dict):
    """The exact model at rtol 1e-12 (the native FMU: the same kernel as the pythonfmu FMU's fidelity 0)."""
    return run_fmu(native_plant_fmu, {**scene, "rtol": 1e-12}, STOP, H)


def chose(run) -> list[str]:
    return [m for m in run.log if "fidelity auto chose" in m]


@pytest.mark.parametrize("tolerance", [1e-3, 1e-10])
def test_the_paper_scene_chooses_by_tolerance_and_meets_it(tolerance, plant_fmu, native_plant_fmu):
    """1e-3: over tau in [0, 50] (500 outputs) the averaged and analytic rungs' set-up costs more than the exact
    model's whole run (vibromodel.auto.SETUP_COST), so both FMUs run the exact model at its loosest rtol, 1e-4 (the
    cheapest; estimate ~9e-8; a long run that the slow flow pays for: tests/model/test_auto.py); 1e-10: only the
    exact model at rtol 1e-10 or tighter. Each run's max|x - x_ref| against the exact model at rtol 1e-12 must meet
    the tolerance, and its published estimate too."""
    ref = reference(native_plant_fmu, {})
    for fmu in (plant_fmu, native_plant_fmu):
        run = run_fmu(fmu, auto(tolerance), STOP, H)
        assert run.completed, run.stop_reason
        chosen = run.outputs["fidelity_chosen"]
        assert np.all(chosen == chosen[0])  # fixed at initialisation
        assert chosen[0] == Fidelity.EXACT, (fmu, chosen[0])
        estimate = run.outputs["error_estimate"][0]
        assert 0.0 < estimate <= tolerance
        assert len(chose(run)) == 1 and f"meets the tolerance {tolerance:g}" in chose(run)[0]
        assert any(m.startswith("[ok] fidelity auto chose") for m in run.log)  # logged with fmi2OK
        assert f"at rtol {1e-10 if tolerance == 1e-10 else 1e-4:g}" in chose(run)[0]
        assert np.max(np.abs(run.outputs["x"] - ref.outputs["x"])) <= tolerance


def test_the_pythonfmu_fmu_chooses_what_auto_chooses_and_the_native_fmu_its_share(plant_fmu, native_plant_fmu):
    """Both FMUs' choices are vibromodel.auto.choose's: the pythonfmu one over every candidate, the native one over
    those it runs (choose(..., native=True)); the log line is the chooser's, word for word."""
    for scene, tolerance in (({}, 1e-3), ({}, 1e-6), ({"Omega": 0.5, "beta": 0.05}, 1e-4), ({"mu": 0.01}, 1e-7)):
        model = Scene().with_values(**scene)
        for fmu, native in ((plant_fmu, False), (native_plant_fmu, True)):
            plant, settings, log = choose(model, Settings(), tolerance,
                                          lambda s: make_plant(model, s, 0.0, STOP), native=native, span=STOP)
            run = run_fmu(fmu, auto(tolerance, **scene), STOP, H)
            assert run.outputs["fidelity_chosen"][0] == settings.fidelity, (scene, tolerance, native)
            assert run.outputs["error_estimate"][0] == plant.error_estimate["estimate"]
            assert chose(run) == [f"[ok] {log[0]}"]


def test_a_run_the_exact_model_ends_at_pull_in_ends_there_under_auto(plant_fmu, native_plant_fmu):
    """x_start = 0.29, R = 0.2 pulls in at tau ~ 0.13: auto runs the exact model (the averaged and analytic rungs
    cost more over this run, and refuse the scene: tests/model/test_auto.py), which stops at the same communication
    point."""
    scene = {"x_start": 0.29, "R": 0.2}
    for fmu in (plant_fmu, native_plant_fmu):
        exact = run_fmu(fmu, scene, STOP, H)
        run = run_fmu(fmu, auto(1e-3, **scene), STOP, H)
        assert not exact.completed and "pull-in" in exact.stop_reason
        # auto runs rtol 1e-4 (its tolerance allows it), the fixed rung 1e-8: the same communication point, the
        # pull-in's tau to the solvers' accuracy, x within the tolerance
        assert run.status == exact.status == FMI2_ERROR and "pull-in" in run.stop_reason
        assert len(run.time) == len(exact.time) < STOP / H
        assert np.max(np.abs(run.outputs["x"] - exact.outputs["x"])) <= 1e-3
        assert run.outputs["fidelity_chosen"][0] == Fidelity.EXACT


@pytest.mark.parametrize("tolerance", [1e-16, 1e-300])
def test_a_tolerance_nothing_meets_is_refused_naming_it(tolerance, plant_fmu, native_plant_fmu):
    """The tightest candidate, the exact model at rtol 1e-12, estimates ~2e-13 on the paper scene: 1e-16 is out of
    reach; fmi2Error at initialisation naming the parameter and listing every candidate's estimate."""
    for fmu in (plant_fmu, native_plant_fmu):
        run = run_fmu(fmu, auto(tolerance), STOP, H)
        assert run.status == FMI2_ERROR and not run.completed and len(run.time) == 0
        assert f"[error] parameter tolerance = {tolerance!r}: no rung's error estimate meets it (" in run.stop_reason
        assert "fidelity 0 at rtol 1e-12: estimate" in run.stop_reason


@pytest.mark.parametrize("tolerance", [0.0, -1.0, float("nan"), float("inf")])
def test_a_tolerance_that_is_no_bound_is_refused_by_its_rule(tolerance, plant_fmu, native_plant_fmu):
    """The rule (parameters.RULES): refused before any candidate is built (the native FMU spells the value in C's
    way: 0 for 0.0)."""
    for fmu in (plant_fmu, native_plant_fmu):
        run = run_fmu(fmu, auto(tolerance), STOP, H)
        assert run.status == FMI2_ERROR and "[error] parameter tolerance = " in run.stop_reason
        assert ": must be a finite number in (0, " in run.stop_reason and not chose(run)


def test_fidelity_chosen_is_minus_one_before_initialisation_and_the_fidelity_of_a_fixed_rung(plant_fmu,
                                                                                               native_plant_fmu):
    for fmu in (plant_fmu, native_plant_fmu):
        assert run_fmu(fmu, {"fidelity": 1}, 1.0, H).outputs["fidelity_chosen"][0] == 1
    assert run_fmu(plant_fmu, {"fidelity": 3}, 1.0, H).outputs["fidelity_chosen"][0] == 3


def test_the_closed_loop_refuses_fidelity_auto(closed_loop_fmu, native_closed_loop_fmu):
    """Only the plant FMU chooses: the closed loop's plant must be an integrated level, in both FMUs alike."""
    for fmu in (closed_loop_fmu, native_closed_loop_fmu):
        run = run_fmu(fmu, {"fidelity": AUTO}, 1.0, H)
        assert run.status == FMI2_ERROR
        assert "[error] parameter fidelity = -1: the closed loop's plant must be 0, 1 or 2" in run.stop_reason


def test_both_plant_fmus_validate_silently(plant_fmu, native_plant_fmu):
    for fmu in (plant_fmu, native_plant_fmu):
        assert validate_fmu(str(fmu)) == []
