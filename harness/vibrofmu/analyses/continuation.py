"""Continuation of the periodic orbits of the exact model in one parameter, through contact loss (issue 24).

Model: shooting.PeriodicModel (Eq. 3 with the AC drive at its mean; docs/continuation.md), with the Hertz force
zero once the contact opens. A branch is a curve of fixed points of the n-period map P^n(z; p) (n = 1, or 2 on
a branch switched to at a period doubling), continued in one parameter p (PARAMETERS) by Keller's
pseudo-arclength method:

- the period map, Newton's corrector, the pseudo-arclength corrector, the tangent and the multipliers are
  shooting.py's (one engine: period_map, newton_shoot, arclength_correct, branch_tangent, multipliers); the
  state and its variational equations Phi' = J Phi, z_p' = J z_p + df/dp are integrated together with
  DOP853 (rtol 1e-11, the accuracy argument of shooting.py), restarted at each contact crossing;
- multipliers: eig of the monodromy M = Phi(nT); stable when max |rho| < 1;
- test functions, each evaluated at every point and located by Brent's method on the arclength where it
  changes sign between two accepted points:
    fold             det(M - I) = (1 - rho1)(1 - rho2) (a real multiplier through +1), located by the bordered
                     test function of M - I (shooting.bordered_test), independent of the branch tangent,
    period-doubling  det(M + I) = (1 + rho1)(1 + rho2) (a real multiplier through -1),
    neimark-sacker   det M - 1 while the pair is complex (|rho|^2 = det M = exp(-mu nT) < 1 for mu > 0:
                     it can only fire when mu itself is continued through 0; kept for that case),
    grazing          min over the orbit of 1 + 2x/3 (contact first lost), i.e. x_min + 3/2;
- at a period doubling the branch of doubled orbits (fixed points of P^2 off the P-branch) is reached by the
  pitchfork's tangent: predictor z* + h v (v the multiplier -1 eigenvector, p = p*), corrector on P^2 with
  the hyperplane v . (z - z* - h v) = 0, then continued like any branch.

Saltation: at contact loss the vector field is C^1 (H = s^{3/2} and H' = s^{1/2} both vanish at s = 1 + 2x/3 = 0),
so the fundamental matrix is continuous across the crossing: the saltation matrix is the identity
(docs/continuation.md; checked by tests/studies/test_continuation.py against a finite-difference monodromy).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from scipy.optimize import brentq

from vibromodel import forces
from vibromodel.parameters import PULL_IN_GAP, Scene

from vibrofmu.analyses import shooting as sh
from vibrofmu.analyses.shooting import NEWTON_TOL, RTOL, TWO_PI, PeriodicModel, ShootingError, piecewise_x

PARAMETERS = sh.PARAMETERS  # what a branch can be continued in
EVENTS = ("fold", "period-doubling", "neimark-sacker", "grazing")
# the longest arclength step, in units of the step that advances the parameter by max_step: where the branch
# runs in the state (a fold, a winding stretch through contact loss) the step may grow to 8 x max_step, bounded
# by the 0.2 rad turning criterion; 8 keeps >= 20 points on a loop of unit size at the default 200 points
STRETCH = 8.0
CONTACT_EDGE = -1.5  # 1 + 2x/3 = 0


# ----- the n-period map with the sensitivity to one parameter: shooting's ----------------------------------

def n_period_map(scene: Scene, param: str, z0, periods: int = 1, rtol: float = RTOL,
                 dense: bool = False) -> sh.PeriodMap:
    """shooting.period_map of the scene's PeriodicModel over `periods` periods with the sensitivity to `param`;
    without dense output unless asked (the compiled period map: a branch needs no x(s))."""
    return sh.period_map(PeriodicModel(scene), z0, scene.omega, rtol, param, periods, dense)


# ----- points of a branch ---------------------------------------------------------------------------------

@dataclass
class Point:
    """One periodic orbit: the fixed point z0 of P^n at parameter value p, its multipliers and test functions."""

    p: float
    z0: np.ndarray
    periods: int
    period: float  # n T = 2 pi n / omega
    monodromy: np.ndarray
    d_param: np.ndarray
    multipliers: np.ndarray  # sorted by modulus
    x_min: float
    x_max: float
    crossings: int
    residual: float
    liouville_error: float  # |det M - exp(-mu nT)|
    event: str = ""
    tangent: np.ndarray | None = field(default=None, repr=False)

    @property
    def rho_max(self) -> float:
        return float(np.max(np.abs(self.multipliers)))

    @property
    def stable(self) -> bool:
        return self.rho_max < 1.0

    def tests(self) -> dict:
        """Test functions (module doc); a sign change between two points is an event."""
        M = self.monodromy
        complex_pair = abs(self.multipliers[0].imag) > 1e-12 * abs(self.multipliers[0])
        return {"fold": float(np.linalg.det(M - np.eye(2))),
                "period-doubling": float(np.linalg.det(M + np.eye(2))),
                "neimark-sacker": float(np.linalg.det(M) - 1.0) if complex_pair else math.nan,
                "grazing": self.x_min - CONTACT_EDGE}


def _point(scene: Scene, param: str, p: float, z0, periods: int, result: sh.PeriodMap) -> Point:
    s = scene if param is None else scene.with_values(**{param: p})
    rho = sh.multipliers(result.monodromy)
    period = TWO_PI * periods / s.omega
    return Point(p=p, z0=np.asarray(z0, dtype=float).copy(), periods=periods, period=period,
                 monodromy=result.monodromy, d_param=result.d_param, multipliers=rho, x_min=result.x_min,
                 x_max=result.x_max, crossings=result.crossings,
                 residual=float(np.max(np.abs(result.end - z0))),
                 liouville_error=float(abs(np.linalg.det(result.monodromy) - math.exp(-s.mu * period))))


@dataclass(frozen=True)
class Problem:
    """Periodic orbits of `scene` with parameter `param` free, as fixed points of the `periods`-period map."""

    scene: Scene
    param: str
    periods: int = 1
    rtol: float = RTOL
    tol: float = NEWTON_TOL

    def __post_init__(self):
        if self.param not in PARAMETERS:
            raise ValueError(f"parameter {self.param!r}: continuation supports {', '.join(PARAMETERS)}")

    def at(self, p: float) -> Scene:
        return self.scene.with_values(**{self.param: float(p)})

    def map(self, z0, p: float) -> sh.PeriodMap:
        return n_period_map(self.at(p), self.param, z0, self.periods, self.rtol)

    def point(self, z0, p: float, result: sh.PeriodMap | None = None) -> Point:
        result = result or self.map(z0, p)
        return _point(self.at(p), self.param, p, z0, self.periods, result)

    def shoot(self, p: float, z_guess, max_iter: int = 25) -> Point:
        """shooting.newton_shoot on P^n at fixed p."""
        result = sh.newton_shoot(lambda z: self.map(z, p), z_guess, self.tol, max_iter, f" at {self.param} = {p:.10g}")
        return self.point(result.z0, p, result)

    def linear_guess(self, p: float) -> np.ndarray:
        """z0 of the linearised response about the equilibrium (shooting.linear_guess)."""
        s = self.at(p)
        model = PeriodicModel(s)
        x_e, k1 = model.equilibrium()
        c = s.Delta / complex(k1 - s.omega**2, s.mu * s.omega)
        return np.array([x_e + c.real, -s.omega * c.imag])


class Continuation:
    """Pseudo-arclength continuation on u = (x0, v0, p / scale) (shooting._Branch for any parameter)."""

    def __init__(self, problem: Problem, scale: float):
        self.problem, self.scale = problem, scale

    def u_of(self, point: Point) -> np.ndarray:
        return np.array([point.z0[0], point.z0[1], point.p / self.scale])

    def tangent(self, point: Point, previous: np.ndarray) -> np.ndarray:
        return sh.branch_tangent(point.monodromy, point.d_param, self.scale, previous,
                                 f" at {self.problem.param} = {point.p:.10g}")

    def correct(self, u_pred: np.ndarray, normal: np.ndarray, max_iter: int = 8) -> tuple[Point, int]:
        """shooting.arclength_correct on P^n in the continued parameter."""
        result, p, iterations = sh.arclength_correct(self.problem.map, u_pred, normal, self.scale, self.problem.tol,
                                                     max_iter, self.problem.param)
        return self.problem.point(result.z0, p, result), iterations

    def point_at(self, u0: np.ndarray, t0: np.ndarray, h: float) -> Point:
        point, _ = self.correct(u0 + h * t0, t0)
        point.tangent = self.tangent(point, t0)
        return point


# ----- pull-in ahead: a branch creeping towards an electrode -------------------------------------------------

# A branch or curve that stops on its point budget with an orbit's turning point within this factor of the gap of
# the electrode's saddle (saddle_gaps) is creeping towards pull-in: there the electrode's pull, ~ alpha / gap^2,
# is at least 1 / CREEP_FACTOR^2 = a quarter of its value at the saddle, where it equals the restoring force, so the
# force on the orbit's lowest (highest) point changes by O(1) of itself over the gap; and no turning point can lie
# much beyond the saddle (x'' >= 0 there needs the pull below the load plus the drive), so the orbits pile up
# against it and the steps shrink (measured: the mu = 0.05, R = 3 fold curve creeps with its lowest gap 1.11 x the
# saddle's). The factor is a margin, not a bifurcation: the stop reason names both gaps.
CREEP_FACTOR = 2.0


def saddle_gaps(scene: Scene) -> tuple[float | None, float | None]:
    """(upper, lower): the electrode gap 1 -+ 2x/(3R) of the unstable equilibrium next to each electrode -- the
    root of the periodic model's restoring force g(x) = H(x) - 1 - F_em,mean(x) nearest the electrode, where the
    electrode's mean pull balances the load and the contact force; beyond it an orbit at rest falls onto the
    electrode. None on a side without one (no pull towards that electrode: alpha + gamma = 0 above, alpha = 0
    below). Scanned outward from the pull-in gap on a geometric grid, refined by Brent to rounding."""
    g = sh.PeriodicModel(scene).restoring()[0]
    reach = 1.5 * scene.R
    found = []
    for side in (1.0, -1.0):  # upper electrode at x = +3R/2, lower at -3R/2
        def force(gap, side=side):
            return g(side * reach * (1.0 - gap))

        gaps = np.geomspace(PULL_IN_GAP, 1.0, 400)
        values = [force(gap) for gap in gaps]
        root = None
        for k in range(len(gaps) - 1):
            if values[k] * values[k + 1] < 0.0:
                root = brentq(force, gaps[k], gaps[k + 1], xtol=1e-15, rtol=4 * np.finfo(float).eps)
                break
        found.append(root)
    return found[0], found[1]


def pull_in_ahead(scene: Scene, x_min: float, x_max: float) -> str:
    """'' or why an orbit with these extremes sits against an electrode (CREEP_FACTOR): its gap and the saddle's."""
    upper, lower = saddle_gaps(scene)
    c = 2.0 / (3.0 * scene.R)
    for name, saddle, gap in (("upper", upper, 1.0 - c * x_max), ("lower", lower, 1.0 + c * x_min)):
        if saddle is not None and gap <= CREEP_FACTOR * saddle:
            return (f"its {'highest' if name == 'upper' else 'lowest'} point at a gap {gap:.4g} of the {name} "
                    f"electrode, within {CREEP_FACTOR:g} x the gap {saddle:.4g} of the electrode's saddle")
    return ""


def budget_reason(reason: str, scene: Scene, last) -> str:
    """A point-budget stop reason ('stopped at ...') turned into 'pull-in ahead: ...' when the last orbit is
    creeping towards an electrode (pull_in_ahead); any other reason unchanged."""
    if not reason.startswith("stopped at"):
        return reason
    why = pull_in_ahead(scene, last.x_min, last.x_max)
    return f"pull-in ahead: {reason}, {why}" if why else reason


def _test_value(point: Point, name: str) -> float:
    return point.tests()[name]


def _locate(cont: Continuation, u0: np.ndarray, t0: np.ndarray, h: float, name: str) -> Point:
    """Brent on the arclength in (0, h) for the zero of the test function `name` (module doc)."""
    cache: dict[float, Point] = {}

    def point(hh):
        if hh not in cache:
            cache[hh] = cont.point_at(u0, t0, hh)
        return cache[hh]

    if name == "fold":  # located by the bordered test function of M - I (b, c fixed at the bracket's start):
        # its zero is where M - I is singular, whatever the branch tangent does there (a fold next to a grazing)
        border = sh.border_of(point(0.0).monodromy - np.eye(2))

        def value(hh):
            return sh.bordered_test(point(hh).monodromy - np.eye(2), *border)[0]
    else:
        def value(hh):
            v = _test_value(point(hh), name)
            return 0.0 if math.isnan(v) else v

    h_event = brentq(value, 0.0, h, xtol=1e-12 * max(h, 1e-300), rtol=1e-12)
    located = replace(point(h_event), event=name)
    return located


@dataclass
class Branch:
    """Points in arclength order (events are points of their own, with `event` set); `doubled` branches
    switched to at period doublings."""

    problem: Problem
    points: list
    doubled: list = field(default_factory=list)  # Branch per switched period doubling
    stop_reason: str = ""
    seconds: float = 0.0  # wall clock
    cpu_seconds: float = 0.0  # this process's CPU time: the cost on a machine shared with other work

    def events(self) -> list[Point]:
        return [pt for pt in self.points if pt.event]


def continue_from(problem: Problem, start: Point, p_stop: float, *, scale: float, step: float = 0.01,
                  max_step: float = 0.02, min_step: float = 1e-7, max_points: int = 5000,
                  direction: np.ndarray | None = None, p_bounds: tuple[float, float] | None = None,
                  progress: Callable[[int, Point], None] | None = None) -> tuple[list[Point], str]:
    """Pseudo-arclength continuation from `start` until p passes p_stop (or leaves p_bounds, or max_points),
    locating every event between consecutive points. Step control: a step is accepted if the corrector converges
    in <= 5 iterations and the tangent turns by less than 0.2 rad; it grows by 1.5 after an easy step (<= 2
    iterations), halves on rejection, and is capped by step_cap (max_step in the parameter, STRETCH x max_step
    in the arclength at most).
    Returns (points, stop reason)."""
    cont = Continuation(problem, scale)

    def step_cap(t):
        """max_step in the parameter: the arclength step is max_step / |t_p|, at most STRETCH max_step where the
        branch runs in the state (near folds, winding through contact loss): a straight branch keeps its points
        per range, a winding one is not starved of them (the turning and Newton criteria still bound the step)."""
        return max_step / max(abs(float(t[2])), 1.0 / STRETCH)

    sign = 1.0 if p_stop >= start.p else -1.0
    reference = direction if direction is not None else np.array([0.0, 0.0, sign])
    u = cont.u_of(start)
    t = cont.tangent(start, reference)
    start.tangent = t
    points, h = [start], step
    lo, hi = p_bounds if p_bounds is not None else (-math.inf, math.inf)
    reason = "reached the end of the range"
    while True:
        last = points[-1]
        if direction is None and sign * (last.p - p_stop) >= 0.0:
            break
        if not lo <= last.p <= hi:
            reason = "left the parameter range"
            break
        if len(points) >= max_points:
            reason = budget_reason(f"stopped at {len(points)} points at {problem.param} = {last.p:.8g}",
                                   problem.at(last.p), last)
            break
        try:
            point, iterations = cont.correct(u + h * t, t)
            t_new = cont.tangent(point, t)
            accepted = iterations <= 5 and np.dot(t, t_new) >= math.cos(0.2)
            failure = ""
        except (ShootingError, np.linalg.LinAlgError) as error:
            accepted, iterations, failure = False, None, str(error)
        if not accepted:
            h *= 0.5
            if h < min_step:
                reason = (f"pull-in beyond {problem.param} = {last.p:.10g} (every shorter step met an electrode)"
                          if failure.startswith("pull-in") else f"step below {min_step:g} at {problem.param} = "
                                                                f"{last.p:.10g}")
                break
            continue
        point.tangent = t_new
        old, new = last.tests(), point.tests()
        located = []
        for name in EVENTS:
            a, b = old[name], new[name]
            if math.isfinite(a) and math.isfinite(b) and a * b < 0.0:
                try:
                    located.append(_locate(cont, u, t, h, name))
                except (ShootingError, ValueError):  # not bracketed after all: keep going, unmarked
                    pass
        located.sort(key=lambda pt: np.dot(cont.u_of(pt) - u, t))
        points.extend(located)
        points.append(point)
        if progress is not None:
            progress(len(points) - 1, point)
        u, t = cont.u_of(point), t_new
        h = min(step_cap(t), 1.5 * h) if iterations <= 2 else min(step_cap(t), h)
    return points, reason


def switch_to_doubled(problem: Problem, pd: Point, scale: float, h: float = 0.02) -> Point:
    """The first point of the doubled branch at the period doubling `pd` (module doc): corrector on P^2 from
    z* + h v along the pitchfork's tangent (v, 0); the result must not be the P-orbit itself."""
    rho, vectors = np.linalg.eig(pd.monodromy)
    k = int(np.argmin(np.abs(rho + 1.0)))
    v = np.real(vectors[:, k])
    v /= np.linalg.norm(v)
    doubled = replace(problem, periods=2 * problem.periods)
    cont = Continuation(doubled, scale)
    u0 = cont.u_of(pd)
    normal = np.array([v[0], v[1], 0.0])
    for amplitude in (h, h / 4, h / 16, h / 64, h / 256, 4 * h):  # small ones for a narrow window (late in a cascade)
        try:
            point, _ = cont.correct(u0 + amplitude * normal, normal)
        except (ShootingError, np.linalg.LinAlgError):
            continue
        single = problem.map(point.z0, point.p)
        if np.max(np.abs(single.end - point.z0)) > 1e3 * problem.tol:  # not a fixed point of P: truly doubled
            point.tangent = cont.tangent(point, normal)  # away from the P-orbit, not back through the vertex
            return point
    raise ShootingError(f"no doubled orbit found next to the period doubling at {problem.param} = {pd.p:.10g}")


def branch(scene: Scene, param: str, lo: float, hi: float, *, points: int = 200, rtol: float = RTOL,
           tol: float = NEWTON_TOL, start_guess=None, double: bool = True, max_points: int | None = None,
           max_period: int = 2, progress: Callable[[int, Point], None] | None = None) -> Branch:
    """The branch of T-periodic orbits from p = lo (started from the linear response, or start_guess) to
    p = hi, with events located; at each period doubling of a branch of period nT with 2n <= max_period the
    branch of period 2nT is switched to and continued (inside [lo, hi]), and so on: a cascade (result.doubled
    holds the doubled branches of every level, parents before children; a period doubling on a branch of
    period max_period is located but not switched). The step is sized so that the branch has about `points`
    points when it is straight: max_step = 1.5 / points of the scaled parameter (range = 1); where the branch
    runs in the state the arclength step grows up to STRETCH x max_step (continue_from); each branch stops at
    max_points (default 4 points) with the stop reason saying so."""
    t0, c0 = time.perf_counter(), time.process_time()
    problem = Problem(scene, param, rtol=rtol, tol=tol)
    scale = abs(hi - lo)
    start = problem.shoot(lo, problem.linear_guess(lo) if start_guess is None else start_guess)
    max_step = 1.5 / points
    main, reason = continue_from(problem, start, hi, scale=scale, step=max_step / 2, max_step=max_step,
                                 max_points=max_points or 4 * points, progress=progress)
    result = Branch(problem, main, stop_reason=reason)
    pending = [result] if double else []
    while pending:
        parent = pending.pop(0)
        if 2 * parent.problem.periods > max_period:
            continue
        child_problem = replace(problem, periods=2 * parent.problem.periods)
        for pd in [pt for pt in parent.points if pt.event == "period-doubling"]:
            try:
                first = switch_to_doubled(parent.problem, pd, scale)
                doubled_points, why = continue_from(child_problem, first, hi, scale=scale,
                                                    step=max_step / 2, max_step=max_step,
                                                    max_points=max_points or 4 * points,
                                                    direction=first.tangent, p_bounds=(min(lo, hi), max(lo, hi)))
                child = Branch(child_problem, doubled_points, stop_reason=why)
                pending.append(child)
            except ShootingError as error:
                child = Branch(child_problem, [], stop_reason=str(error))
            result.doubled.append(child)
    result.seconds, result.cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
    return result


def cascade(result: Branch) -> list[Point]:
    """The period doublings of a cascade in the order of their period: the first of the T-branch, then the first
    on each doubled branch (of period 2T, 4T, ...) switched to from the previous one (branch's result)."""
    found, periods = [], 1
    for br in [result, *result.doubled]:
        if br.problem.periods != periods:
            continue
        pds = [pt for pt in br.points if pt.event == "period-doubling"]
        if not pds:
            break
        found.append(pds[0])
        periods *= 2
    return found


def feigenbaum_ratios(values: list[float]) -> list[float]:
    """(p_k - p_{k-1}) / (p_{k+1} - p_k) for successive doubling points p_1, p_2, ...: Feigenbaum's
    delta = 4.6692... in the limit k -> infinity for a map with a quadratic maximum."""
    d = np.diff(np.asarray(values, dtype=float))
    return [float(d[k] / d[k + 1]) for k in range(len(d) - 1)]


# ----- rows: what branch.parquet holds ---------------------------------------------------------------------

COLUMNS = ("branch", "periods", "param", "value", "period", "x_min", "x_max", "rho_max", "stable", "event",
           "rho1_re", "rho1_im", "rho2_re", "rho2_im", "x0", "v0", "contact_crossings", "residual",
           "liouville_error")


def rows(result: Branch) -> list[dict]:
    """One dict per orbit (COLUMNS); branch 0 is the T-periodic branch, 1, 2, ... the doubled ones."""
    out = []
    for index, br in enumerate([result, *result.doubled]):
        for pt in br.points:
            rho = pt.multipliers
            out.append({"branch": index, "periods": pt.periods, "param": br.problem.param, "value": pt.p,
                        "period": pt.period, "x_min": pt.x_min, "x_max": pt.x_max, "rho_max": pt.rho_max,
                        "stable": bool(pt.stable), "event": pt.event,
                        "rho1_re": rho[0].real, "rho1_im": rho[0].imag, "rho2_re": rho[1].real,
                        "rho2_im": rho[1].imag, "x0": pt.z0[0], "v0": pt.z0[1],
                        "contact_crossings": pt.crossings, "residual": pt.residual,
                        "liouville_error": pt.liouville_error})
    return out


# ----- FMU confirmation of a located event -------------------------------------------------------------------

CONFIRM_SAMPLES = 16  # communication steps per forcing period (the stroboscopic sample is every 16th)
CONFIRM_PERIODS = 1500  # forcing periods per run: mu T / 2 ~ 0.03 at mu = 0.01, omega = 1 -> e^-47 of a start error
CONFIRM_TAIL = 40  # periods at the end that are judged
# Same orbit: stroboscopic states within this of each other (the FMU's rtol 1e-8 and the AC drive's
# O(beta/Omega^2) ~ 1e-5 wobble, which shooting leaves out, are far below it; distinct orbits of a
# fold/PD are O(0.01 .. 1) apart).
SAME_STATE = 1e-3


@dataclass
class FmuRun:
    """A long FMU run at one parameter value, judged on its last CONFIRM_TAIL periods."""

    p: float
    start: tuple[float, float]
    settled_period: int | None  # 1, 2 (x(kT) alternates), or None (neither within SAME_STATE)
    x_min: float
    x_max: float
    end: tuple[float, float]  # stroboscopic state at the end
    stop_reason: str | None = None

    @property
    def contact_lost(self) -> bool:
        return self.x_min < CONTACT_EDGE

    def as_dict(self) -> dict:
        return {"value": self.p, "start": list(self.start), "settled_period": self.settled_period,
                "x_min": self.x_min, "x_max": self.x_max, "end": list(self.end), "contact_lost": self.contact_lost,
                "stop_reason": self.stop_reason}


def fmu_run(fmu, scene: Scene, param: str, p: float, start, periods: int = CONFIRM_PERIODS) -> FmuRun:
    """The plant FMU at parameter value p from the state `start` (at tau = 0, the forcing phase of z0)."""
    from vibromodel.settings import Settings

    from vibrofmu.analyses.simulate import start_values
    from vibrofmu.hosts.run import run_fmu

    s = scene.with_values(**{param: float(p), "x_start": float(start[0]), "v_start": float(start[1])})
    T = TWO_PI / s.omega
    result = run_fmu(fmu, start_values(s, Settings()), periods * T, T / CONFIRM_SAMPLES)
    x, v = result.outputs["x"], result.outputs["v"]
    if not result.completed:
        return FmuRun(p, tuple(start), None, math.nan, math.nan, (math.nan, math.nan), result.stop_reason)
    strobe = np.column_stack([x[::CONFIRM_SAMPLES], v[::CONFIRM_SAMPLES]])[-CONFIRM_TAIL:]
    step1 = np.max(np.abs(strobe[1:] - strobe[:-1]))
    step2 = np.max(np.abs(strobe[2:] - strobe[:-2]))
    settled = 1 if step1 <= SAME_STATE else 2 if step2 <= SAME_STATE else None
    tail = x[-CONFIRM_TAIL * CONFIRM_SAMPLES:]
    return FmuRun(p, tuple(start), settled, float(tail.min()), float(tail.max()), tuple(strobe[-1]))


def _walk(points: list[Point], index: int, step: int, delta: float, stable_only: bool = False) -> Point | None:
    """The orbit about `delta` away in p from the event points[index], reached along the branch in list
    direction `step` (+-1) without passing another event (nor an unstable orbit when stable_only): the
    nearest point of the same piece of branch, never an orbit of another piece at the same p."""
    event, found = points[index], None
    i = index + step
    while 0 <= i < len(points):
        pt = points[i]
        if pt.event or (stable_only and not pt.stable):
            break
        found = pt
        if abs(pt.p - event.p) >= delta:
            break
        i += step
    return found


def confirm_event(result: Branch, index: int, fmu, delta: float) -> dict:
    """Long FMU runs on either side of the event points[index] (docs/continuation.md, FMU confirmation),
    each from an orbit of the branch next to the event (_walk), at that orbit's own parameter value:
    fold       from the stable orbit next to the fold at p_in, and the same start at the mirror value
               p_out = 2 p_fold - p_in (no orbit of this piece there): it stays at p_in (same amplitude within
               10 %) and jumps at p_out (amplitude changed by more than 10 %);
    grazing    from the stable orbit on each side: contact lost on one side only, as the branch predicts;
    period-doubling  from the P-orbit on each side (the unstable one 1e-3 off it): settled period 1 on the
               stable side, 2 on the other.
    Returns {event, value, runs, expected, confirmed, reason}."""
    problem, points = result.problem, result.points
    event = points[index]
    record = {"event": event.event, "value": event.p, "delta": delta, "runs": [], "confirmed": False}

    def run(p, start):
        return fmu_run(fmu, problem.scene, problem.param, p, start)

    if event.event == "fold":
        candidates = [pt for pt in (_walk(points, index, -1, delta, True), _walk(points, index, 1, delta, True))
                      if pt is not None]
        if not candidates:
            record["reason"] = "both sides of the fold are unstable: nothing for an FMU run to follow"
            return record
        start = max(candidates, key=lambda pt: abs(pt.p - event.p))
        inside = run(start.p, start.z0)
        outside = run(2.0 * event.p - start.p, start.z0)
        record["runs"] = [inside.as_dict(), outside.as_dict()]
        amp_start = start.x_max - start.x_min
        amp_in, amp_out = inside.x_max - inside.x_min, outside.x_max - outside.x_min
        record["expected"] = (f"at {start.p:.8g} stays on the orbit (amplitude {amp_start / 2:.4g}); at "
                              f"{2.0 * event.p - start.p:.8g} jumps to another orbit")
        stays = inside.settled_period is not None and abs(amp_in - amp_start) < 0.1 * amp_start
        jumps = outside.settled_period is not None and abs(amp_out - amp_start) > 0.1 * amp_start
        record["confirmed"] = bool(stays and jumps)
        record["jump"] = {"amplitude_before": amp_start / 2, "amplitude_after": amp_out / 2}
        return record
    sides = [_walk(points, index, -1, delta), _walk(points, index, 1, delta)]
    if None in sides:
        record["reason"] = "the branch has no orbit on one side of the event"
        return record
    # an unstable orbit is left from a start 1e-3 off it (an exact start would sit on it for as long as the
    # FMU's own errors take to grow)
    runs = [run(pt.p, pt.z0 if pt.stable else pt.z0 + np.array([1e-3, 0.0])) for pt in sides]
    record["runs"] = [r.as_dict() for r in runs]
    if event.event == "grazing":
        if not all(pt.stable for pt in sides):
            record["reason"] = "an orbit next to the grazing is unstable: no FMU run can stay on it"
            return record
        predicted = [pt.x_min < CONTACT_EDGE for pt in sides]
        record["expected"] = f"contact lost: {predicted[0]} at {sides[0].p:.8g}, {predicted[1]} at {sides[1].p:.8g}"
        record["confirmed"] = bool(predicted[0] != predicted[1]
                                   and [r.contact_lost for r in runs] == predicted
                                   and all(r.settled_period == 1 for r in runs))
    elif event.event == "period-doubling":
        expected = [1 if pt.stable else 2 for pt in sides]
        record["expected"] = (f"settled period (in T): {expected[0]} at {sides[0].p:.8g}, {expected[1]} at "
                              f"{sides[1].p:.8g}")
        record["confirmed"] = bool(expected[0] != expected[1] and [r.settled_period for r in runs] == expected)
    else:
        record["reason"] = f"no FMU check for {event.event}"
    return record


def confirm(result: Branch, fmu, delta: float, progress: Callable[[str], None] | None = None) -> list[dict]:
    """confirm_event for every event of the T-periodic branch."""
    records = []
    for index, pt in enumerate(result.points):
        if pt.event:
            record = confirm_event(result, index, fmu, delta)
            record["verdict"] = ("confirmed" if record["confirmed"] else
                                 f"not checkable ({record['reason']})" if "reason" in record else "NOT confirmed")
            records.append(record)
            if progress is not None:
                progress(f"FMU check of the {pt.event} at {result.problem.param} = {pt.p:.8g}: {record['verdict']}")
    return records


# ----- the undamped, unforced oscillator: free orbits continued in energy (a check, docs/continuation.md) -------

@dataclass
class FreeOrbit:
    energy: float  # V(x0) - V(x_e), V = forces.potential (alpha = gamma = 0: x_e = 0)
    x0: float  # the right turning point (v = 0)
    period: float
    closure: float  # |x(T) - x0|, not imposed by the Newton iteration: energy conservation closes the orbit
    monodromy: np.ndarray
    crossings: int
    segments: list = field(repr=False)

    def x(self, s: np.ndarray) -> np.ndarray:
        """x at rescaled time s = 2 pi tau / T in [0, 2 pi]."""
        return piecewise_x(self.segments, s)


def free_orbits(energies, rtol: float = RTOL, R: float = 3.0) -> list[FreeOrbit]:
    """x'' + H(x) = 1 (mu = Delta = alpha = beta = gamma = 0): the orbit of each energy (in increasing order),
    continued in the energy. Unknowns (x0, omega = 2 pi/T): V(x0) - V(0) = E and v(2 pi; (x0, 0), omega) = 0
    (the return to the section v = 0 after one turn), Newton with dv/dx0 = Phi21 and dv/domega from the
    variational equations; the predictor is the secant through the last two orbits (the first is started from
    the linear oscillator, x0 = sqrt(2E), omega = 1). R only places the electrodes (no force: alpha = gamma = 0)."""
    scene = Scene(mu=0.0, Delta=0.0, alpha=0.0, beta=0.0, gamma=0.0, R=R, omega=1.0)
    v_ref = forces.potential(0.0)
    found: list[FreeOrbit] = []
    for energy in energies:
        if len(found) >= 2:
            (e1, a), (e2, b) = [(o.energy, np.array([o.x0, TWO_PI / o.period])) for o in found[-2:]]
            u = b + (b - a) * (energy - e2) / (e2 - e1)
        elif found:
            u = np.array([found[-1].x0, TWO_PI / found[-1].period])
        else:
            u = np.array([math.sqrt(2.0 * energy), 1.0])
        for _ in range(30):
            s = scene.with_values(omega=float(u[1]))
            result = n_period_map(s, "omega", [u[0], 0.0], 1, rtol, dense=True)
            F = np.array([forces.potential(u[0]) - v_ref - energy, result.end[1]])
            if abs(F[1]) <= NEWTON_TOL and abs(F[0]) <= 1e-14 * max(1.0, energy):
                break
            g0 = forces.hertz(u[0]) - 1.0  # V'(x0)
            J = np.array([[g0, 0.0], [result.monodromy[1, 0], result.d_param[1]]])
            u = u - np.linalg.solve(J, F)
        else:
            raise ShootingError(f"free orbit of energy {energy:g} did not converge")
        found.append(FreeOrbit(energy=float(energy), x0=float(u[0]), period=TWO_PI / float(u[1]),
                               closure=float(abs(result.end[0] - u[0])), monodromy=result.monodromy,
                               crossings=result.crossings, segments=result.segments))
    return found


def free_energy(x: float) -> float:
    """W(x) = V(x) - V(0) of the free oscillator (alpha = gamma = 0), without V's cancellation near x = 0:
    (3/5)[(1 + y)^(5/2) - 1 - 5y/2] with y = 2x/3 in contact (expm1/log1p), -x - 3/5 beyond the contact edge."""
    if x <= CONTACT_EDGE:
        return -x - 0.6
    y = 2.0 * x / 3.0
    return 0.6 * (math.expm1(2.5 * math.log1p(y)) - 2.5 * y)


def quadrature_period(energy: float) -> float:
    """T(E) = 2 int_{x-}^{x+} dx / sqrt(2 (E - W(x))), independent of any ODE solver: with W(x) = E sin^2 theta
    on each side of x = 0, dx = 2E sin cos dtheta / W'(x), so T = 2 sqrt(2E) int_0^{pi/2} sin theta
    (1/W'(x+(theta)) + 1/|W'(x-(theta))|) dtheta, a smooth integrand (split where x- crosses the contact edge,
    where W'' jumps); x(theta) by Brent, the integral by scipy's quad."""
    from scipy.integrate import quad

    def slope(x):  # W'(x) = H(x) - 1
        return forces.hertz(x) - 1.0

    def x_at(theta, side):
        level = energy * math.sin(theta) ** 2
        if level == 0.0:
            return 0.0
        bound = side * (1.0 + 2.0 * energy + 2.0 * math.sqrt(2.0 * energy))
        return brentq(lambda x: free_energy(x) - level, 0.0, bound, xtol=1e-16, rtol=1e-15)

    def integrand(theta):
        if theta == 0.0:
            return 2.0 / math.sqrt(2.0 * energy)  # W' ~ x ~ sqrt(2E) theta on both sides
        return math.sin(theta) * (1.0 / slope(x_at(theta, 1.0)) + 1.0 / abs(slope(x_at(theta, -1.0))))

    edge = free_energy(CONTACT_EDGE)  # 0.9
    points = [math.asin(math.sqrt(edge / energy))] if energy > edge else None
    value, _ = quad(integrand, 0.0, math.pi / 2, points=points, epsabs=0.0, epsrel=1e-13, limit=200)
    return 2.0 * math.sqrt(2.0 * energy) * value
