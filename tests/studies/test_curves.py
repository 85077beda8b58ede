"""Two-parameter curves of folds (harness/vibrofmu/analyses/curves.py) and the tangent-free fold location of a
branch, each point checked against an independent fold system: the orbit and its monodromy integrated by
SciPy's Radau (an implicit method, not the DOP853 of the engine) with variational equations written here."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vibromodel import forces
from vibromodel.parameters import Scene
from vibrofmu.analyses import continuation as cont
from vibrofmu.analyses import curves

FOLD_SCENE = Scene(mu=0.05, Delta=0.1, R=3.0, beta=0.0, gamma=0.0)  # two folds at omega ~ 0.829, 0.933
GRAZING_FOLD_SCENE = Scene(mu=0.05, R=2.0, omega=0.8, beta=0.0, gamma=0.0)  # fold and grazing 2.5e-6 apart in Delta
# Radau at rtol 1e-12: its global error over one period is a small multiple of that, ~1e-11, far below 1e-8
INDEPENDENT_RTOL = 1e-12
FOLD_SYSTEM_TOL = 1e-8  # |P(z) - z| and |det(M - I)| of the independent fold system at each curve point


def independent_map(scene: Scene, z0):
    """P(z0) and M of the periodic model x'' + mu x' + H(x) - 1 - F_em,mean(x) = Delta cos(omega tau) over one
    period, by Radau, restarted at each contact crossing (x = -3/2, where H'' is singular)."""
    mu, Delta, omega = scene.mu, scene.Delta, scene.omega
    alpha, gamma, R = scene.alpha, scene.gamma, scene.R

    def g(x):
        return forces.hertz(x) - 1.0 - forces.electrostatic_mean(x, alpha, gamma, R)

    def g_x(x):
        return forces.hertz_stiffness(x) - forces.electrostatic_mean_stiffness(x, alpha, gamma, R)

    def rhs(t, y):
        x, v = y[0], y[1]
        Phi = y[2:].reshape(2, 2)
        J = np.array([[0.0, 1.0], [-g_x(x), -mu]])
        return np.concatenate([[v, Delta * math.cos(omega * t) - mu * v - g(x)], (J @ Phi).ravel()])

    def edge(t, y):
        return y[0] + 1.5

    edge.terminal = True
    T = 2.0 * math.pi / omega
    t, y = 0.0, np.concatenate([np.asarray(z0, dtype=float), np.eye(2).ravel()])
    while True:
        sol = solve_ivp(rhs, (t, T), y, method="Radau", rtol=INDEPENDENT_RTOL, atol=1e-14, events=edge)
        assert sol.status >= 0, sol.message
        t, y = sol.t[-1], sol.y[:, -1]
        if sol.status == 0:
            return y[:2], y[2:].reshape(2, 2)
        t = np.nextafter(t, T)  # past the crossing, so the event does not fire again at once


@pytest.fixture(scope="module")
def fold_curve():
    branch = cont.branch(FOLD_SCENE, "omega", 0.9, 0.95, points=10, double=False)
    assert [pt.event for pt in branch.events()].count("fold") == 1
    return curves.curves_from_branch(branch, "fold", "Delta", 0.12, 0.08, points=20, max_points=5)


@pytest.mark.long
def test_every_fold_curve_point_solves_an_independent_fold_system(fold_curve):
    (curve,) = fold_curve.curves
    assert len(curve.points) >= 8
    deltas = [pt.p2 for pt in curve.points]
    assert min(deltas) < 0.1 < max(deltas)  # both ways from the branch
    for pt in curve.points[::2]:
        end, M = independent_map(FOLD_SCENE.with_values(omega=pt.p1, Delta=pt.p2), pt.z0)
        assert np.max(np.abs(end - pt.z0)) <= FOLD_SYSTEM_TOL, (pt.p1, pt.p2)
        assert abs(np.linalg.det(M - np.eye(2))) <= FOLD_SYSTEM_TOL, (pt.p1, pt.p2)


@pytest.mark.long
def test_curves_parquet_has_one_row_per_point_with_both_parameters_named(fold_curve, tmp_path):
    import pyarrow.parquet as pq

    from vibrofmu.analyses import continuation_output as output

    output.write_curves(tmp_path, fold_curve, FOLD_SCENE, "fold curves")
    table = pq.read_table(tmp_path / "curves.parquet")
    assert {"kind", "curve", "omega", "Delta", "x0", "v0", "period", "x_min", "x_max", "event"} <= set(
        table.column_names)
    assert table.num_rows == sum(len(c.points) for c in fold_curve.curves)
    assert set(table.column("kind").to_pylist()) == {"fold"}
    assert (tmp_path / "curves.png").stat().st_size > 10000 and (tmp_path / "curves.pdf").stat().st_size > 1000


@pytest.mark.long
def test_the_fold_beside_a_grazing_is_where_m_minus_i_is_singular():
    # the fold and the grazing of the Delta branch lie 2.5e-6 apart: the fold is located by the bordered test
    # function of M - I, not by the branch tangent; the independent map must find M - I singular there and the
    # grazing orbit touching the contact edge
    result = cont.branch(GRAZING_FOLD_SCENE, "Delta", 0.38, 0.39, points=10, double=False, max_points=20)
    events = {pt.event: pt for pt in result.events()}
    fold, grazing = events["fold"], events["grazing"]
    assert 1e-7 < fold.p - grazing.p < 1e-5
    end, M = independent_map(GRAZING_FOLD_SCENE.with_values(Delta=fold.p), fold.z0)
    assert np.max(np.abs(end - fold.z0)) <= FOLD_SYSTEM_TOL
    assert abs(np.linalg.det(M - np.eye(2))) <= FOLD_SYSTEM_TOL
    rho = np.linalg.eigvals(M)
    assert np.min(np.abs(rho - 1.0)) <= 1e-6  # a multiplier at +1 (|rho - 1| ~ |det(M - I)| / (1 - rho2))
    assert fold.x_min > cont.CONTACT_EDGE  # the fold orbit still in contact; the grazing one touches the edge
    assert abs(grazing.x_min - cont.CONTACT_EDGE) <= 1e-9


def _at(p1, p2, z0=(0.0, 0.0)):
    return curves.CurvePoint(kind="fold", p1=p1, p2=p2, z0=np.array(z0), periods=1, period=1.0,
                             multipliers=np.ones(2), x_min=0.0, x_max=0.0, residual=0.0, g=0.0, quadratic=0.0)


def test_a_cusp_is_kept_only_where_the_parameters_turn():
    # the measured cusp of the mu = 0.05 curve (omega and Delta both turn) and the dropped sign change near pull-in
    # (both go on monotonically, omega at 0.12 of the state's move): points 183, 184 (located), 185 and 911, 912, 913
    # of that curve
    assert curves.parameters_turn(_at(0.9609378590714457, 0.05962776012493513, (0.3741620135413197, 0.9981036012690473)),
                                  _at(0.9609381117160323, 0.059627524664295196, (0.3726394323978897, 0.9996554486362746)),
                                  _at(0.9609365970966298, 0.059628928118328234, (0.3689094676246529, 1.0034571954272644)))
    assert not curves.parameters_turn(
        _at(0.6367760693467331, 0.12980414610676405, (-2.5412460274615416, 1.8856721958133948)),
        _at(0.6367725822063229, 0.12980420872287107, (-2.5412729294051015, 1.885658306944098)),
        _at(0.6367693204547975, 0.12980426729861164, (-2.541298092542524, 1.8856453156377457)))
    # monotone but by far less than the step: a turning below the resolution, kept
    assert curves.parameters_turn(_at(0.0, 0.0, (0.0, 0.0)), _at(1e-9, 1e-9, (0.5, 0.0)), _at(2e-9, 2e-9, (1.0, 0.0)))
