"""Fidelity 3: the averaged slow flow integrated in time and x reconstructed (docs/model.md, Averaging and slow flow), model and FMU."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vibromodel import slowflow
from vibromodel.averaging import averaged
from vibromodel.parameters import ParameterError, Scene
from vibromodel.plant import Plant, Settings
from vibrofmu.analyses.reference import reference_solution
from vibrofmu.analyses.stability import fidelity3_check

EPS = np.finfo(float).eps


def solution(scene=Scene(), t0=0.0, rtol=1e-8, t_end=400.0, kernel=False):
    """kernel: tabulated on the compiled kernel where one is loaded (slowflow_kernel), else with SciPy."""
    return slowflow.SlowFlowSolution(averaged(scene), t0, scene.x_start, scene.v_start, rtol, t_end=t_end,
                                     kernel=kernel)


@pytest.mark.parametrize("t0", [0.0, 3.7])
def test_initial_state_is_reproduced(t0):
    scene = Scene(x_start=0.04, v_start=0.01)
    x, v, _ = solution(scene, t0).state(t0)
    assert x == pytest.approx(scene.x_start, abs=8 * EPS)  # the fixed point is iterated to round-off
    assert v == pytest.approx(scene.v_start, abs=8 * EPS)


def test_v_and_a_are_the_time_derivatives_of_x():
    sol, h = solution(), 1e-4
    for t in (0.37, 57.3, 199.9):
        x = [sol.state(t + k * h) for k in (-1, 0, 1)]
        # central differences: error h^2/6 |x'''| ~ 2e-11 (|x'''| ~ 1e-3 with omega ~ 1); the Hermite
        # table is C^1, so a is only piecewise continuous: t is kept away from the cell nodes (spacing 0.5)
        assert x[1][1] == pytest.approx((x[2][0] - x[0][0]) / (2 * h), abs=1e-9)
        assert x[1][2] == pytest.approx((x[2][1] - x[0][1]) / (2 * h), abs=1e-9)


def test_table_matches_an_independent_integration_of_the_slow_flow():
    rtol = 1e-8
    sol = solution(rtol=rtol)
    flow = averaged(Scene()).flow()
    Z0 = sol.cells[0][0], sol.cells[0][4]
    reference = solve_ivp(lambda _t, Z: flow.rhs(*Z), (0, 400), Z0, method="DOP853", rtol=1e-13, atol=1e-16,
                          dense_output=True)
    t = np.random.default_rng(1).uniform(0, 400, 500)
    u = t / sol.spacing
    i = u.astype(int)
    s = u - i
    cells = np.array(sol.cells)[i]
    A = cells[:, 0] + s * (cells[:, 1] + s * (cells[:, 2] + s * cells[:, 3]))
    B = cells[:, 4] + s * (cells[:, 5] + s * (cells[:, 6] + s * cells[:, 7]))
    error = np.max(np.abs(np.vstack([A, B]) - reference.sol(t)))
    # the table is refined until its midpoint error is <= rtol max|Z| + atol, and DOP853's global error is a
    # small multiple of rtol |Z| over the 400 tau of smooth decay: 10 (rtol max|Z| + atol) bounds both
    assert error <= 10 * (rtol * np.max(np.abs(reference.y)) + 1e-2 * rtol)


def test_chunked_extension_matches_a_single_integration():
    """Without a stop time the slow flow is integrated in chunks of slowflow.CHUNK; crossing into a new
    chunk restarts DOP853 there, so the two runs agree to the integration tolerance, not bit for bit."""
    scene, rtol = Scene(), 1e-10
    chunked = slowflow.SlowFlowSolution(averaged(scene), 0.0, scene.x_start, scene.v_start, rtol)
    whole = slowflow.SlowFlowSolution(averaged(scene), 0.0, scene.x_start, scene.v_start, rtol, t_end=700.0)
    assert chunked.t_end < 700.0
    t = np.linspace(0, 699, 777)
    difference = max(abs(chunked.state(tk)[0] - whole.state(tk)[0]) for tk in t)
    assert chunked.t_end >= 699.0
    assert difference <= 100 * rtol * abs(scene.x_start)  # DOP853 restarts: a few rtol of the state


def test_error_after_the_transient_is_within_one_percent_of_the_amplitude():
    """First-order averaging neglects O(epsilon) terms: the k2 y^2 harmonics 2 omega and 0 of size
    k2 r^2/(2 k1) ~ 4e-6 and the O(mu/omega) corrections to A, B; about 0.3 % of r = 7e-3 here."""
    scene = Scene()
    sol = solution(scene, t_end=400.0)
    t = np.arange(200.0, 400.0, 0.1)
    x_ref = reference_solution(scene, 0, 400.0)(t)[0]
    x = np.array([sol.state(tk)[0] for tk in t])
    amplitude = 0.5 * (x_ref.max() - x_ref.min())
    assert np.max(np.abs(x - x_ref)) < 0.01 * amplitude


def test_plant_at_fidelity_3_evaluates_the_solution_and_notes_the_validity():
    scene = Scene()
    plant = Plant(scene, Settings(fidelity=3), 0.0, 50.0)
    sol = solution(scene, t_end=50.0, kernel=plant.solution.kernel)  # the table the plant made, made alike
    for k in range(1, 11):
        assert plant.do_step((k - 1) * 0.5, 0.5, 0.0).x == sol.state(k * 0.5)[0]
    assert any("Omega = 2 is near 2 omega" in note for note in plant.notes)


@pytest.mark.parametrize("max_step", [5e-324, 1e-300, 1e-5])
def test_a_max_step_too_small_for_the_slow_flow_is_refused_naming_it(max_step):
    """The slow flow is integrated at initialisation: 200 tau in steps of max_step. 5e-324 used to fail inside SciPy
    ("initialisation failed: RuntimeError(...)", no parameter named), 1e-300 to run for ever; more than
    slowflow.MAX_STEPS = 1e6 steps (1e-5: 2e7 steps) is refused, as the integrators refuse such a doStep."""
    with pytest.raises(ParameterError, match=f"parameter max_step = {max_step!r}: the averaged slow flow"):
        Plant(Scene(), Settings(fidelity=3, max_step=max_step), 0.0, 200.0)


def test_fmu_fidelity_3_against_fidelity_0(plant_fmu):
    check = fidelity3_check(plant_fmu, Scene(), stop_time=400.0)
    assert "error" not in check
    assert check["relative_to_amplitude"] < 0.01  # as in the test above, through the FMU
    assert "averaged slow flow" in check["fmu_log_fidelity_3"][0]
    for key in ("end_to_end_speedup", "model_speedup", "integration_speedup"):
        assert math.isfinite(check[key]) and check[key] > 0  # reported, not asserted: shared, noisy machines
