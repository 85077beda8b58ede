"""A period-doubling cascade followed by continuation (analyses/continuation.py: branch with max_period, cascade,
feigenbaum_ratios) on the documented chaos scene (docs/bifurcation-diagram.md, Chaos): each located doubling
checked against an independent period map -- the state alone (no variational equations) in the original time
tau, by SciPy's DOP853, restarted past each contact crossing -- whose monodromy is formed by central
differences, Richardson-extrapolated over two steps."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vibromodel import forces
from vibromodel.parameters import Scene
from vibrofmu.analyses import continuation as cont

CHAOS_SCENE = Scene(mu=0.1, Delta=2.5, R=3.0, beta=0.0, gamma=0.0)  # period 1, 2, 4, 8, chaos from omega 2.2 down
INDEPENDENT_RTOL = 1e-13  # the plain map's error ~1e-13 |z| per period: a few 1e-12 over 8 periods
FD_STEP = 1e-4  # central differences over h and h/2, Richardson: truncation O(h^4 |P^(5)|) ~ 1e-16 |P^(5)|,
# round-off ~ (map error) / h ~ 1e-8 at worst over 8 periods
FD_STEPS = (1e-3, 3e-4, 1e-4, 3e-5)  # checked_monodromy: the step whose M satisfies Liouville best
# |rho + 1| at a located doubling: the location's own error (Brent to 1e-12 of the step on det(M + I) evaluated to
# the engine's ~1e-9) moves rho by ~1e-8 with |drho/domega| ~ 10 .. 100; the independent M's error ~1e-8: 1e-6
# leaves two decades for both
MULTIPLIER_TOL = 1e-6
ORBIT_TOL = 1e-8  # |P^n(z) - z| of the located orbit under the independent map: 100 x the engine's Newton tolerance


def independent_map(scene: Scene, z0, periods: int) -> np.ndarray:
    """P^n(z0) of x'' + mu x' + H(x) - 1 - F_em,mean(x) = Delta cos(omega tau) in the original time tau, the
    state alone, by DOP853, restarted past each contact crossing (x = -3/2, where H'' is singular)."""
    mu, Delta, omega = scene.mu, scene.Delta, scene.omega
    alpha, gamma, R = scene.alpha, scene.gamma, scene.R

    def rhs(t, y):
        x, v = y
        return [v, Delta * math.cos(omega * t) - mu * v - forces.hertz(x) + 1.0
                + forces.electrostatic_mean(x, alpha, gamma, R)]

    def edge(t, y):
        return y[0] + 1.5

    edge.terminal = True
    edge.direction = -1.0 if z0[0] > -1.5 else 1.0  # the next crossing only: not the one just restarted from
    end = periods * 2.0 * math.pi / omega
    t, y = 0.0, np.asarray(z0, dtype=float)
    while True:
        sol = solve_ivp(rhs, (t, end), y, method="DOP853", rtol=INDEPENDENT_RTOL, atol=1e-15, events=edge)
        assert sol.status >= 0, sol.message
        t, y = sol.t[-1], sol.y[:, -1]
        if sol.status == 0:
            return y
        edge.direction = -edge.direction


def checked_monodromy(scene: Scene, z0, periods: int) -> tuple[np.ndarray, float]:
    """independent_monodromy at the FD steps FD_STEPS, the one whose determinant is nearest Liouville's exact
    det M = exp(-mu n T), and that defect |det M exp(mu n T) - 1|: the independent M's own accuracy. Over 8 periods
    with contact lost on every cycle (H'' singular there: P is C^1 but not smooth enough for Richardson's error law
    everywhere) one step can be off by 1e-5 where its neighbours are good to 1e-8 (measured at the 8T doubling:
    defects 1.1e-6, 7.5e-8, 2.5e-5, 8e-5 for steps 1e-3 .. 3e-5), so one fixed step does not measure the engine."""
    exact = math.exp(-scene.mu * periods * 2.0 * math.pi / scene.omega)
    found = [independent_monodromy(scene, z0, periods, h) for h in FD_STEPS]
    defects = [abs(np.linalg.det(M) / exact - 1.0) for M in found]
    best = int(np.argmin(defects))
    return found[best], defects[best]


def independent_monodromy(scene: Scene, z0, periods: int, step: float | None = None) -> np.ndarray:
    """dP^n/dz at z0 by central differences over h and h / 2 (h = step, default FD_STEP), Richardson-extrapolated."""
    h0 = FD_STEP if step is None else step

    def central(h):
        columns = []
        for k in range(2):
            e = np.zeros(2)
            e[k] = h
            columns.append((independent_map(scene, z0 + e, periods) - independent_map(scene, z0 - e, periods))
                           / (2.0 * h))
        return np.column_stack(columns)

    coarse, fine = central(h0), central(h0 / 2)
    return fine + (fine - coarse) / 3.0


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
def test_each_located_doubling_has_a_multiplier_at_minus_one_on_an_independent_map(cascade):
    _, steps = cascade
    assert steps
    for pt in steps:
        scene = CHAOS_SCENE.with_values(omega=pt.p)
        end = independent_map(scene, pt.z0, pt.periods)
        assert np.max(np.abs(end - pt.z0)) <= ORBIT_TOL, (pt.periods, pt.p)
        M, defect = checked_monodromy(scene, pt.z0, pt.periods)
        assert defect <= MULTIPLIER_TOL, (pt.periods, pt.p, defect)  # the check itself accurate enough
        rho = np.linalg.eigvals(M)
        assert np.min(np.abs(rho + 1.0)) <= MULTIPLIER_TOL, (pt.periods, pt.p, rho)


GRAZING_FOLD_SCENE = Scene(mu=0.05, R=2.0, omega=0.8, beta=0.0, gamma=0.0)  # the Delta branch of docs/continuation.md


@pytest.mark.slow
def test_the_contact_loss_orbit_of_the_delta_branch_doubles_and_is_a_flip_saddle_beyond():
    """The period-T orbit beyond the lower fold is stable only up to a period doubling; past it one real multiplier
    is below -1 (a flip saddle), on the independent map too."""
    result = cont.branch(GRAZING_FOLD_SCENE, "Delta", 0.002, 0.5, double=False)  # the documented command
    events = [pt.event for pt in result.events()]
    assert events[:3] == ["grazing", "fold", "fold"] or events[:3] == ["fold", "grazing", "fold"], events
    pd_index = next(i for i, pt in enumerate(result.points) if pt.event == "period-doubling")
    pd = result.points[pd_index]
    assert pd.x_min < cont.CONTACT_EDGE  # on the contact-loss part, beyond the lower fold
    scene = GRAZING_FOLD_SCENE.with_values(Delta=pd.p)
    assert np.max(np.abs(independent_map(scene, pd.z0, 1) - pd.z0)) <= ORBIT_TOL
    rho = np.linalg.eigvals(independent_monodromy(scene, pd.z0, 1))
    assert np.min(np.abs(rho + 1.0)) <= MULTIPLIER_TOL, rho
    beyond = [pt for pt in result.points[pd_index + 1:] if 0.15 <= pt.p <= 0.25]
    assert beyond
    for pt in beyond[:: max(1, len(beyond) // 2)]:
        rho = np.sort(np.linalg.eigvals(independent_monodromy(GRAZING_FOLD_SCENE.with_values(Delta=pt.p), pt.z0, 1)).real)
        assert rho[0] < -1.0, (pt.p, rho)  # a flip saddle: unstable, not the stable motion
        # the engine's multipliers within the independent map's own accuracy (1e-6 relative, Liouville above)
        engine = np.sort(pt.multipliers.real)
        assert np.allclose(rho, engine, rtol=1e-5, atol=1e-8), (pt.p, rho, engine)


@pytest.mark.slow
@pytest.mark.parametrize("delta", [0.45, 0.5])
def test_no_bounded_motion_of_the_delta_scene_is_left_at_the_end_of_its_range(delta):
    """Past the upper fold (Delta 0.3867) the in-contact orbit is gone and the contact-loss orbits (period T, 2T,
    ...) are saddles: at Delta = 0.45 and 0.5 every run of the compiled plant from a 10 x 10 grid of starts (x from
    -2.5 to 2, x' from -2 to 2) ends in pull-in within 400 forcing periods (docs/continuation.md): no stable branch
    of this family reaches Delta = 0.5. A bounded attractor would keep some run alive."""
    from vibrofmu import api

    period = 2 * math.pi / GRAZING_FOLD_SCENE.omega
    survivors = []
    for x0 in np.linspace(-2.5, 2.0, 10):
        for v0 in np.linspace(-2.0, 2.0, 10):
            scene = GRAZING_FOLD_SCENE.with_values(Delta=delta, x_start=float(x0), v_start=float(v0))
            run = api.simulate(scene, stop_time=400 * period, interval=period)
            if not run.stopped:
                survivors.append((x0, v0))
            else:
                assert "pull-in" in run.stopped, run.stopped
    assert survivors == []
