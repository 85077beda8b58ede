"""Two-parameter continuation of fold, period-doubling and grazing points of the periodic orbits
(docs/continuation.md, Two-parameter curves), on the shooting formulation of shooting.py.

A fold (a Floquet multiplier +1) or a period doubling (-1) of the orbit z = P(z; p1, p2) is one equation more
than an orbit: the minimally augmented system (Govaerts, Numerical Methods for Bifurcations of Dynamical
Equilibria, 2000, ch. 4)

    P(z; p1, p2) - z = 0,    g(z; p1, p2) = 0,

with g the bordered test function of A = M - I (fold) or M + I (period doubling), M = dP/dz:

    [[A, b], [c^T, 0]] [w; g] = [0; 1]     and its transpose   [v^T, h] [[A, b], [c^T, 0]] = [0, 1],

b, c the left and right singular vectors of A's smallest singular value at the last Jacobian (fixed during a
correction). g = 0 exactly where A is singular, whatever b and c (as long as the bordered matrix is regular):
the fold is located without the branch tangent. Three equations in u = (x0, v0, p1/s1, p2/s2): a curve,
continued by Keller's pseudo-arclength method like a branch (shooting.arclength_correct's recipe, 4 unknowns).

Derivatives: the period map gives M and dP/dp1 (variational equations) and dP/dp2 (a second map with the
sensitivity to p2); g's gradient is g_y = -v^T (dA/dy) w (the bordered system's derivative), dA/dy = dM/dy by
forward differences of M over a relative step FD_STEP (4 maps). The corrector is a chord method: the Jacobian
is formed once per point at the predictor and reused (its base map is the first iteration's residual); each
further iteration re-evaluates the exact residual (1 map).

Codimension two on a fold curve: the cusp, where the fold's quadratic coefficient a = v^T P_zz(w, w) / 2
changes sign. The Jacobian's row g_z gives it for free: g_z w = -v^T (dM/dz w) w = -2 a (v normalised by the
bordered system), so a sign change of g_z w between two points is located by Brent on the arclength; at the
cusp both parameters turn (the curve's tangent lies in the state): a located point where they do not is dropped
(parameters_turn).

Grazing (the orbit touching the contact edge x = -3/2 at its lowest turning point) is one equation more than an
orbit too, g = x_min(z; p1, p2) + 3/2 with x_min the minimum over the orbit's turning points (v = 0, located as
integration events). Its gradient is dx_min/dy by the same forward differences (4 maps; x_min is differentiable:
at a nondegenerate minimum dx_min/dy = dx(s*)/dy, s* the turning phase). Codimension two on both a fold and a
grazing curve: the grazing-fold, a fold whose orbit touches the contact edge, where the two curves meet -- on a
fold curve a sign change of x_min + 3/2, on a grazing curve a sign change of det(M - I), each located by Brent on
the arclength.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import brentq

from vibromodel.parameters import Scene

from vibrofmu.analyses import shooting as sh
from vibrofmu.analyses.continuation import CONTACT_EDGE, budget_reason

KINDS = ("fold", "period-doubling", "grazing")  # what a curve follows
SIGN = {"fold": -1.0, "period-doubling": 1.0}  # A = M + SIGN I: the sign of the multiplier that sits at 1
# forward-difference step of M, relative to max(1, |y|): the period map's error ~ rtol 1e-11 |M| over the step
# 1e-6 gives dM/dy to ~1e-5, and the truncation ~ 1e-6 |M''|: the chord Newton converges with ratio ~1e-5
FD_STEP = 1e-6
TOL = 1e-10  # |P(z) - z|_inf and |g|: shooting.NEWTON_TOL
TURN = 0.2  # largest accepted turning of the tangent per step (rad), as for a branch
# parameters_turn: over a step through a cusp the parameters move by O(step^2), measured <= 1e-6 of the state's move
# where they did not visibly turn (eps = 1/32 of cusp_order: noise); through the false one by 0.12 of it
TURN_SLOPE = 0.01
# chord iterations for a located point: 1e-4 (a predictor's residual) to TOL at the linear rate ~0.25 measured at a
# grazing orbit on a fold curve (locate) takes ~13; 40 leaves room for a slower rate
LOCATE_ITERATIONS = 40
# how far along the grazing curve (in fold-curve steps) a grazing-fold is looked for from the fold curve's crossing
# of x_min = -3/2: the two curves cross at the point, so it lies within about one step of that grazing orbit
GRAZING_FOLD_SEARCH = (0.25, 1.0, 4.0)


@dataclass
class CurvePoint:
    """A point of a two-parameter curve: the orbit z (a fixed point of P^periods) at (p1, p2) with a multiplier
    at +1 (fold) or -1 (period doubling)."""

    kind: str
    p1: float
    p2: float
    z0: np.ndarray
    periods: int
    period: float
    multipliers: np.ndarray
    x_min: float
    x_max: float
    residual: float  # |P(z) - z|_inf
    g: float  # the bordered test function
    quadratic: float  # g_z w (proportional to the fold's quadratic coefficient; its sign change is the cusp); NaN
    # on a grazing curve
    event: str = ""
    fold_test: float = math.nan  # det(M - I) = (1 - rho1)(1 - rho2): its sign change on a grazing curve is a grazing-fold
    flip_test: float = math.nan  # det(M + I) = (1 + rho1)(1 + rho2): ... a grazing-flip
    tangent: np.ndarray | None = field(default=None, repr=False)


@dataclass
class Curve:
    kind: str
    index: int
    points: list
    stop_reason: str = ""
    ends: list = field(default_factory=list)  # (the last point, why it stopped) of each piece continued


class Augmented:
    """The minimally augmented system of `kind` for the periodic orbits of `scene` in (param1, param2)."""

    def __init__(self, scene: Scene, kind: str, param1: str, param2: str, scales: tuple[float, float],
                 periods: int = 1, rtol: float = sh.RTOL):
        if kind not in KINDS:
            raise ValueError(f"curve kind {kind!r}: supported {', '.join(KINDS)}")
        self.scene, self.kind, self.params, self.scales = scene, kind, (param1, param2), scales
        self.periods, self.rtol, self.sign = periods, rtol, SIGN.get(kind, 0.0)
        self.grazing = kind == "grazing"
        self.border: tuple[np.ndarray, np.ndarray] | None = None

    def at(self, p1: float, p2: float) -> Scene:
        return self.scene.with_values(**{self.params[0]: float(p1), self.params[1]: float(p2)})

    def map(self, z, p1: float, p2: float, param: str | None = None) -> sh.PeriodMap:
        s = self.at(p1, p2)
        return sh.period_map(sh.PeriodicModel(s), z, s.omega, self.rtol, param or self.params[0], self.periods,
                             dense=False)

    def unscale(self, u: np.ndarray) -> tuple[np.ndarray, float, float]:
        return u[:2], u[2] * self.scales[0], u[3] * self.scales[1]

    def A(self, monodromy: np.ndarray) -> np.ndarray:
        return monodromy + self.sign * np.eye(2)

    def set_border(self, monodromy: np.ndarray) -> None:
        """b, c: the singular vectors of A's smallest singular value (the bordered matrix is then best conditioned)."""
        self.border = sh.border_of(self.A(monodromy))

    def bordered(self, monodromy: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """(g, w, v) of the bordered system (shooting.bordered_test)."""
        return sh.bordered_test(self.A(monodromy), *self.border)

    def condition(self, pmap: sh.PeriodMap) -> float:
        """The defining condition at the orbit of `pmap`: x_min + 3/2 (grazing) or the bordered test function."""
        if self.grazing:
            return pmap.x_min - CONTACT_EDGE
        return self.bordered(pmap.monodromy)[0]

    def residual(self, u: np.ndarray) -> tuple[np.ndarray, sh.PeriodMap]:
        z, p1, p2 = self.unscale(u)
        pmap = self.map(z, p1, p2)
        return np.append(pmap.end - z, self.condition(pmap)), pmap

    def jacobian(self, u: np.ndarray) -> tuple[np.ndarray, float, tuple]:
        """The 3 x 4 Jacobian of (P - z, g) in u (module doc), g_z w (the cusp's test function; NaN for grazing)
        and the residual at u (from the same period map: the corrector's first iteration needs no map of its own)."""
        z, p1, p2 = self.unscale(u)
        base = self.map(z, p1, p2)
        if self.grazing:
            g, w, v = base.x_min - CONTACT_EDGE, None, None
        else:
            self.set_border(base.monodromy)
            g, w, v = self.bordered(base.monodromy)
        J = np.zeros((3, 4))
        J[:2, :2] = base.monodromy - np.eye(2)
        J[:2, 2] = base.d_param * self.scales[0]
        y = np.array([z[0], z[1], p1, p2])
        for k in range(4):
            step = FD_STEP * max(1.0, abs(y[k]))
            yk = y.copy()
            yk[k] += step
            shifted = self.map(yk[:2], yk[2], yk[3])
            scale = 1.0 if k < 2 else self.scales[k - 2]
            if self.grazing:
                J[2, k] = (shifted.x_min - base.x_min) / step * scale
            else:
                J[2, k] = -float(v @ ((shifted.monodromy - base.monodromy) / step) @ w) * scale
            if k == 3:  # dP/dp2 by the same forward difference (a chord Jacobian and the tangent need ~1e-5)
                J[:2, 3] = (shifted.end - base.end) / step * self.scales[1]
        quadratic = math.nan if self.grazing else float(J[2, :2] @ w)
        return J, quadratic, (np.append(base.end - z, g), base)

    def quadratic(self, u: np.ndarray, base: sh.PeriodMap) -> float:
        """g_z w at u (the cusp's test function: module doc), dM/dz by forward differences (2 maps); the
        bordering vectors are the point's own. NaN on a grazing curve (no maps)."""
        if self.grazing:
            return math.nan
        z, p1, p2 = self.unscale(u)
        self.set_border(base.monodromy)
        _, w, v = self.bordered(base.monodromy)
        total = 0.0
        for k in range(2):
            step = FD_STEP * max(1.0, abs(z[k]))
            zk = np.array(z, dtype=float)
            zk[k] += step
            dM = (self.map(zk, p1, p2).monodromy - base.monodromy) / step
            total += -float(v @ dM @ w) * w[k]
        return total

    def point(self, u: np.ndarray, pmap: sh.PeriodMap, g: float, quadratic: float) -> CurvePoint:
        z, p1, p2 = self.unscale(u)
        s = self.at(p1, p2)
        return CurvePoint(kind=self.kind, p1=float(p1), p2=float(p2), z0=np.array(z, dtype=float),
                          periods=self.periods, period=sh.TWO_PI * self.periods / s.omega,
                          multipliers=sh.multipliers(pmap.monodromy), x_min=pmap.x_min, x_max=pmap.x_max,
                          residual=float(np.max(np.abs(pmap.end - z))), g=g, quadratic=quadratic,
                          fold_test=float(np.linalg.det(pmap.monodromy - np.eye(2))),
                          flip_test=float(np.linalg.det(pmap.monodromy + np.eye(2))))


def null_vector(J: np.ndarray, previous: np.ndarray | None) -> np.ndarray:
    """The unit null vector of the 3 x 4 Jacobian (last right singular vector), oriented along `previous`."""
    t = np.linalg.svd(J)[2][-1]
    if previous is not None and np.dot(t, previous) < 0.0:
        t = -t
    return t


def correct(system: Augmented, u_pred: np.ndarray, normal: np.ndarray, max_iter: int = 8,
            tol: float = TOL) -> tuple[np.ndarray, sh.PeriodMap, np.ndarray, int]:
    """Chord Newton on ((P - z, g), normal . (u - u_pred)) = 0 with the Jacobian at u_pred.
    Returns (u, its period map, the Jacobian at u_pred, iterations); ShootingError if it does not converge."""
    J, _, first = system.jacobian(u_pred)
    K = np.vstack([J, normal])
    u = u_pred.copy()
    for iteration in range(max_iter):
        F, pmap = first if iteration == 0 else system.residual(u)
        if np.max(np.abs(F)) <= tol:
            return u, pmap, J, iteration
        u = u - np.linalg.solve(K, np.append(F, np.dot(normal, u - u_pred)))
        if not np.all(np.isfinite(u)):
            break
    raise sh.ShootingError(f"{system.kind} curve: corrector did not converge near {system.params[0]} = "
                           f"{u[2] * system.scales[0]:.8g}, {system.params[1]} = {u[3] * system.scales[1]:.8g}")


def solve(system: Augmented, u_pred: np.ndarray, normal: np.ndarray, previous: np.ndarray | None,
          max_iter: int = 8) -> tuple[np.ndarray, CurvePoint, np.ndarray, int]:
    """A point of the curve on the hyperplane through u_pred with `normal`: (u, point, tangent, iterations).
    The tangent is the null vector of the Jacobian at the predictor (O(h) off the point's own: a predictor
    direction); the quadratic coefficient is the point's own (Augmented.quadratic), so the cusp is exact."""
    u, pmap, J, iterations = correct(system, u_pred, normal, max_iter)
    point = system.point(u, pmap, system.condition(pmap), system.quadratic(u, pmap))
    point.tangent = null_vector(J, previous if previous is not None else normal)
    return u, point, point.tangent, iterations


def locate(system: Augmented, u0: np.ndarray, t0: np.ndarray, h: float, test: Callable[[CurvePoint], float],
           event: str) -> tuple[float, CurvePoint]:
    """Brent on the arclength in (0, h) for the zero of test(point) (each value a point of the curve on the
    hyperplane at that arclength): (the arclength, the located point, marked `event`, with its own tangent).
    Up to LOCATE_ITERATIONS chord iterations per point: at a grazing orbit the fold system's dM/dy jumps (H'' is
    singular at the contact edge, an integrable singularity that adds a finite amount to dM/dy once the orbit
    enters the contact), so the chord Newton on a fold curve converges only linearly there (ratio ~0.25 measured
    at the grazing-fold of the mu = 0.05 fold curve, ~0.06 a step away)."""
    cache: dict[float, CurvePoint] = {}

    def point(hh):
        if hh not in cache:
            cache[hh] = solve(system, u0 + hh * t0, t0, t0, LOCATE_ITERATIONS)[1]
        return cache[hh]

    hh = brentq(lambda x: test(point(x)), 0.0, h, xtol=1e-12 * h, rtol=1e-12)
    located = point(hh)
    located.event = event
    J, _, _ = system.jacobian(np.array([*located.z0, located.p1 / system.scales[0], located.p2 / system.scales[1]]))
    located.tangent = null_vector(J, t0)  # its own: both parameter components vanish at a cusp
    return hh, located


def grazing_event_on_curve(system: Augmented, u0: np.ndarray, t0: np.ndarray, h: float, before: float,
                           after: float, event: str) -> tuple[float, CurvePoint]:
    """The grazing-fold (grazing-flip) between two points of a fold (period-doubling) curve, x_min + 3/2 = before,
    after of opposite signs, located on the grazing curve that crosses this curve there (the fold or flip system
    itself is not smooth at a grazing orbit: locate's doc): a grazing orbit on this curve's step (the hyperplane of
    the linear estimate, normal t0), then Brent on det(M - I) (det(M + I)) along that grazing curve's tangent,
    bracketed within GRAZING_FOLD_SEARCH steps h of it. Returns (the arclength estimate on this curve, the point
    marked `event` as a point of this curve)."""
    test = GRAZING_TESTS[event]
    grazing = Augmented(system.scene, "grazing", *system.params, system.scales, system.periods, system.rtol)
    s = h * before / (before - after)
    u, _, J, _ = correct(grazing, u0 + s * t0, t0, LOCATE_ITERATIONS)
    tg = null_vector(J, None)
    start = test(solve(grazing, u, tg, tg)[1])
    for reach in GRAZING_FOLD_SEARCH:
        for sign in (1.0, -1.0):
            if test(solve(grazing, u + sign * reach * h * tg, tg, tg)[1]) * start < 0.0:
                _, located = locate(grazing, u, sign * tg, reach * h, test, event)
                pmap = system.map(located.z0, located.p1, located.p2)
                system.set_border(pmap.monodromy)
                located.kind, located.g, located.quadratic = system.kind, system.condition(pmap), math.nan
                return s, located
    raise ValueError(f"no {event} bracketed along the grazing curve")


def locate_cusp(system: Augmented, u0: np.ndarray, t0: np.ndarray, h: float) -> tuple[float, CurvePoint]:
    """Brent on the arclength in (0, h) for the zero of g_z w (module doc): locate's (arclength, point)."""
    return locate(system, u0, t0, h, lambda pt: pt.quadratic, "cusp")


def _x_min_test(pt: CurvePoint) -> float:
    return pt.x_min - CONTACT_EDGE


def _fold_test(pt: CurvePoint) -> float:
    return pt.fold_test


def _flip_test(pt: CurvePoint) -> float:
    return pt.flip_test


# on a grazing curve: the test function of each grazing event (its sign change there is the event)
GRAZING_TESTS = {"grazing-fold": _fold_test, "grazing-flip": _flip_test}
# the codimension-two points looked for on a curve of each kind besides the cusp (module doc): (event, the test
# function whose sign change between two points of the curve is that event). A fold-flip (multipliers +1 and -1 at
# once) cannot occur here -- rho1 rho2 = det M = exp(-mu n T) > 0 (Liouville), so on a fold curve
# det(M + I) = 2 (1 + det M) >= 2 and on a flip curve det(M - I) = 2 (1 + det M) >= 2 -- but it is looked for all
# the same: the sign test costs nothing (M is at hand) and documents the bound (tests check it along the curves)
CODIM2 = {"fold": (("grazing-fold", _x_min_test), ("fold-flip", _flip_test)),
          "period-doubling": (("grazing-flip", _x_min_test), ("fold-flip", _fold_test)),
          "grazing": (("grazing-fold", _fold_test), ("grazing-flip", _flip_test))}


def follow(system: Augmented, start: CurvePoint, direction: float, p2_bounds: tuple[float, float], *,
           max_step: float, max_points: int, stop_at: list | None = None, min_step: float = 1e-8,
           progress: Callable[[CurvePoint], None] | None = None) -> tuple[list[CurvePoint], str, object]:
    """Pseudo-arclength continuation of the curve from `start` with p2 first moving in `direction` (+-1), until p2
    leaves p2_bounds, the curve comes back to a point of `stop_at` (another fold of the branch: the same curve),
    or max_points; returns (points, stop reason, the point of stop_at reached or None). Step control as for a branch (continuation.continue_from): accepted with <= 5 corrector
    iterations and a tangent turning < TURN, grown x1.5 after an easy step, halved on rejection. A sign change
    of the quadratic coefficient is a cusp, located by Brent."""
    u = np.array([start.z0[0], start.z0[1], start.p1 / system.scales[0], start.p2 / system.scales[1]])
    J, quadratic, _ = system.jacobian(u)
    t = null_vector(J, np.array([0.0, 0.0, 0.0, direction]))
    start.tangent, start.quadratic = t, quadratic
    points, h = [start], max_step / 2
    lo, hi = p2_bounds
    reason, joined = f"stopped at {max_points} points", None
    while len(points) < max_points:
        last = points[-1]
        try:
            u_new, point, t_new, iterations = solve(system, u + h * t, t, t)
            accepted = iterations <= 5 and np.dot(t, t_new) >= math.cos(TURN)
        except (sh.ShootingError, np.linalg.LinAlgError):
            accepted, iterations = False, None
        if not accepted:
            h *= 0.5
            if h < min_step:
                reason = f"step below {min_step:g} at {system.params[0]} = {last.p1:.8g}, {system.params[1]} = " \
                         f"{last.p2:.8g}" + grazing_turn(system, last)
                break
            continue
        found = []
        if system.kind == "fold" and last.quadratic * point.quadratic < 0.0:
            try:
                hh, located = locate_cusp(system, u, t, h)
                if parameters_turn(last, located, point):
                    found.append((hh, located))
            except (sh.ShootingError, ValueError):
                pass
        for event, test in CODIM2[system.kind]:
            if not test(last) * test(point) < 0.0:
                continue
            try:
                if event.startswith("grazing-") and system.kind != "grazing":  # on the grazing curve through it
                    found.append(grazing_event_on_curve(system, u, t, h, test(last), test(point), event))
                else:
                    found.append(locate(system, u, t, h, test, event))
            except (sh.ShootingError, ValueError, np.linalg.LinAlgError):  # not bracketed: keep going, unmarked
                pass
        points += [pt for _, pt in sorted(found, key=lambda item: item[0])]
        points.append(point)
        if progress is not None:
            progress(point)
        u, t = u_new, t_new
        met = [q for q in (stop_at or []) if _between(last, point, q, system.scales)]
        if met:  # before the range: the branch's other fold may sit on the range's end
            joined = met[0]
            reason = f"reached the {system.kind} of the branch at {system.params[0]} = {joined.p1:.8g} (the same curve)"
            break
        if not lo <= point.p2 <= hi:
            reason = f"left the range of {system.params[1]}"
            break
        h = min(max_step, 1.5 * h) if iterations <= 2 else min(max_step, h)
    if reason.startswith("stopped at"):  # the point budget: say where, and whether an electrode is ahead
        last = points[-1]
        reason = budget_reason(f"{reason} at {system.params[0]} = {last.p1:.8g}, {system.params[1]} = "
                               f"{last.p2:.8g}", system.at(last.p1, last.p2), last)
    return points, reason, joined


# a turning point this close to the contact edge makes a stalled curve a stall at a grazing (grazing_turn): the
# corrector's own tolerance 1e-10 in the state times a conditioning up to 1e4 near the kink
GRAZING_NEAR = 1e-6


def grazing_turn(system: Augmented, last: CurvePoint) -> str:
    """'' or why a fold or flip curve stalled at `last`: a turning point of its orbit (any, not only the lowest,
    which x_min and the grazing-fold/flip test see) on the contact edge, where the fold or flip system has a kink
    (locate's doc). From the dense map (scipy's DOP853: every turning point)."""
    if system.grazing:
        return ""
    s = system.at(last.p1, last.p2)
    try:
        pmap = sh.period_map(sh.PeriodicModel(s), last.z0, s.omega, system.rtol, system.params[0], system.periods)
    except sh.ShootingError:
        return ""
    near = [x for x in pmap.extrema if abs(x - CONTACT_EDGE) <= GRAZING_NEAR]
    if not near:
        return ""
    return (f": a turning point of the orbit at x = {near[0]:.10g} grazes the contact edge (the {system.kind} "
            f"system has a kink there{'' if near[0] <= last.x_min + GRAZING_NEAR else '; not the lowest one, which the grazing events follow'})")


def parameters_turn(before: CurvePoint, at: CurvePoint, after: CurvePoint) -> bool:
    """The parameters turn at `at` between the curve's points before and after it -- the cusp's geometric signature:
    the tangent lies in the state there, so over the step the parameters move by O(step^2) and turn -- unless a
    parameter turns (the located point may lie a little past the other's turning), or the parameters' move over the
    step is below TURN_SLOPE times the state's (a turning below the corrector's resolution: the curve's points carry
    its absolute tolerances, coarse beside parameters ~1e-7 at the smallest cusp_order scenes). A sign
    change of the quadratic coefficient without it is not a cusp: g_z w comes from forward differences of M, whose
    bias moves its zero where the true coefficient is small (seen near pull-in on the fold curve of mu = 0.05, R = 3
    at omega ~ 0.637, Delta ~ 0.1298: omega went on monotonically at 0.12 of the state's move)."""
    if (at.p1 - before.p1) * (after.p1 - at.p1) < 0.0 or (at.p2 - before.p2) * (after.p2 - at.p2) < 0.0:
        return True
    step = float(np.linalg.norm(after.z0 - before.z0))
    move = max(abs(after.p1 - before.p1), abs(after.p2 - before.p2))
    return move <= TURN_SLOPE * step


def _between(a: CurvePoint, b: CurvePoint, q: CurvePoint, scales) -> bool:
    """q lies on the step from a to b: within the step's length of both ends, p2 of q between theirs."""
    def u(pt):
        return np.array([pt.z0[0], pt.z0[1], pt.p1 / scales[0], pt.p2 / scales[1]])
    step = np.linalg.norm(u(b) - u(a))
    return (min(a.p2, b.p2) <= q.p2 <= max(a.p2, b.p2) and np.linalg.norm(u(q) - u(a)) <= 1.01 * step
            and np.linalg.norm(u(q) - u(b)) <= 1.01 * step)


def start_point(system: Augmented, z0, p1: float, p2: float) -> CurvePoint:
    """The located event of a one-parameter branch as a curve point: corrected onto g = 0 at fixed p2 (the
    branch located it by its own test function; this removes the difference)."""
    u = np.array([z0[0], z0[1], p1 / system.scales[0], p2 / system.scales[1]])
    normal = np.array([0.0, 0.0, 0.0, 1.0])  # p2 fixed
    u, pmap, _, _ = correct(system, u, normal)
    J, quadratic, _ = system.jacobian(u)
    return system.point(u, pmap, system.condition(pmap), quadratic)


@dataclass
class Curves:
    curves: list
    params: tuple
    seconds: float = 0.0
    cpu_seconds: float = 0.0


def curves_from_branch(branch, kind: str, param2: str, p2_to: float, p2_from: float | None = None, *,
                       points: int = 200, max_points: int | None = None, scale1: float | None = None,
                       progress: Callable[[str], None] | None = None) -> Curves:
    """Every `kind` event of the one-parameter `branch` (continuation.Branch: its own points, of period n T for
    a doubled branch, whose curves are then of the n T orbits) continued in (branch param, param2) both ways,
    inside [p2_from, p2_to] (p2_from defaults to the branch's value of param2); a curve that comes back to another
    event of the branch stops there (one curve through both). The step is sized like a branch's: 1.5 / points of
    the scaled arclength (each parameter scaled by its range; param's by scale1 if given, e.g. the range of the
    period-T branch for a doubled branch that spans less of it)."""
    t0, c0 = time.perf_counter(), time.process_time()
    problem = branch.problem
    param1 = problem.param
    p2_here = float(getattr(problem.scene, param2))
    p2_from = p2_here if p2_from is None else p2_from
    lo2, hi2 = min(p2_from, p2_to), max(p2_from, p2_to)
    values = [pt.p for pt in branch.points]
    scales = (scale1 or max(values) - min(values) or 1.0, (hi2 - lo2) or abs(p2_here) or 1.0)
    system = Augmented(problem.scene, kind, param1, param2, scales, problem.periods, problem.rtol)
    events = [pt for pt in branch.points if pt.event == kind]
    starts = []
    for pt in events:
        try:
            starts.append(start_point(system, pt.z0, pt.p, p2_here))
        except sh.ShootingError as error:
            if progress:
                progress(f"{kind} at {param1} = {pt.p:.8g}: not a start ({error})")
    found, covered = [], {}  # (start index, direction in p2) a curve already took
    done: set = set()
    for index, start in enumerate(starts):
        if index in done:
            continue
        pieces = []
        queue = [(index, start, 1.0), (index, start, -1.0)]
        while queue:
            at, origin, direction = queue.pop(0)
            if (direction > 0 and p2_here >= hi2) or (direction < 0 and p2_here <= lo2) \
                    or (at, direction) in covered:
                continue
            covered[(at, direction)] = True
            done.add(at)
            first = system.point(np.array([*origin.z0, origin.p1 / scales[0], origin.p2 / scales[1]]),
                                 system.map(origin.z0, origin.p1, origin.p2), origin.g, origin.quadratic)
            others = [other for j, other in enumerate(starts) if j != at]
            pts, why, joined = follow(system, first, direction, (lo2, hi2), max_step=1.5 / points,
                                      max_points=max_points or 4 * points, stop_at=others)
            pieces.append((at, direction, pts, why))
            if progress:
                progress(f"{kind} curve from {param1} = {origin.p1:.8g}, {param2} "
                         f"{'up' if direction > 0 else 'down'}: {len(pts)} points ({why})")
            if joined is not None:  # the same curve goes on from that event in the other direction
                j = next(j for j, other in enumerate(starts) if other is joined)
                arrival = 1.0 if pts[-1].p2 >= pts[-2].p2 else -1.0
                covered[(j, -arrival)] = True
                done.add(j)
                queue.append((j, joined, arrival))
        # one curve, in order: the first start's upward piece reversed, then each following piece
        ordered = []
        for number, (origin_index, _, pts, _) in enumerate(pieces):
            if number == 0:
                ordered = pts[::-1] if len(pieces) > 1 else list(pts)
            elif number == 1 and origin_index == pieces[0][0]:
                ordered += pts[1:]  # from the same start, which ends the reversed first piece
            else:
                ordered += pts
        found.append(Curve(kind, len(found), ordered, "; ".join(why for *_, why in pieces),
                           [(pts[-1], why) for _, _, pts, why in pieces]))
    return Curves(found, (param1, param2), time.perf_counter() - t0, time.process_time() - c0)


def merge(found: list, params: tuple) -> Curves:
    """Curves of several kinds as one set, numbered in order."""
    out = Curves([], params, sum(c.seconds for c in found), sum(c.cpu_seconds for c in found))
    for group in found:
        for curve in group.curves:
            out.curves.append(Curve(curve.kind, len(out.curves), curve.points, curve.stop_reason, curve.ends))
    return out


def rows(curves: Curves) -> list[dict]:
    """One dict per curve point: kind, curve, both parameters by name, x0, v0, period, x_min, x_max, event."""
    p1, p2 = curves.params
    out = []
    for curve in curves.curves:
        for pt in curve.points:
            out.append({"kind": pt.kind, "curve": curve.index, "periods": pt.periods, p1: pt.p1, p2: pt.p2,
                        "x0": float(pt.z0[0]),
                        "v0": float(pt.z0[1]), "period": pt.period, "x_min": pt.x_min, "x_max": pt.x_max,
                        "event": pt.event, "rho1_re": float(pt.multipliers[0].real),
                        "rho2_re": float(pt.multipliers[1].real), "residual": pt.residual, "g": pt.g,
                        "quadratic": pt.quadratic, "det_m_minus_i": pt.fold_test,
                        "det_m_plus_i": pt.flip_test})
    return out


# the check's rtol: scipy's DOP853 at the engine's 1e-11 leaves ~3e-9 in M on the bench curve (its det(M - I) was 1e-8
# where the converged value is 1.5e-10); at 1e-12 its |det(M - I)| is at most 1.2e-9 over the bench curve, below 1e-8
# by 8x. Not 1e-13: there scipy's DOP853 is at the edge of double precision (atol 1e-13 too) and
# at one bench point (omega 0.8071, Delta 0.1060, two contact crossings) its M was 4e-8 off, det(M - I) -4.4e-8,
# where scipy at 1e-12, 3e-13 and 2e-13 and the compiled map at 1e-11, 1e-12 and 1e-13 all give 5e-11 ... 6e-11
CHECK_RTOL = 1e-12


def fold_system_check(scene: Scene, points: list, param1: str, param2: str) -> dict:
    """Each point against the fold system P(z) = z, det(M - I) = 0 evaluated by scipy's DOP853 period map
    (shooting.period_map with dense output: the Python right-hand side and scipy's solver, not the compiled
    twin that continued the curve) at rtol CHECK_RTOL: the largest |P(z) - z|_inf and |det(M - I)| over the points."""
    worst_residual = worst_det = 0.0
    for pt in points:
        s = scene.with_values(**{param1: pt.p1, param2: pt.p2})
        pmap = sh.period_map(sh.PeriodicModel(s), pt.z0, s.omega, CHECK_RTOL, "omega", pt.periods, dense=True)
        worst_residual = max(worst_residual, float(np.max(np.abs(pmap.end - pt.z0))))
        worst_det = max(worst_det, abs(float(np.linalg.det(pmap.monodromy + SIGN[pt.kind] * np.eye(2)))))
    return {"points": len(points), "max_residual": worst_residual, "max_det": worst_det,
            "checked_by": f"scipy's DOP853 at rtol {CHECK_RTOL:g} (shooting.period_map with dense output)"}


# ----- the benchmark: `vibrofmu bench --curve` -------------------------------------------------------------------

BENCH_SCENE = {"mu": 0.05, "Delta": 0.1, "R": 3.0, "beta": 0.0, "gamma": 0.0}  # two folds at omega ~ 0.829, 0.933
BENCH_POINTS = 200  # the curve's points: the target is BENCH_POINTS in < 60 s on 2 cores
BENCH_DELTA = (0.02, 0.2)  # the fold curve's range in Delta: through the cusp (Delta ~ 0.06) to the end of both folds


def bench_curve(progress: Callable[[str], None] | None = None) -> dict:
    """The fold curve of BENCH_SCENE in (omega, Delta), from the two folds of the omega-branch at Delta = 0.1,
    each of its (at most four) pieces, up and down from each fold, capped so that the curve has BENCH_POINTS
    points at most; the cost of the curve alone (the
    branch that starts it is timed apart)."""
    from vibrofmu.analyses import continuation as cont

    scene = Scene(**BENCH_SCENE)
    t0, c0 = time.perf_counter(), time.process_time()
    branch = cont.branch(scene, "omega", 0.8, 0.95, points=20, double=False)
    branch_seconds, branch_cpu = time.perf_counter() - t0, time.process_time() - c0
    found = curves_from_branch(branch, "fold", "Delta", BENCH_DELTA[1], BENCH_DELTA[0], points=BENCH_POINTS,
                               max_points=BENCH_POINTS // 4, progress=progress)
    points = sum(len(c.points) for c in found.curves)
    check = fold_system_check(scene, [pt for c in found.curves for pt in c.points], "omega", "Delta")
    return {"scene": BENCH_SCENE, "engine": sh.compiled_period_map()[1] or "the compiled period map",
            "fold_system": check, "delta_range": list(BENCH_DELTA), "points": points,
            "seconds": found.seconds, "cpu_seconds": found.cpu_seconds,
            "seconds_per_point": found.seconds / points, "cpu_seconds_per_point": found.cpu_seconds / points,
            "branch_seconds": branch_seconds, "branch_cpu_seconds": branch_cpu,
            "events": [{"event": pt.event, "omega": pt.p1, "Delta": pt.p2} for c in found.curves for pt in c.points
                       if pt.event],
            "stop_reasons": [c.stop_reason for c in found.curves],
            "target": f"{BENCH_POINTS} points in < 60 s on 2 cores"}

