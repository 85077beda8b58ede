"""The FMU's integrators against closed forms, conservation and their own dense output."""
import math

import numpy as np
import pytest

from vibromodel.fidelities import make_model
from vibromodel.integrate import Dop853, IntegrationError, Rk4
from vibromodel.parameters import Scene
from vibromodel.plant import Plant, Settings

MU, K = 0.1, 1.0


def damped_accel(t, x, v, U):
    return -MU * v - K * x + U


def damped_exact(t, x0=1.0):
    """x'' + mu x' + x = 0, x(0) = x0, x'(0) = 0."""
    p = math.sqrt(K - MU**2 / 4)
    return x0 * math.exp(-MU * t / 2) * (math.cos(p * t) + MU / (2 * p) * math.sin(p * t))


@pytest.mark.parametrize("rtol", [1e-6, 1e-9, 1e-12])
def test_dop853_matches_the_damped_linear_oscillator(rtol):
    ig = Dop853(damped_accel, (), 0.0, 1.0, 0.0, 0.0, rtol)
    errs = []
    for t in np.arange(0.05, 50.0, 0.05):  # communication points read from the dense output
        ig.advance(t)
        errs.append(abs(ig.value_at(t)[0] - damped_exact(t)))
    # global error of a tolerance-proportional method: a small multiple of rtol over ~8 periods
    assert max(errs) <= 50 * rtol


def test_dense_output_is_seventh_order_inside_a_step():
    ig = Dop853(damped_accel, (), 0.0, 1.0, 0.0, 0.0, 1e-13, max_step=math.inf)
    ig.advance(1e-9)
    t_old, t = ig.t_old, ig.t
    mid = 0.5 * (t_old + t)
    # a step of 1e-9: the dense output's error is O(h^8), nothing; 1e-13 bounds the rounding of values ~1
    assert abs(ig.value_at(mid)[0] - damped_exact(mid)) <= 1e-13


def test_dop853_conserves_energy_undamped_unforced():
    scene = Scene(mu=0.0, Delta=0.0, alpha=0.0, beta=0.0, gamma=0.0, x_start=0.3)
    model = make_model(scene, 0)

    def energy(x, v):  # v^2/2 + integral of (Hertz - 1)
        return 0.5 * v * v + 0.6 * ((1 + 2 * x / 3) ** 2.5 - 1) - x

    ig = Dop853(model.accel, model.events, 0.0, 0.3, 0.0, 0.0, 1e-12)
    e0 = energy(0.3, 0.0)
    ig.advance(1000.0)
    x, v = ig.value_at(1000.0)
    # rtol 1e-12 per step over tau = 1000 (~160 periods): the energy error of a non-symplectic method grows about
    # linearly with the number of steps (several thousand): 1e-9 = 1000 rtol
    assert abs(energy(x, v) - e0) / abs(e0) <= 1e-9


def test_input_change_restarts_from_the_dense_output():
    """U held at 0 then 0.5 from t = 3: compare with the exact piecewise solution."""
    ig = Dop853(damped_accel, (), 0.0, 1.0, 0.0, 0.0, 1e-12)
    ig.advance(3.0)
    x3, v3 = ig.value_at(3.0)
    # rtol 1e-12 on x ~ 1 over ~0.5 period: the global error a small multiple of rtol; 10 rtol
    assert abs(x3 - damped_exact(3.0)) <= 1e-11
    ig.set_input(3.0, 0.5)
    ig.advance(10.0)
    # after t = 3 the equilibrium is x = 0.5: shift and solve the homogeneous problem
    ref = Dop853(damped_accel, (), 0.0, x3 - 0.5, v3, 0.0, 1e-13)
    ref.advance(7.0)
    assert abs(ig.value_at(10.0)[0] - (ref.value_at(7.0)[0] + 0.5)) <= 1e-10


def test_rk4_step_is_fourth_order():
    errs = []
    for h in (0.2, 0.1, 0.05):
        ig = Rk4(damped_accel, (), 0.0, 1.0, 0.0, 0.0, h)
        ig.advance(10.0)
        errs.append(abs(ig.x - damped_exact(10.0)))
    # observed order of a 4th-order method from three step sizes: the h^5 term shifts the slope by O(h) = 0.1-0.2
    assert math.log2(errs[0] / errs[1]) == pytest.approx(4.0, abs=0.3)
    assert math.log2(errs[1] / errs[2]) == pytest.approx(4.0, abs=0.3)


def test_rk4_with_a_step_too_large_reports_instability():
    stiff = Scene(mu=50.0)
    model = make_model(stiff, 0)
    ig = Rk4(model.accel, model.events, 0.0, 0.04, 0.0, 0.0, 0.5)  # |h lambda| = 25 >> 2.8
    with pytest.raises(IntegrationError, match="RK4"):
        ig.advance(1000.0)


def test_adaptive_solver_survives_a_stiff_scene():
    stiff = Scene(mu=50.0)
    model = make_model(stiff, 0)
    ig = Dop853(model.accel, model.events, 0.0, 0.04, 0.0, 0.0, 1e-8)
    for t in np.arange(10.0, 101.0, 10.0):
        ig.advance(t)
    x, _ = ig.value_at(100.0)
    assert math.isfinite(x)


def test_adaptive_step_budget_stops_an_endless_doStep():
    model = make_model(Scene(), 0)
    integrator = Dop853(model.accel, model.events, 0.0, 0.04, 0.0, 0.0, 1e-8, step_budget=5)
    with pytest.raises(IntegrationError, match="5 steps reached only tau = "):
        integrator.advance(100.0)
    assert 0.0 < integrator.t < 100.0


def test_input_change_restarts_the_integrator_at_the_communication_point():
    """U switched on at tau = 1 acts from tau = 1 on: after it, x differs from the U = 0 run by ~ U t^2/2."""
    scene = Scene()
    runs = []
    for U in (0.0, 1e-3):
        plant = Plant(scene, Settings(rtol=1e-12), 0.0, 2.0)
        plant.do_step(0.0, 1.0, 0.0)
        runs.append(plant.do_step(1.0, 0.1, U).x)
    # the plant responds to a constant force step like a mass over 0.1 of tau: dx = U h^2/2 to first order
    assert runs[1] - runs[0] == pytest.approx(1e-3 * 0.1**2 / 2, rel=0.05)
