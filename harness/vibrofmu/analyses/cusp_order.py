"""The exact cusp of the primary resonance beside the slow flow's, and the order of their difference in the
averaging's small parameter (docs/continuation.md, The cusp against the averaging's).

Scaling. The slow flow (vibromodel.averaging: first-order averaging with the Lindstedt backbone
kappa(r) = kappa2 r^2 + kappa4 r^4) is the leading order of x'' + mu x' + g(x) = Delta cos(omega tau) when the
amplitude r ~ eps, the damping mu ~ eps^2, the detuning omega - omega_e ~ eps^2 and the drive Delta ~ eps^3: then
every term of its rates, mu r, (omega - omega_e) r, kappa2 r^3, Delta, is O(eps^3). The family here:
mu = MU1 eps^2, Delta = DELTA1 eps^3 (the branch that starts the fold curve), R = 3, beta = gamma = 0.

The slow flow's cusp. Steady states: s (mu^2/4 + u^2) = d^2 with s = r^2, u = D - kappa(r), D = (omega^2 - k1) /
(2 omega) (its detuning), d = Delta / (2 omega). With F(s) = s (mu^2/4 + u(s)^2) - d^2, a fold is F_s = 0 and the
cusp F_s = F_ss = 0, which do not involve d: F_ss = 0 gives u = s k'^2 / (2 k' + s k'') (k(s) = kappa2 s + kappa4
s^2, primes in s), then F_s = mu^2/4 + u^2 - 2 s u k' = 0 is one equation in s (bracketed around its kappa4 = 0
root s = mu / (sqrt 3 |kappa2|)), solved by Brent to rounding; then D = u + k(s), omega = D + sqrt(D^2 + k1),
Delta = 2 omega sqrt(s (mu^2/4 + u^2)). No sampling, no bisection.

The exact cusp. On the fold curve in (omega, Delta) (curves.py: P(z) = z and the bordered g = 0) the cusp is where
both parameters turn: the curve's tangent lies in the state, so Delta along the curve has an extremum there
(Delta - Delta_c ~ t^2 in a regular parameter t of the curve, while b Delta - a omega ~ t^3). It is located as that
extremum: Brent's minimiser on Delta(t), each Delta(t) a point of the curve on the hyperplane through the
sign-change estimate of curves.locate_cusp normal to its tangent, at distance t. This uses only points that solve
the fold system -- not the quadratic coefficient's finite differences; the two locations are reported side by side.

The order expected. The slow flow drops the next order of the expansion: its rates are exact to O(eps^3) and wrong
at O(eps^5) (second-order averaging: terms mu^2 r, mu kappa2 r^3, Delta r ..., each eps^2 times a leading term),
so the cusp's coordinates, set by a balance of O(eps^3) terms, are wrong relatively by O(eps^2):
|Delta_c - Delta_c,slow| = O(eps^3 eps^2) = O(eps^5) and |omega_c - omega_c,slow| = O(eps^2 eps^2) = O(eps^4)
(omega_c - omega_e ~ eps^2). The fit of log |error| against log eps measures the orders.
"""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

from vibromodel.parameters import Scene

from vibrofmu.analyses import continuation as cont
from vibrofmu.analyses import curves
from vibrofmu.analyses.continuation_output import omega_window, slow_flow_cusp_point

MU1, DELTA1, R = 0.01, 0.008, 3.0  # mu = MU1 eps^2, the starting branch at Delta = DELTA1 eps^3
EPSILONS = (1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125)
# the fit of the order uses eps <= FIT_MAX: above it the error in Delta changes sign (between eps = 1/2 and 1/4: the
# O(eps^5) term and the next, O(eps^7), of opposite signs, are of one size there), so the leading order is not yet
# alone; the local orders between successive eps are reported for all
FIT_MAX = 0.125
EXPECTED_ORDERS = {"Delta": 5, "omega": 4}  # module doc
# the cusp located with the period map at rtol 1e-13 and the fold system solved to 1e-12 (the engine's 1e-11, 1e-10
# are coarse here: the amplitudes shrink like eps, the tolerances are absolute), and again at 10 x both: the
# difference of the two locations estimates the exact cusp's own error, which must lie far below the averaging's
TIGHT_RTOL, TIGHT_TOL = 1e-13, 1e-12


def scene_of(eps: float) -> Scene:
    return Scene(mu=MU1 * eps**2, Delta=DELTA1 * eps**3, R=R, beta=0.0, gamma=0.0)


def slow_flow_cusp(scene: Scene) -> dict:
    """(omega, Delta, r) of the slow flow's cusp (module doc; continuation_output.slow_flow_cusp_point)."""
    return slow_flow_cusp_point(scene)


def refine_cusp(system: curves.Augmented, estimate: curves.CurvePoint, width: float,
                tol: float = curves.TOL) -> tuple[curves.CurvePoint, int]:
    """The extremum of Delta along the fold curve near `estimate` (module doc), t in (-width, width) along its
    tangent: (the point, evaluations)."""
    u0 = np.array([*estimate.z0, estimate.p1 / system.scales[0], estimate.p2 / system.scales[1]])
    n = estimate.tangent
    cache: dict[float, curves.CurvePoint] = {}

    def point(t):
        if t not in cache:
            u, pmap, _, _ = curves.correct(system, u0 + t * n, n, max_iter=12, tol=tol)
            g, _, _ = system.bordered(pmap.monodromy)
            cache[t] = system.point(u, pmap, g, math.nan)
        return cache[t]

    sign = 1.0 if point(width).p2 > estimate.p2 else -1.0  # a minimum of Delta at a cusp pointing down, else a maximum
    found = minimize_scalar(lambda t: sign * point(t).p2, bounds=(-width, width), method="bounded",
                            options={"xatol": 1e-10 * width})
    located = point(found.x)
    located.event = "cusp"
    return located, len(cache)


def exact_cusp(scene: Scene, points: int = 40) -> dict:
    """The fold curve of scene's omega-branch continued down in Delta through the cusp; the cusp by the sign change
    of the quadratic coefficient (curves.locate_cusp) and refined as Delta's extremum (refine_cusp)."""
    slow = slow_flow_cusp(scene)
    lo, hi = omega_window(scene)
    branch = cont.branch(scene, "omega", lo, hi, points=points, double=False)
    folds = [pt for pt in branch.points if pt.event == "fold"]
    if len(folds) != 2:
        raise RuntimeError(f"{len(folds)} folds on the omega-branch at Delta = {scene.Delta:g} (expected 2)")
    found = curves.curves_from_branch(branch, "fold", "Delta", 0.5 * slow["Delta"], scene.Delta, points=points)
    cusps = [(c, k) for c in found.curves for k, pt in enumerate(c.points) if pt.event == "cusp"]
    if not cusps:
        raise RuntimeError(f"no cusp on the fold curve from Delta = {scene.Delta:g}")
    curve, k = cusps[0]
    estimate = curve.points[k]
    neighbours = [curve.points[j] for j in (k - 1, k + 1) if 0 <= j < len(curve.points)]
    located = {}
    for name, rtol, tol in (("check", 10 * TIGHT_RTOL, 10 * TIGHT_TOL), ("tight", TIGHT_RTOL, TIGHT_TOL)):
        system = curves.Augmented(scene, "fold", "omega", "Delta", _scales(found, branch, scene), 1, rtol)
        u0 = np.array([*estimate.z0, estimate.p1 / system.scales[0], estimate.p2 / system.scales[1]])
        width = max(abs(float(estimate.tangent @ (np.array([*p.z0, p.p1 / system.scales[0], p.p2 / system.scales[1]])
                                                  - u0))) for p in neighbours)
        refined, evaluations = refine_cusp(system, estimate, width, tol)
        located[name] = {"omega": refined.p1, "Delta": refined.p2, "residual": refined.residual, "g": refined.g,
                         "evaluations": evaluations, "x_min": refined.x_min, "x_max": refined.x_max,
                         "rtol": rtol, "tol": tol, "z0": [float(refined.z0[0]), float(refined.z0[1])]}
    return {"sign_change": {"omega": estimate.p1, "Delta": estimate.p2}, **located,
            "curve_points": len(curve.points), "slow_flow": slow}


def _scales(found: curves.Curves, branch, scene: Scene) -> tuple[float, float]:
    """curves_from_branch's scales for this branch and range (so the tangent of a curve point is in its units)."""
    values = [pt.p for pt in branch.points]
    return (max(values) - min(values) or 1.0, abs(scene.Delta - 0.5 * slow_flow_cusp(scene)["Delta"]) or 1.0)


def fit_order(eps, errors) -> tuple[float, float]:
    """(slope, its standard error) of log |error| against log eps by least squares."""
    x, y = np.log(np.asarray(eps, float)), np.log(np.abs(np.asarray(errors, float)))
    A = np.vstack([x, np.ones_like(x)]).T
    coef, res, *_ = np.linalg.lstsq(A, y, rcond=None)
    dof = len(x) - 2
    sigma2 = float(res[0]) / dof if dof > 0 and res.size else 0.0
    cov = sigma2 * np.linalg.inv(A.T @ A)
    return float(coef[0]), math.sqrt(cov[0, 0])


def study(epsilons=EPSILONS, progress=None) -> dict:
    """The exact and slow-flow cusps at each eps, the errors, their fitted order over eps <= FIT_MAX and the local
    orders."""
    t0, c0 = time.perf_counter(), time.process_time()
    rows = []
    for eps in epsilons:
        scene = scene_of(eps)
        result = exact_cusp(scene)
        exact, slow = result["tight"], result["slow_flow"]
        row = {"eps": eps, "mu": scene.mu, "Delta_start": scene.Delta, **{f"exact_{k}": v for k, v in exact.items()},
               "sign_change_omega": result["sign_change"]["omega"], "sign_change_Delta": result["sign_change"]["Delta"],
               "check_omega": result["check"]["omega"], "check_Delta": result["check"]["Delta"],
               "slow_omega": slow["omega"], "slow_Delta": slow["Delta"], "slow_r": slow["r"],
               "error_Delta": exact["Delta"] - slow["Delta"], "error_omega": exact["omega"] - slow["omega"]}
        rows.append(row)
        if progress:
            progress(f"eps = {eps:g}: exact cusp omega = {exact['omega']:.10f}, Delta = {exact['Delta']:.8e}; slow "
                     f"flow's {slow['omega']:.10f}, {slow['Delta']:.8e}")
    orders = {}
    tail = [r for r in rows if r["eps"] <= FIT_MAX]
    for name in ("Delta", "omega"):
        slope, stderr = fit_order([r["eps"] for r in tail], [r[f"error_{name}"] for r in tail])
        local = [math.log(abs(a[f"error_{name}"] / b[f"error_{name}"])) / math.log(a["eps"] / b["eps"])
                 if a[f"error_{name}"] * b[f"error_{name}"] > 0 else None for a, b in zip(rows, rows[1:])]
        orders[name] = {"order": slope, "stderr": stderr, "expected": EXPECTED_ORDERS[name], "fit_points": len(tail),
                        "local": local}
    return {"family": {"mu": f"{MU1} eps^2", "Delta_start": f"{DELTA1} eps^3", "R": R, "beta": 0.0, "gamma": 0.0},
            "fit_max": FIT_MAX, "tight": [TIGHT_RTOL, TIGHT_TOL],
            "rows": rows, "orders": orders, "seconds": time.perf_counter() - t0,
            "cpu_seconds": time.process_time() - c0}


def main(argv) -> int:
    if len(argv) != 1:
        print("usage: python3 -m vibrofmu.analyses.cusp_order OUT_FOLDER", file=sys.stderr)
        return 2
    out = Path(argv[0])
    out.mkdir(parents=True, exist_ok=True)
    data = study(progress=lambda line: print(line, file=sys.stderr, flush=True))
    (out / "cusp_order.json").write_text(json.dumps(data, indent=1))
    for name, o in data["orders"].items():
        print(f"error in {name}: order {o['order']:.3f} +- {o['stderr']:.3f} over eps <= {FIT_MAX:g} (expected "
              f"{o['expected']}); local orders " + ", ".join("-" if x is None else f"{x:.2f}" for x in o["local"]))
    print(f"wrote {out}/cusp_order.json ({data['cpu_seconds']:.0f} s CPU)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
