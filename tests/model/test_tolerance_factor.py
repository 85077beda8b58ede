"""The adaptive plant's tolerance over long, lightly damped runs (models.tolerance_factor, issue 25).

The rule: the solver runs at rtol * ERROR_MEMORY_REFERENCE / M, M = min(2/mu, the run's span), the factor within
[TOLERANCE_FACTOR_FLOOR, 1]. Checked here: its closed form, that a scene with mu >= 2/150 or a short span keeps the
rtol asked (the default scene's results are the same bits), the same solver rtol in the pure-Python and the compiled
plant, and the property it is for: the grazing campaign's worst runs, 1.1 ... 2.3 times over 100 rtol max|x| with the
rtol asked, within it with the factor.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibrofmu.analyses.domains import fastest_drive, run_steps, graze_scene
from vibrofmu.fmus import kernel
from vibromodel import models
from vibromodel.models import (ERROR_MEMORY_REFERENCE, TOLERANCE_FACTOR_FLOOR, error_memory, solver_tolerance,
                               tolerance_factor)
from vibromodel.parameters import MIN_RTOL, Scene
from vibromodel.plant import Kernel, Settings, make_plant


@pytest.fixture(scope="module")
def library():
    return kernel.kernel_library(), "the test's kernel"


def test_the_memory_is_2_over_mu_or_the_span_if_shorter():
    assert error_memory(Scene(mu=0.002)) == 1000.0
    assert error_memory(Scene(mu=0.002), 300.0) == 300.0
    assert error_memory(Scene(mu=0.002), 5000.0) == 1000.0
    assert error_memory(Scene(mu=0.0)) == math.inf
    assert error_memory(Scene(mu=0.0), 600.0) == 600.0
    for unknown in (None, 0.0, -5.0, math.nan):  # a span that is not known leaves 2/mu
        assert error_memory(Scene(mu=0.002), unknown) == 1000.0


def test_the_factor_is_the_reference_over_the_memory_within_its_floor_and_1():
    assert ERROR_MEMORY_REFERENCE == 150.0 and TOLERANCE_FACTOR_FLOOR == 0.01
    assert tolerance_factor(Scene()) == 1.0  # the paper's mu = 0.1: memory 20
    assert tolerance_factor(Scene(mu=2.0 / 150.0)) == 1.0
    assert tolerance_factor(Scene(mu=0.002)) == 150.0 / 1000.0
    assert tolerance_factor(Scene(mu=0.002), 600.0) == 150.0 / 600.0
    assert tolerance_factor(Scene(mu=0.002), 100.0) == 1.0  # a short run
    assert tolerance_factor(Scene(mu=0.0)) == TOLERANCE_FACTOR_FLOOR  # undamped, open-ended
    assert tolerance_factor(Scene(mu=0.0), 1e6) == TOLERANCE_FACTOR_FLOOR


def test_the_solver_tolerance_is_not_below_the_floor_and_says_what_it_did():
    assert solver_tolerance(Scene(), Settings(rtol=1e-8), 0.0, 200.0) == (1e-8, [])
    rtol, notes = solver_tolerance(Scene(mu=0.002), Settings(rtol=1e-6), 0.0, 5000.0)
    assert rtol == 1e-6 * 0.15 and len(notes) == 1
    assert "rtol = 1.5e-07 (rtol 1e-06 x 0.15)" in notes[0] and "tau = 1000" in notes[0]
    assert solver_tolerance(Scene(mu=0.0), Settings(rtol=1e-13))[0] == MIN_RTOL  # 1e-15 would be rounding noise
    # RK4 reads no rtol: its (unused) rtol is scaled alike, but nothing is said about it
    assert solver_tolerance(Scene(mu=0.002), Settings(rtol=1e-6, solver=1), 0.0, 5000.0) == (1e-6 * 0.15, [])


@pytest.mark.parametrize("kind", [Kernel.COMPILED, Kernel.PYTHON])
def test_both_plants_run_their_solver_at_the_factored_rtol(kind, library):
    def solver_rtol(scene, stop):
        plant = make_plant(scene, Settings(rtol=1e-6, kernel=kind), 0.0, stop, library=library)
        return plant._plant.dop.rtol if kind == Kernel.COMPILED else plant.integrator.rtol

    assert solver_rtol(Scene(), 200.0) == 1e-6  # the default scene: the rtol asked, the same bits as before
    assert solver_rtol(Scene(mu=0.002), None) == 1e-6 * 0.15
    assert solver_rtol(Scene(mu=0.002), 600.0) == 1e-6 * 0.25


def test_the_pure_python_and_the_compiled_plant_agree_bit_for_bit_with_the_factor(library):
    scene = Scene(mu=0.002, Delta=0.03)
    runs = []
    for kind in (Kernel.COMPILED, Kernel.PYTHON):
        plant = make_plant(scene, Settings(rtol=1e-6, kernel=kind), 0.0, 300.0, library=library)
        runs.append([plant.do_step(5.0 * i, 5.0, 0.0).x for i in range(60)])
    assert runs[0] == runs[1]


# The grazing campaign (vibrofmu.analyses.domains.graze_campaign, seed 0) runs that were over the bound with the
# rtol asked under DOP853's I step controller: (index, measured error / bound with the rtol asked then). Measured with
# the factor: at most 0.22 of the bound. Under the PI controller (integrate.PI_BETA) with the factor 0.040, 0.238 and
# 0.043 of the bound for runs 3, 56 and 127, with the rtol asked 0.504, 0.448 and 0.487: the controller's lower
# accepted errors brought them within the bound, and the factor still cuts their error 12.8, 1.9 and 11.4 times.
WORST_RUNS = {3: 2.26, 127: 1.72, 56: 1.28}
# What the factor must at least cut these runs' error by: the smallest cut measured (1.9, run 56) less a fifth
FACTOR_CUT = 1.5


@pytest.fixture(scope="module")
def campaign_scenes():
    rng = np.random.default_rng(0)
    return [graze_scene(rng) for _ in range(max(WORST_RUNS) + 1)]


@pytest.mark.parametrize("index", sorted(WORST_RUNS))
def test_the_factor_brings_the_campaigns_worst_long_runs_within_100_rtol_max_x(index, campaign_scenes, library,
                                                                               monkeypatch):
    """Error of x at the communication points (every tau = 1) against the plant at rtol 1e-12 with steps of at most 0.3
    rad of the fastest drive (its own error at rtol 1e-12 is ~1e-4 of the bound at rtol 1e-8: error proportional to
    the tolerance, measured), over the bound 100 rtol max|x| of the issue. With the factor: within it; with the factor
    switched off (a reference memory of inf gives factor 1): at least FACTOR_CUT times larger (over the bound before
    the PI step controller, as measured before the rule)."""
    scene, stop, rtol = campaign_scenes[index]

    def error(settings):
        x, stopped = run_steps(make_plant(scene, settings, 0.0, stop, library=library), stop, 1.0)
        assert stopped is None
        return x

    reference = error(Settings(rtol=1e-12, max_step=0.3 / fastest_drive(scene)))
    bound = 100.0 * rtol * np.max(np.abs(reference))
    with_factor = np.max(np.abs(error(Settings(rtol=rtol)) - reference))
    assert with_factor <= bound
    monkeypatch.setattr(models, "ERROR_MEMORY_REFERENCE", math.inf)
    assert np.max(np.abs(error(Settings(rtol=rtol)) - reference)) > FACTOR_CUT * with_factor
