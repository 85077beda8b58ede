"""vibromodel.control against independent forms: the regressor against the models of Eq. 7 and Eq. 3, V' by the
chain rule against finite differences of V, V' against the law's promise, the exact hold integral against
quadrature, gain validation."""
import math

import numpy as np
import pytest
from scipy.integrate import quad

from vibromodel.closedloop import ERRATA_SCENE, ClosedLoop, LoopSettings
from vibromodel.control import GAIN_NAMES, Controller, Gains, Law, Regressor, true_theta
from vibromodel.models import ExactModel, PolynomialModel
from vibromodel.parameters import ParameterError
from vibromodel.plant import Settings

SCENE = ERRATA_SCENE
rng = np.random.default_rng(5)
STATES = [(rng.uniform(0, 50), rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1)) for _ in range(50)]


@pytest.mark.parametrize("t,x,v", STATES)
def test_regressor_times_theta_is_eq7_and_eq3(t, x, v):
    """docs/model.md, Adaptive controller: phi^T theta + U is Eq. 73 = Eq. 7 (corrected a_i). Against PolynomialModel the only difference
    is rounding (terms <= 1 in size: 1e-15). Against the exact Eq. 3 it is the series remainder at |x| <= 0.1:
    G1: 7x^6/11664 <= 6e-10, gamma/beta * 7u^6 (u = 2x/3) <= 2e-10, alpha G2's x^7 term smaller: bound 1e-9."""
    phi_theta = float(Regressor(SCENE)(t, x, v) @ true_theta(SCENE))
    U = 0.3
    assert abs(phi_theta + U - PolynomialModel(SCENE).accel(t, x, v, U)) <= 1e-15
    assert abs(phi_theta + U - ExactModel(SCENE).accel(t, x, v, U)) <= 1e-9


@pytest.mark.parametrize("law", [Law.PAPER_CORRECTED, Law.DAMPED])
@pytest.mark.parametrize("t,x,v", STATES[:20])
def test_v_rate_equals_the_promise_identically(law, t, x, v):
    """With the plant = Eq. 73 (PolynomialModel), V' (chain rule) is the promised formula for any state, reference
    and estimates, not only along a solution. Terms are O(1): rounding leaves <= 1e-14."""
    c = Controller(SCENE, Gains(lambdas=(3.0, 0.7) + tuple(rng.uniform(0.5, 2.0, 9)), k_damping=0.8), law)
    ref = tuple(rng.uniform(-0.1, 0.1, 3))
    theta_hat = true_theta(SCENE) + rng.uniform(-0.1, 0.1, 9)
    U = c.control(t, x, v, ref, theta_hat)
    accel = PolynomialModel(SCENE).accel(t, x, v, U)
    rate = c.lyapunov_rate(x, v, accel, ref, theta_hat, c.rates(t, x, v, ref))
    e1, e2 = c.errors(x, v, ref)
    assert abs(rate - c.promised_rate(e1, e2)) <= 1e-14


def test_paper_literal_breaks_the_promise():
    """Eq. 78 + 81 as printed: V' differs from Eq. 85 (the erratum). Difference at a typical state: O(lambda2 e2
    Delta~) ~ 1e-4; asserted > 1e-6."""
    c = Controller(SCENE, Gains(), Law.PAPER_LITERAL)
    t, x, v, ref = 3.0, 0.05, 0.01, (0.04, 0.0, -0.04)
    theta_hat = true_theta(SCENE) + 0.05
    accel = PolynomialModel(SCENE).accel(t, x, v, c.control(t, x, v, ref, theta_hat))
    rate = c.lyapunov_rate(x, v, accel, ref, theta_hat, c.rates(t, x, v, ref))
    assert abs(rate - c.promised_rate(*c.errors(x, v, ref))) > 1e-6


def test_chain_rule_v_rate_matches_central_differences_along_the_closed_loop():
    """Closed loop (exact Eq. 3 plant, rtol 1e-12): (V(t+h) - V(t-h))/2h vs V'(t), h = 1e-3. Truncation h^2 V'''/6
    with |V'''| <~ |V'| omega_max^2 ~ 3e-3 * 4^2 gives <= 1e-8; the states' error (~1e-14) / h adds 1e-11."""
    loop = ClosedLoop(SCENE, Settings(rtol=1e-12), LoopSettings(), stop_time=10.0)
    h, out = 1e-3, []
    for i in range(int(round(6.0 / h))):
        out.append(loop.do_step(i * h, h))
    V = np.array([o["V"] for o in out])
    rate = np.array([o["V_rate"] for o in out])
    central = (V[2:] - V[:-2]) / (2 * h)
    assert np.max(np.abs(central - rate[1:-1])) <= 1e-8
    assert np.max(np.abs(rate)) > 1e-4  # the check is not vacuous


@pytest.mark.parametrize("law", list(Law))
def test_hold_increment_is_the_exact_integral(law):
    """Controller.increment (inputs held) = quad of the update law's right-hand side over [t, t + H]."""
    c = Controller(SCENE, Gains(), law)
    t, H, x, v, ref = 7.3, 0.4, 0.05, -0.02, (0.03, 0.01, -0.02)
    exact = [quad(lambda s, i=i: c.rates(s, x, v, ref)[i], t, t + H, epsabs=1e-16, epsrel=1e-13)[0] for i in range(9)]
    # rtol 1e-12: ten times the relative accuracy asked of quad (epsrel 1e-13); atol 1e-18 matters only for a
    # component that is exactly 0
    assert np.allclose(c.increment(t, H, x, v, ref), exact, rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("index", range(11))
@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_bad_gains_name_the_gain(index, bad):
    lambdas = list(Gains().lambdas)
    lambdas[index] = bad
    with pytest.raises(ParameterError, match=f"parameter {GAIN_NAMES[index]} = "):
        Controller(SCENE, Gains(lambdas=tuple(lambdas)), Law.PAPER_CORRECTED)


def test_bad_damping_gain_is_named():
    with pytest.raises(ParameterError, match="parameter k_damping = "):
        Gains(k_damping=-1.0).validate()
