"""Fidelity auto (vibromodel.auto): the cheapest rung whose error estimate (vibromodel.error_estimates) meets a
tolerance on max|x - x_exact|, against the exact model run by the compiled kernel."""
import numpy as np
import pytest

from vibrofmu.fmus import kernel
from vibrofmu.fmus.native import auto_rows
from vibromodel.auto import LADDER_COST, candidates, choose
from vibromodel.fidelities import Fidelity, entry
from vibromodel.models import ExactModel
from vibromodel.integrate import TerminalEvent
from vibromodel.parameters import ParameterError, Scene
from vibromodel.plant import Settings, make_plant

STOP, H = 50.0, 0.1


@pytest.fixture(scope="module")
def library():
    return kernel.kernel_library(), "the test's kernel"


def xs(plant, n=int(STOP / H)):
    """x at the communication points until the stop time or a terminal event (pull-in)."""
    out = []
    for i in range(n):
        try:
            out.append(plant.do_step(i * H, H, 0.0).x)
        except TerminalEvent:
            break
    return np.array(out)


def chosen(scene, tolerance, library):
    return choose(scene, Settings(), tolerance, lambda s: make_plant(scene, s, 0.0, STOP, library=library))


@pytest.mark.parametrize("tolerance", [1e-3, 1e-10])
def test_the_paper_scene_gets_a_rung_whose_measured_error_meets_the_tolerance(tolerance, library):
    """1e-3: the averaged slow flow (its estimate 4e-3) does not meet it, the analytic solution (1e-8) does; 1e-10: only
    the exact model at a tight rtol. The measured error against DOP853 at rtol 1e-12 must meet the tolerance too."""
    plant, settings, log = chosen(Scene(), tolerance, library)
    if tolerance == 1e-3:
        assert settings.fidelity in (Fidelity.AVERAGED, Fidelity.ANALYTIC)
    else:
        assert settings.fidelity == Fidelity.EXACT and settings.rtol <= 1e-10
    assert plant.error_estimate["estimate"] <= tolerance and "fidelity auto chose" in log[0]
    reference = xs(make_plant(Scene(), Settings(rtol=1e-12), 0.0, STOP, library=library))
    assert np.max(np.abs(xs(plant) - reference)) <= tolerance


def test_a_run_the_exact_model_ends_at_pull_in_ends_there_under_auto(library):
    """x_start = 0.29, R = 0.2 pulls in at tau ~ 0.13: the averaged and analytic rungs refuse the scene, auto runs
    the exact model, which stops at the same communication point."""
    scene = Scene(x_start=0.29, R=0.2)
    plant, settings, log = chosen(scene, 1e-3, library)
    assert settings.fidelity == Fidelity.EXACT and "refused" in log[0]
    exact = xs(make_plant(scene, Settings(), 0.0, STOP, library=library))
    assert len(xs(plant)) == len(exact) < STOP / H


@pytest.mark.parametrize("tolerance", [1e-16, 0.0, -1.0, float("nan")])
def test_a_tolerance_nothing_meets_is_refused_naming_it(tolerance, library):
    with pytest.raises(ParameterError) as refusal:
        chosen(Scene(), tolerance, library)
    assert refusal.value.name == "tolerance"


def test_every_candidate_s_forces_are_the_exact_model_s():
    """The plant FMU publishes Eq. 3's a and forces in Initialization Mode under fidelity auto (HertzEAOscillator.
    _initial_output, native model_initial_output): right only if every candidate's model is the exact one."""
    for _, candidate in candidates(Settings()):
        assert entry(candidate.fidelity).model is ExactModel, candidate


def test_the_candidates_run_cheapest_first_and_the_native_fmu_gets_them_all():
    """The native FMU's rules.h carries the list (fmus/native.auto_rows) in auto's order, costs included."""
    rows = candidates(Settings())
    costs = [cost for cost, _ in rows]
    assert costs == sorted(costs) and costs[0] == min(LADDER_COST.values())
    table = [line.strip() for line in auto_rows() if line.strip().startswith("{") and line.strip().endswith("},")]
    assert len(table) == len(rows)
    for line, (cost, settings) in zip(table, rows):
        level, solver, rtol, c = (float(v) for v in line.strip("{},").split(","))
        assert (level, solver, rtol, c) == (settings.fidelity, settings.solver, settings.rtol, cost)


def test_the_native_choice_is_auto_s_over_the_rungs_without_python(library):
    """choose(..., native=True) passes over the averaged and analytic rungs (native_refusal) without building them:
    on the paper scene at 1e-3 the exact model at rtol 1e-8 (the tightest of the cheapest cost)."""
    plant, settings, log = choose(Scene(), Settings(), 1e-3, lambda s: make_plant(Scene(), s, 0.0, STOP,
                                                                                  library=library), native=True)
    assert (settings.fidelity, settings.rtol) == (Fidelity.EXACT, 1e-8)
    assert "skipped: fidelity 3: refused (needs Python); fidelity 4: refused (needs Python)" in log[0]
