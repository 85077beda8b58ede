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


def independent_map(scene: Scene, z0, restart: bool = True):
    """P(z0) and M of the periodic model x'' + mu x' + H(x) - 1 - F_em,mean(x) = Delta cos(omega tau) over one
    period, by Radau, restarted at each contact crossing (x = -3/2, where H'' is singular); restart=False: in
    one piece, for an orbit that touches the edge tangentially (a grazing orbit: a terminal crossing event would
    fire again and again there; the field is C^1 and the solver's error control shortens its steps at the edge)."""
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
        sol = solve_ivp(rhs, (t, T), y, method="Radau", rtol=INDEPENDENT_RTOL, atol=1e-14,
                        events=edge if restart else None)
        assert sol.status >= 0, sol.message
        t, y = sol.t[-1], sol.y[:, -1]
        if sol.status == 0:
            return y[:2], y[2:].reshape(2, 2)
        t = np.nextafter(t, T)  # past the crossing, so the event does not fire again at once


@pytest.fixture(scope="module")
def fold_branch():
    """The branch at Delta = 0.1 from omega 0.9 to 0.95 (one fold, one grazing), shared by the curve fixtures."""
    return cont.branch(FOLD_SCENE, "omega", 0.9, 0.95, points=10, double=False)


def curves_of_the_one(branch, kind, to2, from2, max_points):
    """The curves of `kind` continued in Delta from the branch's one point of that kind."""
    assert [pt.event for pt in branch.events()].count(kind) == 1
    return curves.curves_from_branch(branch, kind, "Delta", to2, from2, points=20, max_points=max_points)


@pytest.fixture(scope="module")
def fold_curve(fold_branch):
    return curves_of_the_one(fold_branch, "fold", 0.12, 0.08, max_points=5)


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
    # no fold-flip can lie on it: with rho1 = 1, det(M + I) = 2 (1 + rho2) = 2 (1 + det M) and det M = exp(-mu T) > 0
    assert min(pt.flip_test for pt in curve.points) > 2.0
    assert not any(pt.event == "fold-flip" for pt in curve.points)


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


# ----- grazing curves: P(z) = z and x_min = -3/2, and the grazing-fold where they meet the fold curve ----------

# the plain map's error ~1e-13 |z| per period (DOP853 at rtol 1e-13 on the state alone): far below GRAZING_TOL
PLAIN_RTOL = 1e-13
GRAZING_TOL = 1e-8  # |P(z) - z| and |x_min + 3/2| of the plain system at a re-solved point
PLAIN_FD = 1e-7  # forward differences of the plain map: error ~ 1e-13 / 1e-7 + 1e-7 |P''| ~ 1e-6, a Newton ratio ~1e-6


def plain_orbit(scene: Scene, z0) -> tuple[np.ndarray, float]:
    """(P(z0), x_min over the period) of x'' + mu x' + H(x) - 1 - F_em,mean(x) = Delta cos(omega tau) in the
    original time tau, the state alone (no variational equations), by SciPy's DOP853 in one piece; x_min is the
    least of x at the turning points v = 0 (integration events, located on the 7th-order dense output) and at
    both ends. Not restarted at the contact edge (unlike independent_map): these orbits touch it tangentially,
    where a terminal crossing event fires again and again; the field is C^1 there (H'' ~ s^(-1/2) integrable)
    and the solver's error control shortens its steps at the edge."""
    mu, Delta, omega = scene.mu, scene.Delta, scene.omega
    alpha, gamma, R = scene.alpha, scene.gamma, scene.R

    def rhs(t, y):
        return [y[1], Delta * math.cos(omega * t) - mu * y[1] - forces.hertz(y[0]) + 1.0
                + forces.electrostatic_mean(y[0], alpha, gamma, R)]

    def turning(t, y):
        return y[1]

    sol = solve_ivp(rhs, (0.0, 2.0 * math.pi / omega), np.asarray(z0, dtype=float), method="DOP853",
                    rtol=PLAIN_RTOL, atol=1e-15, events=turning)
    assert sol.status == 0, sol.message
    end = sol.y[:, -1]
    return end, min(float(z0[0]), float(end[0]), *(float(x) for x in sol.y_events[0][:, 0]))


def plain_grazing_newton(scene: Scene, z0, omega: float, max_iter: int = 20):
    """Newton on (P(z) - z, x_min + 3/2) = 0 in (x0, v0, omega) at the scene's Delta, the plain map's forward
    differences for the Jacobian: (x0, v0, omega, the residual, the Jacobian at the solution)."""
    def F(y):
        end, x_min = plain_orbit(scene.with_values(omega=y[2]), y[:2])
        return np.array([end[0] - y[0], end[1] - y[1], x_min + 1.5])

    y = np.array([z0[0], z0[1], omega], dtype=float)
    for _ in range(max_iter):
        f = F(y)
        J = np.column_stack([(F(y + PLAIN_FD * e) - f) / PLAIN_FD for e in np.eye(3)])
        if np.max(np.abs(f)) <= 1e-11:
            return y, f, J
        y = y - np.linalg.solve(J, f)
    raise AssertionError(f"plain Newton did not converge: residual {np.max(np.abs(f)):.3g}")


@pytest.fixture(scope="module")
def grazing_curve(fold_branch):
    # the branch at Delta = 0.1 from omega 0.9 over the fold at 0.933 back along the unstable middle branch,
    # which loses contact (grazing) at omega ~ 0.9235; the grazing curve from there down in Delta meets the
    # fold curve at the grazing-fold (Delta ~ 0.067) and turns back up along the stable upper branch
    return curves_of_the_one(fold_branch, "grazing", 0.1, 0.06, max_points=40)


@pytest.mark.long
def test_every_grazing_curve_point_is_re_solved_by_a_plain_newton(grazing_curve):
    (curve,) = grazing_curve.curves
    assert {pt.kind for pt in curve.points} == {"grazing"}
    assert max(abs(pt.g) for pt in curve.points) <= curves.TOL  # the engine's own grazing residual
    picked = curve.points[:: max(1, len(curve.points) // 4)]
    assert len(picked) >= 4
    for pt in picked:
        scene = FOLD_SCENE.with_values(omega=pt.p1, Delta=pt.p2)
        end, x_min = plain_orbit(scene, pt.z0)
        assert np.max(np.abs(end - pt.z0)) <= GRAZING_TOL, (pt.p1, pt.p2)
        assert abs(x_min + 1.5) <= GRAZING_TOL, (pt.p1, pt.p2)
        # from a start 1e-3 off in the state and 1e-4 in omega, at the same Delta
        y, f, J = plain_grazing_newton(scene, pt.z0 + np.array([1e-3, -1e-3]), pt.p1 + 1e-4)
        assert np.max(np.abs(f)) <= GRAZING_TOL
        # both points solve the system to GRAZING_TOL (the curve's under this plain map, above): they are one root
        # if they lie within |J^-1| (2 GRAZING_TOL) of each other, to first order
        bound = 2 * GRAZING_TOL * np.linalg.norm(np.linalg.inv(J), 2)
        assert np.linalg.norm(y - np.array([*pt.z0, pt.p1])) <= bound, (pt.p1, pt.p2)


@pytest.mark.long
def test_the_grazing_curve_meets_the_fold_curve_at_a_grazing_fold(grazing_curve):
    (curve,) = grazing_curve.curves
    located = [pt for pt in curve.points if pt.event == "grazing-fold"]
    assert len(located) == 1
    pt = located[0]
    # on either side of it the orbit's stability differs: det(M - I) = (1 - rho1)(1 - rho2) changes sign
    index = curve.points.index(pt)
    assert curve.points[index - 1].fold_test * curve.points[index + 1].fold_test < 0.0
    # the located orbit solves the independent fold system (Radau, variational equations) and touches the edge
    scene = FOLD_SCENE.with_values(omega=pt.p1, Delta=pt.p2)
    end, M = independent_map(scene, pt.z0, restart=False)
    assert np.max(np.abs(end - pt.z0)) <= FOLD_SYSTEM_TOL
    assert abs(np.linalg.det(M - np.eye(2))) <= FOLD_SYSTEM_TOL
    assert abs(plain_orbit(scene, pt.z0)[1] + 1.5) <= GRAZING_TOL
    # the fold curves of a branch above it (Delta = 0.07: its contact-loss fold at omega ~ 0.940) find it as the zero
    # of x_min + 3/2 along the fold, with no grazing curve given
    branch = cont.branch(FOLD_SCENE.with_values(Delta=0.07), "omega", 0.93, 0.965, points=10, double=False)
    assert [q.event for q in branch.events()].count("fold") == 2
    fold = curves.curves_from_branch(branch, "fold", "Delta", 0.07, 0.066, points=20, max_points=30)
    on_fold = [q for c in fold.curves for q in c.points if q.event == "grazing-fold"]
    assert len(on_fold) == 1
    # one point located on two curves (by Brent on det(M - I) along grazing curves started from different
    # orbits): both to the curves' tolerance 1e-10 over a conditioning ~ 1 .. 100 of the located point
    assert abs(on_fold[0].p1 - pt.p1) <= 1e-8 and abs(on_fold[0].p2 - pt.p2) <= 1e-8


# ----- codimension two beyond the cusp: fold-flip and grazing-flip ------------------------------------------------

class FoldFlipMap(curves.Augmented):
    """A planar map with a fold-flip, standing in for the period map (which has none: det M = exp(-mu n T) > 0, so
    multipliers +1 and -1 never meet): P(x, y) = (x + p1 - x^2 + y^2 / 10, (x - 1 - p2) y + y^3). Its fixed points
    (+-sqrt(p1), 0) have the multipliers 1 - 2x and x - 1 - p2: the fold curve is p1 = 0 (x = 0), where
    det(M + I) = 2 (x - p2) changes sign at p2 = 0; the flip curve is p2 = x, p1 = x^2, where det(M - I) = 4 x
    changes sign at x = 0. Both meet at the fold-flip (p1, p2) = (0, 0), z = 0 (multipliers 1 and -1). x_min stays
    far from the contact edge (no grazing event)."""

    def at(self, p1, p2):
        return self.scene  # the map's parameters are not the scene's

    def map(self, z, p1, p2, param=None):
        from vibrofmu.analyses import shooting as sh

        x, y = float(z[0]), float(z[1])
        end = np.array([x + p1 - x * x + 0.1 * y * y, (x - 1.0 - p2) * y + y ** 3])
        M = np.array([[1.0 - 2.0 * x, 0.2 * y], [y, x - 1.0 - p2 + 3.0 * y * y]])
        return sh.PeriodMap(omega=1.0, z0=np.array([x, y]), end=end, monodromy=M, d_param=np.array([1.0, 0.0]),
                            segments=[], extrema=np.array([0.0]), contact_crossings=0)


def _toy_curve(kind, z0, p1, p2, direction):
    system = FoldFlipMap(Scene(), kind, "omega", "Delta", (1.0, 1.0))
    start = curves.start_point(system, z0, p1, p2)
    points, _, _ = curves.follow(system, start, direction, (-0.3, 0.3), max_step=0.05, max_points=40)
    return system, points


@pytest.mark.parametrize("kind, z0, p1, p2, direction", [("fold", (0.01, 0.0), 0.001, -0.3, 1.0),
                                                         ("period-doubling", (0.3, 0.0), 0.09, 0.3, -1.0)])
def test_a_fold_flip_is_located_on_the_fold_curve_and_on_the_flip_curve(kind, z0, p1, p2, direction):
    system, points = _toy_curve(kind, z0, p1, p2, direction)
    located = [pt for pt in points if pt.event]
    assert [pt.event for pt in located] == ["fold-flip"]
    pt = located[0]
    # error bound: the point solves the augmented system to curves.TOL (|F|_inf <= 1e-10 per equation, 4 with
    # the hyperplane), Brent's bracket on the test function adds ~1e-12 of a step; to first order the error in
    # u = (x, y, p1, p2) is below |K^-1|_2 sqrt(4) TOL, K the exact 4 x 4 Jacobian at the fold-flip (the curve's
    # tangent, p2 on the fold curve, x on the flip curve, as the last row; g's row by the bordered system)
    tangent = np.array([0.0, 0.0, 0.0, 1.0]) if kind == "fold" else np.array([1.0, 0.0, 0.0, 1.0]) / math.sqrt(2)
    M = np.diag([1.0, -1.0])
    A = M + curves.SIGN[kind] * np.eye(2)
    g, w, v = curves.sh.bordered_test(A, *curves.sh.border_of(A))
    dM = {0: np.array([[-2.0, 0.0], [0.0, 1.0]]), 1: np.array([[0.0, 0.2], [1.0, 0.0]]), 2: np.zeros((2, 2)),
          3: np.array([[0.0, 0.0], [0.0, -1.0]])}  # dM/dx, dM/dy, dM/dp1, dM/dp2 at the origin
    K = np.zeros((4, 4))
    K[:2, :2] = M - np.eye(2)
    K[:2, 2] = [1.0, 0.0]
    K[2] = [-float(v @ dM[k] @ w) for k in range(4)]
    K[3] = tangent
    bound = np.linalg.norm(np.linalg.inv(K), 2) * 2.0 * curves.TOL
    assert np.linalg.norm([pt.z0[0], pt.z0[1], pt.p1, pt.p2]) <= bound, (pt.z0, pt.p1, pt.p2, bound)
    # the test functions on either side have opposite signs, and at the point both determinants vanish
    index = points.index(pt)
    test = pt.flip_test if kind == "fold" else pt.fold_test
    assert abs(pt.flip_test) <= 4 * bound and abs(pt.fold_test) <= 4 * bound  # |d det / du| <= 4 near the origin
    before, after = points[index - 1], points[index + 1]
    sides = [(q.flip_test if kind == "fold" else q.fold_test) for q in (before, after)]
    assert sides[0] * sides[1] < 0.0 and abs(test) < min(abs(s) for s in sides)


CHAOS_SCENE = Scene(mu=0.1, Delta=2.5, R=3.0, beta=0.0, gamma=0.0)  # docs/continuation.md's doubling cascade scene
FD_STEP = 1e-5  # central differences of the plain map for its monodromy (the tolerance below)
# |det(M + I)| of that monodromy at a located grazing-flip: each entry of M is off by the plain map's error eps over
# the step (eps ~ 1e-12: its |P(z) - z| at the located points, engine tolerance included) plus the truncation
# h^2 |P'''| / 6 ~ 1e-10 |P'''|: ~1e-7 per entry for |P'''| <= 1e3; det(M + I) = (M11 + 1)(M22 + 1) - M12 M21 moves
# by at most (|M + I|_1 + |M + I|_inf) 1e-7 ~ 1e-6 for entries O(1)
FD_DET_TOL = 1e-6


def plain_monodromy(scene: Scene, z0, step: float = FD_STEP) -> np.ndarray:
    """M = dP/dz by central differences of plain_orbit (DOP853 at rtol 1e-13 on the state alone, no variational
    equations): an estimate that shares nothing with the engine's."""
    return np.column_stack([(plain_orbit(scene, z0 + step * e)[0] - plain_orbit(scene, z0 - step * e)[0])
                            / (2 * step) for e in np.eye(2)])


# the period-2T orbits of the doubling scene cross the contact edge four times, twice nearly tangentially, in the
# plain map's one piece (not restarted), where its error control meets H'' ~ s^(-1/2): its error there is
# eps ~ 1e-10 (measured: central differences at 1e-6 and 1e-5 scatter by 1e-5 .. 4e-4 in det(M + I), as eps / h
# predicts), so the step is 1e-4: eps / h ~ 1e-6 per entry plus h^2 |d3P| / 6 ~ 1e-8 |d3P|; det(M2 M1 + I) of the
# product of two such factors (entries O(1)) moves by at most ~4e-6
FD2_STEP = 1e-4
FD2_DET_TOL = 5e-6


@pytest.mark.slow
def test_the_flip_curve_of_the_doubling_scene_meets_grazing_at_two_grazing_flips():
    # the period doubling of the documented cascade scene (omega ~ 2.051 at Delta = 2.5) continued in Delta: the
    # flip orbit loses contact at Delta ~ 4.75 going up, and again at Delta ~ 1.98 (omega ~ 1.54) after the curve
    # turns at Delta ~ 1.68; each crossing of x_min = -3/2 is a grazing-flip, located on the grazing curve through it
    branch = cont.branch(CHAOS_SCENE, "omega", 2.2, 2.0, points=10, double=False)
    assert [pt.event for pt in branch.events()] == ["period-doubling"]
    found = curves.curves_from_branch(branch, "period-doubling", "Delta", 5.0, 1.6, points=40)
    (curve,) = found.curves
    located = [pt for pt in curve.points if pt.event]
    assert [pt.event for pt in located] == ["grazing-flip", "grazing-flip"]
    for pt in located:
        index = curve.points.index(pt)
        before, after = curve.points[index - 1], curve.points[index + 1]
        assert (before.x_min - cont.CONTACT_EDGE) * (after.x_min - cont.CONTACT_EDGE) < 0.0
        scene = CHAOS_SCENE.with_values(omega=pt.p1, Delta=pt.p2)
        end, x_min = plain_orbit(scene, pt.z0)
        assert np.max(np.abs(end - pt.z0)) <= GRAZING_TOL and abs(x_min + 1.5) <= GRAZING_TOL, (pt.p1, pt.p2)
        M = plain_monodromy(scene, pt.z0)
        assert abs(np.linalg.det(M + np.eye(2))) <= FD_DET_TOL, (pt.p1, pt.p2)
        # and by the Radau variational equations (no finite differences), in one piece through the grazing
        end, M = independent_map(scene, pt.z0, restart=False)
        assert abs(np.linalg.det(M + np.eye(2))) <= FOLD_SYSTEM_TOL, (pt.p1, pt.p2)
        # the other multiplier is -det M = -exp(-mu T) (Liouville): no fold-flip there, det(M - I) = 2 (1 + det M)
        assert np.linalg.det(M - np.eye(2)) > 2.0
    # no fold-flip anywhere on the flip curve: det(M - I) = 2 (1 + det M) > 2 at every point
    assert min(pt.fold_test for pt in curve.points) > 2.0
    # the grazing curve from the grazing of the branch at Delta = 5 finds the upper one as the zero of det(M + I)
    # along it, with no flip curve given: one point located on two curves to the curves' tolerance 1e-10 over a
    # conditioning ~ 1 .. 100
    above = cont.branch(CHAOS_SCENE.with_values(Delta=5.0), "omega", 2.4, 2.13, points=10, double=False)
    grazing = curves.curves_from_branch(above, "grazing", "Delta", 5.0, 4.5, points=40)
    on_grazing = [q for c in grazing.curves for q in c.points if q.event == "grazing-flip"]
    assert len(on_grazing) == 1
    upper = max(located, key=lambda q: q.p2)
    assert abs(on_grazing[0].p1 - upper.p1) <= 1e-8 and abs(on_grazing[0].p2 - upper.p2) <= 1e-8


# ----- pull-in ahead: a curve creeping towards an electrode ------------------------------------------------------

def test_the_saddle_gaps_balance_the_electrode_pull_against_the_load():
    # written out here (not through forces): out of contact below, g = -1 - (alpha + gamma)/(2 - l)^2 + alpha/l^2
    # with l the lower gap; in contact above, g = (1 + 2x/3)^(3/2) - 1 - (alpha + gamma)/u^2 + alpha/(2 - u)^2 with u
    # the upper gap, x = 3R/2 (1 - u); each term O(1) at the root, so Brent's rounding leaves ~1e-15 of them
    scene = FOLD_SCENE.with_values(omega=0.64)
    alpha, gamma, R = scene.alpha, scene.gamma, scene.R
    upper, lower = cont.saddle_gaps(scene)
    assert R * (1.0 - lower) > 1.0  # the lower saddle lies out of contact, the upper one in contact
    assert abs(alpha / lower**2 - 1.0 - (alpha + gamma) / (2.0 - lower) ** 2) <= 1e-12
    x = 1.5 * R * (1.0 - upper)
    assert abs((1.0 + 2.0 * x / 3.0) ** 1.5 - 1.0 - (alpha + gamma) / upper**2 + alpha / (2.0 - upper) ** 2) <= 1e-12
    # no bias, no drive: nothing pulls towards either electrode, no saddle
    assert cont.saddle_gaps(scene.with_values(alpha=0.0, gamma=0.0)) == (None, None)


def test_a_budget_stop_is_pull_in_ahead_only_against_an_electrode():
    from types import SimpleNamespace

    scene = FOLD_SCENE.with_values(omega=0.64)
    lower = cont.saddle_gaps(scene)[1]
    x_of_gap = -1.5 * scene.R * (1.0 - cont.CREEP_FACTOR * lower)  # the lowest point at CREEP_FACTOR x the saddle gap
    reason = "stopped at 5 points at omega = 0.64"
    assert cont.budget_reason(reason, scene, SimpleNamespace(x_min=x_of_gap + 1e-9, x_max=1.0)) == reason
    assert cont.budget_reason(reason, scene, SimpleNamespace(x_min=x_of_gap - 1e-9, x_max=1.0)).startswith(
        "pull-in ahead: " + reason)
    assert cont.budget_reason("left the range", scene, SimpleNamespace(x_min=x_of_gap - 1e-9, x_max=1.0)) == \
        "left the range"


def test_the_fold_curve_creeping_towards_the_lower_electrode_ends_as_pull_in_ahead():
    # a point of the mu = 0.05, R = 3 fold curve from the branch at Delta = 0.1 (its lower fold's piece going up in
    # Delta), where it creeps towards the lower electrode (x_min -4.3398, gap 0.0356: 1.12 x the saddle's) and
    # used to stop on its point budget unmarked
    system = curves.Augmented(FOLD_SCENE, "fold", "omega", "Delta", (0.6, 0.18))
    start = curves.start_point(system, (-2.496664457140037, 1.9084762832938378), 0.6425656943867719,
                               0.12970845946241527)
    points, why, _ = curves.follow(system, start, 1.0, (0.02, 0.2), max_step=1.5 / 40, max_points=4)
    assert len(points) == 4 and why.startswith("pull-in ahead: stopped at 4 points")
    assert "lower electrode" in why
    # drawn as an end, not as a cap: the pull-in mark in the legend, no cross
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from vibrofmu.analyses import continuation_output as output

    fig, ax = plt.subplots()
    output.draw_curves(ax, curves.Curves([curves.Curve("fold", 0, points, why, [(points[-1], why)])],
                                          ("omega", "Delta")), set())
    labels = [line.get_label() for line in ax.get_lines()]
    plt.close(fig)
    assert "curve ends creeping towards pull-in" in labels and "curve stopped (point budget or step)" not in labels


@pytest.mark.slow
def test_the_doubled_branch_flip_curve_solves_an_independent_period_two_flip_system():
    # the cascade of the doubling scene: the period-2T branch's own doubling (to 4T, omega ~ 1.862 at Delta = 2.5)
    # continued in Delta; its points are fixed points of P^2 with a multiplier -1 of dP^2/dz, not of P
    result = cont.branch(CHAOS_SCENE, "omega", 2.2, 1.785, points=40, max_period=2)
    (doubled,) = result.doubled
    assert [pt.event for pt in doubled.events()].count("period-doubling") == 1
    found = curves.curves_from_branch(doubled, "period-doubling", "Delta", 2.7, 2.5, points=40,
                                      scale1=abs(2.2 - 1.785))
    (curve,) = found.curves
    assert {pt.periods for pt in curve.points} == {2} and len(curve.points) >= 5
    for pt in curve.points[:: max(1, len(curve.points) // 4)]:
        # by the plain map (DOP853 at rtol 1e-13 on the state alone, one piece; Radau's restarts at the edge crawl
        # here: the 2T orbits pass the edge nearly tangentially), P^2 = P o P and its monodromy M(z1) M(z0) by
        # central differences (FD2_DET_TOL)
        scene = CHAOS_SCENE.with_values(omega=pt.p1, Delta=pt.p2)
        z1 = plain_orbit(scene, pt.z0)[0]
        z2 = plain_orbit(scene, z1)[0]
        assert np.max(np.abs(z2 - pt.z0)) <= GRAZING_TOL, (pt.p1, pt.p2)
        M = plain_monodromy(scene, z1, FD2_STEP) @ plain_monodromy(scene, pt.z0, FD2_STEP)
        assert abs(np.linalg.det(M + np.eye(2))) <= FD2_DET_TOL, (pt.p1, pt.p2)
        assert np.max(np.abs(z1 - pt.z0)) > 1e-3  # truly of period 2T
    # going down in Delta the curve stalls where a local maximum of its orbit touches the contact edge from the
    # free side (a grazing the lowest point does not see): the stop reason says so
    down = curves.curves_from_branch(doubled, "period-doubling", "Delta", 2.5, 2.3, points=40,
                                     scale1=abs(2.2 - 1.785))
    (curve,) = down.curves
    assert "grazes the contact edge" in curve.stop_reason
    last = curve.points[-1]
    scene = CHAOS_SCENE.with_values(omega=last.p1, Delta=last.p2)
    turning = cont.n_period_map(scene, "omega", last.z0, 2, dense=True).extrema
    assert np.min(np.abs(turning - cont.CONTACT_EDGE)) <= curves.GRAZING_NEAR


@pytest.mark.slow
def test_follow_continues_the_curves_of_the_doubled_branches_too(tmp_path, capsys):
    import pyarrow.parquet as pq

    from vibrofmu.cli import main

    code = main(["continuation", "--param", "omega", "--from", "2.2", "--to", "1.785", "--points", "20",
                 "--max-period", "2", "--set", "mu=0.1", "--set", "Delta=2.5", "--set", "R=3", "--set", "beta=0",
                 "--set", "gamma=0", "--follow", "period-doubling", "--param2", "Delta", "--to2", "2.6",
                 "--out", str(tmp_path)])
    assert code == 0
    table = pq.read_table(tmp_path / "curves.parquet").to_pydict()
    assert set(zip(table["kind"], table["periods"])) == {("period-doubling", 1), ("period-doubling", 2)}
    assert "period-doubling curve 1 of period-2T orbits" in capsys.readouterr().out
