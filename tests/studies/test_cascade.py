"""A period-doubling cascade followed by continuation (analyses/continuation.py: branch with max_period, cascade,
feigenbaum_ratios) on the documented chaos scene (docs/bifurcation-diagram.md, Chaos): each located doubling
checked against an independent integration -- the orbit and its monodromy over n periods by SciPy's Radau (an
implicit method, not the engine's DOP853 in rescaled time) with variational equations written here."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vibromodel import forces
from vibromodel.parameters import Scene
from vibrofmu.analyses import continuation as cont

CHAOS_SCENE = Scene(mu=0.1, Delta=2.5, R=3.0, beta=0.0, gamma=0.0)  # period 1, 2, 4, 8, chaos from omega 2.2 down
# Radau at rtol 1e-12: its global error over n <= 8 periods is a small multiple of n x 1e-12 in z and M
INDEPENDENT_RTOL = 1e-12
# |rho + 1| at a located doubling: the location's own error (Brent to 1e-12 of the step on a test function
# evaluated to the engine's ~1e-9) moves rho by ~1e-8 with |drho/domega| ~ 10 .. 100; the independent M's error
# ~1e-10 |M|; 1e-6 leaves two decades for both
MULTIPLIER_TOL = 1e-6
ORBIT_TOL = 1e-8  # |P^n(z) - z| of the located orbit under the independent map: 100 x the engine's Newton tolerance


def independent_map(scene: Scene, z0, periods: int):
    """P^n(z0) and its monodromy M for x'' + mu x' + H(x) - 1 - F_em,mean(x) = Delta cos(omega tau) in the
    original time tau, by Radau, restarted past each contact crossing (x = -3/2, where H'' is singular)."""
    mu, Delta, omega = scene.mu, scene.Delta, scene.omega
    alpha, gamma, R = scene.alpha, scene.gamma, scene.R

    def rhs(t, y):
        x, v = y[0], y[1]
        k = forces.hertz_stiffness(x) - forces.electrostatic_mean_stiffness(x, alpha, gamma, R)
        f = forces.hertz(x) - 1.0 - forces.electrostatic_mean(x, alpha, gamma, R)
        p11, p12, p21, p22 = y[2:]
        return [v, Delta * math.cos(omega * t) - mu * v - f,
                p21, p22, -k * p11 - mu * p21, -k * p12 - mu * p22]

    def edge(t, y):
        return y[0] + 1.5

    edge.terminal = True
    end = periods * 2.0 * math.pi / omega
    t, y = 0.0, np.concatenate([np.asarray(z0, dtype=float), np.eye(2).ravel()])
    while True:
        sol = solve_ivp(rhs, (t, end), y, method="Radau", rtol=INDEPENDENT_RTOL, atol=1e-14, events=edge)
        assert sol.status >= 0, sol.message
        t, y = sol.t[-1], sol.y[:, -1]
        if sol.status == 0:
            return y[:2], y[2:].reshape(2, 2)
        t = np.nextafter(t, end)  # past the crossing, so the event does not fire again at once


@pytest.fixture(scope="module")
def cascade():
    result = cont.branch(CHAOS_SCENE, "omega", 2.2, 1.785, points=200, max_period=8)
    return result, cont.cascade(result)


@pytest.mark.slow
def test_the_cascade_is_followed_to_period_8_and_its_doublings_accumulate(cascade):
    result, steps = cascade
    assert [pt.periods for pt in steps] == [1, 2, 4, 8]  # 1 -> 2 -> 4 -> 8 -> 16: four doublings located
    values = [pt.p for pt in steps]
    assert all(a > b for a, b in zip(values, values[1:]))  # each further down in omega
    ratios = cont.feigenbaum_ratios(values)
    # the intervals shrink (a ratio above 1) and the last ratio is nearer Feigenbaum's delta than the first
    assert all(r > 1.0 for r in ratios)
    assert abs(ratios[-1] - 4.6692) < abs(ratios[0] - 4.6692)


@pytest.mark.slow
def test_each_located_doubling_has_a_multiplier_at_minus_one_on_an_independent_integration(cascade):
    _, steps = cascade
    assert steps
    for pt in steps:
        scene = CHAOS_SCENE.with_values(omega=pt.p)
        end, M = independent_map(scene, pt.z0, pt.periods)
        assert np.max(np.abs(end - pt.z0)) <= ORBIT_TOL, (pt.periods, pt.p)
        rho = np.linalg.eigvals(M)
        assert np.min(np.abs(rho + 1.0)) <= MULTIPLIER_TOL, (pt.periods, pt.p, rho)
        # Liouville: det M = exp(-mu n T) whatever the engine did (a check of the independent map itself)
        assert abs(np.linalg.det(M) - math.exp(-scene.mu * pt.period)) <= 1e-9, (pt.periods, pt.p)
