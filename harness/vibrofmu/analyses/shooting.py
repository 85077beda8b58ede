"""Ground truth for the steady vibrations of Eq. 3: periodic orbits by shooting, continued in omega (issue 4).

Model. Eq. 3 (docs/model.md, Scaling) with U = 0, written as x'' + mu x' + g(x) = Delta cos(omega tau) with the
restoring force g(x) = H(x) - 1 - F_em(x). The AC part of F_em, (beta sin Omega tau - gamma cos 2 Omega tau)
(1-u)^-2, has the frequencies Omega and 2 Omega, which are not commensurate with omega: Eq. 3 then has no
T-periodic orbit at all. Shooting therefore uses the AC drive at its mean gamma (forces.electrostatic_mean).
What that drops is the fast response psi = O(beta/Omega^2) = 2.5e-5 and its averaged feedback on the slow
motion, m2, q1 of docs/model.md, Averaging and slow flow = O(beta^2/Omega^2) ~ 1e-9 in the stiffness (far below the 5 digits of
the §3.4(f) table); with beta = gamma = 0 the model is Eq. 3 exactly. PeriodicModel(polynomial=True) shoots
the degree-5 Eq. 7 instead (corrected a_k): docs/model.md, Averaging and slow flow's shooting column was computed with that model.

Time is rescaled, s = omega tau, so the period is 2 pi for every omega:
    dx/ds = v/omega,   dv/ds = (Delta cos s - mu v - g(x))/omega,   v = dx/dtau.
The state is integrated together with its fundamental matrix Phi = dz(s)/dz(0) and its omega-sensitivity
dz(s)/domega (variational equations), all with scipy's DOP853 at rtol 1e-11: the multipliers near a fold
are 1 +- 2e-3 (§3.4(f)), so deciding stable/saddle there needs M to ~1e-6 and the Liouville check
rho1 rho2 = exp(-mu T) to ~1e-9; DOP853's global error is a small multiple of rtol over one period, and
rtol 1e-11 leaves two decades to spare above the ~1e-13 round-off floor of the 8-state system.

Contact loss (1 + 2x/3 = 0, x = -1.5): H is C^1 there (H' = (1 + 2x/3)^(1/2) -> 0) but H'' is singular, so
the integration is stopped at each crossing (solve_ivp event) and restarted; Phi needs no jump (saltation)
because the vector field stays C^1. Each orbit reports its number of crossings. A pull-in (an electrode gap
below PULL_IN_GAP) raises ShootingError.
"""
from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, newton

from vibromodel import forces
from vibromodel.parameters import PULL_IN_GAP, Scene

from vibrofmu.analyses.harmonics import first_harmonic

RTOL = 1e-11
ATOL = 1e-13  # absolute floor: the state and Phi are O(0.01 .. 1), the omega-sensitivity O(1 .. 100)
NEWTON_TOL = 1e-10  # on |P(z) - z|_inf: 1e3 x the period map's own error ~ rtol |z|
HARMONIC_SAMPLES = 512  # trapezoid rule on a periodic analytic integrand: converges geometrically
TWO_PI = 2.0 * math.pi


class ShootingError(RuntimeError):
    """Newton or the continuation did not converge, or the orbit hit an electrode (pull-in)."""


@dataclass(frozen=True)
class PeriodicModel:
    """x'' + mu x' + g(x) = Delta cos(omega tau): the T-periodic part of the plant that is shot.

    exact (default): g(x) = H(x) - 1 - F_em,mean(x), Eq. 3 with the AC drive at its mean (module doc).
    polynomial: g(x) = sum a_k x^k with the corrected a0..a5 of Eq. 7 (docs/model.md, Series and polynomial model), the degree-5
    truncation the averaged slow flow (§3.4(a)) starts from.
    """

    scene: Scene
    polynomial: bool = False

    def restoring(self) -> tuple[Callable[[float], float], Callable[[float], float]]:
        """(g, g'): plain Python closures for the integrator's hot path."""
        s = self.scene
        if self.polynomial:
            a = forces.coefficients(s.alpha, s.gamma, s.R)
            da = tuple(k * a[k] for k in range(1, len(a)))
            return (lambda x: forces.horner(a, x)), (lambda x: forces.horner(da, x))
        alpha, gamma, R = s.alpha, s.gamma, s.R
        hertz, hertz_k = forces.hertz, forces.hertz_stiffness
        em, em_k = forces.electrostatic_mean, forces.electrostatic_mean_stiffness
        return (lambda x: hertz(x) - 1.0 - em(x, alpha, gamma, R)), (lambda x: hertz_k(x) - em_k(x, alpha, gamma, R))

    def equilibrium(self) -> tuple[float, float]:
        """(x_e, k1): root of g next to x = 0 (Newton from 0; g(0) = -gamma is small) and k1 = g'(x_e).

        omega_e = sqrt(k1) is the small-amplitude resonance (docs/model.md, Averaging and slow flow without the O(1e-9)
        vibrational corrections of the AC part).
        """
        g, g_x = self.restoring()
        x_e = newton(g, 0.0, fprime=g_x, tol=1e-15, maxiter=50)
        return x_e, g_x(x_e)

    def period(self, omega: float) -> float:
        return TWO_PI / omega


PARAMETERS = ("omega", "Delta", "mu", "alpha", "gamma")  # what the period map has the sensitivity to


def _parameter_field(model: PeriodicModel, omega: float, param: str) -> Callable[[float, float, float], tuple]:
    """df/dp (x, v, s) of the rescaled field f = (v/omega, (Delta cos s - mu v - g(x))/omega) for p != omega
    (omega's, -f/omega, is formed in variational_rhs). g is linear in alpha and gamma: dg/dalpha = -F_em,mean(x; 1, 0)."""
    w, R = 1.0 / omega, model.scene.R
    em = forces.electrostatic_mean
    if param == "Delta":
        return lambda x, v, s: (0.0, math.cos(s) * w)
    if param == "mu":
        return lambda x, v, s: (0.0, -v * w)
    if param in ("alpha", "gamma") and model.polynomial:
        raise ValueError(f"parameter {param!r}: the polynomial model has no sensitivity to it")
    if param == "alpha":
        return lambda x, v, s: (0.0, em(x, 1.0, 0.0, R) * w)
    if param == "gamma":
        return lambda x, v, s: (0.0, em(x, 0.0, 1.0, R) * w)
    raise ValueError(f"parameter {param!r}: the period map supports {', '.join(PARAMETERS)}")


def variational_rhs(model: PeriodicModel, omega: float, param: str = "omega"):
    """f(s, y) for y = (x, v, Phi11, Phi21, Phi12, Phi22, x_p, v_p) in rescaled time s = omega tau, p = `param`.

    Phi' = J Phi with J = [[0, 1/omega], [-g'(x)/omega, -mu/omega]];
    z_p' = J z_p + df/dp, with df/domega = -(x', v')/omega (the explicit 1/omega of the field).
    Plain Python floats: numpy arithmetic on 8-element arrays only adds call overhead.
    """
    g, g_x = model.restoring()
    mu, Delta, w = model.scene.mu, model.scene.Delta, 1.0 / omega
    cos = math.cos
    dfdp = None if param == "omega" else _parameter_field(model, omega, param)

    def rhs(s, y):
        x, v, p11, p21, p12, p22, xp, vp = y
        dx = v * w
        dv = (Delta * cos(s) - mu * v - g(x)) * w
        kx, kv = -g_x(x) * w, -mu * w
        if dfdp is None:
            fx, fv = -dx * w, -dv * w
        else:
            fx, fv = dfdp(x, v, s)
        return [dx, dv,
                p21 * w, kx * p11 + kv * p21,
                p22 * w, kx * p12 + kv * p22,
                vp * w + fx, kx * xp + kv * vp + fv]

    return rhs


def _events(R: float):
    """Contact loss / regain (x = -1.5, non-terminal for the physics, used to restart) and pull-in."""
    c = 2.0 / (3.0 * R)

    def contact(s, y):
        return forces.contact_indentation(y[0])

    def upper_gap(s, y):
        return 1.0 - c * y[0] - PULL_IN_GAP

    def lower_gap(s, y):
        return 1.0 + c * y[0] - PULL_IN_GAP

    def turning_point(s, y):  # v = 0: the extrema of x
        return y[1]

    contact.terminal = upper_gap.terminal = lower_gap.terminal = True
    return contact, upper_gap, lower_gap, turning_point


@dataclass
class PeriodMap:
    """n periods of the variational system from z0 at omega: P^n(z0), M = dP^n/dz0, dP^n/dp for p = `param`."""

    omega: float
    z0: np.ndarray
    end: np.ndarray
    monodromy: np.ndarray
    d_param: np.ndarray
    segments: list  # OdeSolution per smooth piece (split at contact crossings)
    extrema: np.ndarray  # x at v = 0
    contact_crossings: int
    param: str = "omega"
    periods: int = 1

    @property
    def d_omega(self) -> np.ndarray:
        if self.param != "omega":
            raise AttributeError(f"this period map has the sensitivity to {self.param}, not omega")
        return self.d_param

    @property
    def residual(self) -> np.ndarray:
        return self.end - self.z0

    @property
    def x_min(self) -> float:
        """min x over the orbit: the turning points and both ends."""
        return float(min(self.z0[0], self.end[0], *self.extrema))

    @property
    def x_max(self) -> float:
        return float(max(self.z0[0], self.end[0], *self.extrema))

    @property
    def crossings(self) -> int:
        return self.contact_crossings

    def x(self, s: np.ndarray) -> np.ndarray:
        """x(s) on [0, 2 pi] from the dense output of the piece that holds s."""
        return piecewise_x(self.segments, s)


def piecewise_x(segments, s) -> np.ndarray:
    """x(s) from the dense outputs `segments` (OdeSolutions of consecutive pieces), each s from the piece holding it."""
    s = np.asarray(s, dtype=float)
    out = np.empty_like(s)
    for sol in segments:
        inside = (s >= sol.t_min) & (s <= sol.t_max)
        out[inside] = sol(s[inside])[0]
    return out


def integrate_pieces(rhs, R: float, z0, s_end: float, rtol: float, where: str = ""):
    """The variational system `rhs` (state, fundamental matrix from the identity, parameter derivative from 0) from
    z0 at s = 0 to s_end with DOP853 (dense output), restarted at each contact crossing: (the final y, the pieces'
    OdeSolutions, x at each turning point v = 0, the number of contact crossings). A solver failure or pull-in is a
    ShootingError; `where` (e.g. ", omega = 0.93") places it in the message."""
    contact, upper_gap, lower_gap, turning_point = _events(R)
    y = np.concatenate([np.asarray(z0, dtype=float), [1.0, 0.0, 0.0, 1.0, 0.0, 0.0]])
    s, segments, extrema, crossings = 0.0, [], [], 0
    contact.direction = -1.0 if contact(0.0, y) > 0.0 else 1.0
    while True:
        sol = solve_ivp(rhs, (s, s_end), y, method="DOP853", rtol=rtol, atol=ATOL, dense_output=True,
                        events=(contact, upper_gap, lower_gap, turning_point))
        if sol.status < 0:
            raise ShootingError(f"DOP853 failed at s = {sol.t[-1]:.6g}{where}: {sol.message}")
        segments.append(sol.sol)
        extrema.extend(float(y_event[0]) for y_event in sol.y_events[3])
        if sol.t_events[1].size or sol.t_events[2].size:
            raise ShootingError(f"pull-in (an electrode gap below {PULL_IN_GAP:g}) at x = {sol.y[0, -1]:.6g}{where}")
        y, s = sol.y[:, -1], sol.t[-1]
        if sol.status == 0:
            return y, segments, extrema, crossings
        crossings += 1
        contact.direction = -contact.direction  # the next crossing is the way back


# ----- the compiled period map (fmu_src/core/periodmap.c): the same system on the core's DOP853 ---------------

_COMPILED: list = []  # per process: [vk_period_map or None, why not]


def compiled_period_map():
    """(the kernel's vk_period_map, "") or (None, why it cannot be used): loaded once per process."""
    if not _COMPILED:
        try:
            from vibrofmu.fmus.kernel import kernel_library  # compiled once per source version

            function = kernel_library().vk_period_map
            d, i = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int64)
            function.restype = ctypes.c_int
            function.argtypes = [d, ctypes.c_int64, ctypes.c_int64, d, d, i, ctypes.c_char_p, ctypes.c_int64]
            _COMPILED.extend([function, ""])
        except (RuntimeError, OSError, AttributeError) as error:  # no compiler, a failed build, an old kernel
            _COMPILED.extend([None, f"the compiled period map is not available ({error}): scipy's DOP853 instead"])
    return _COMPILED[0], _COMPILED[1]


def _compiled_map(function, model: PeriodicModel, z0, omega: float, rtol: float, param: str,
                  periods: int) -> PeriodMap:
    s = model.scene
    scene = (ctypes.c_double * 9)(s.mu, s.Delta, omega, s.alpha, s.gamma, s.R, rtol, ATOL, PULL_IN_GAP)
    z = (ctypes.c_double * 2)(float(z0[0]), float(z0[1]))
    out, counts, message = (ctypes.c_double * 10)(), (ctypes.c_int64 * 3)(), ctypes.create_string_buffer(512)
    code = function(scene, PARAMETERS.index(param), periods, z, out, counts, message, 512)
    if code != 0:
        raise ShootingError(f"{message.value.decode(errors='replace')}, omega = {omega:.10g}")
    return PeriodMap(omega=omega, z0=np.array([z[0], z[1]]), end=np.array(out[0:2]),
                     monodromy=np.array([[out[2], out[4]], [out[3], out[5]]]), d_param=np.array(out[6:8]),
                     segments=[], extrema=np.array(out[8:10]), contact_crossings=int(counts[0]), param=param,
                     periods=periods)


def period_map(model: PeriodicModel, z0, omega: float, rtol: float = RTOL, param: str = "omega",
               periods: int = 1, dense: bool = True) -> PeriodMap:
    """Integrate `periods` periods, s in [0, 2 pi periods], with DOP853 (dense output), restarting at each contact
    crossing, with the sensitivity to `param` (PARAMETERS). The one period map of the package: shooting,
    continuation in any parameter and the two-parameter curves all call it.

    dense=False: no dense output is needed (PeriodMap.x unavailable; x_min, x_max from the turning points as
    always): the exact model is then integrated by the compiled twin (fmu_src/core/periodmap.c: the same system, the
    same DOP853 tableau and tolerances, the steps cut at contact and at v = 0 instead of restarted), ~100 x faster;
    scipy's where the kernel cannot be built (compiled_period_map says why) or for the polynomial model."""
    if param not in PARAMETERS:
        raise ValueError(f"parameter {param!r}: the period map supports {', '.join(PARAMETERS)}")
    if not dense and not model.polynomial:
        function, _ = compiled_period_map()
        if function is not None:
            return _compiled_map(function, model, z0, omega, rtol, param, periods)
    y, segments, extrema, crossings = integrate_pieces(variational_rhs(model, omega, param), model.scene.R, z0,
                                                       TWO_PI * periods, rtol, f", omega = {omega:.10g}")
    return PeriodMap(omega=omega, z0=np.asarray(z0, dtype=float).copy(), end=y[:2].copy(),
                     monodromy=np.array([[y[2], y[4]], [y[3], y[5]]]), d_param=y[6:8].copy(),
                     segments=segments, extrema=np.array(extrema), contact_crossings=crossings, param=param,
                     periods=periods)


def multipliers(monodromy: np.ndarray) -> np.ndarray:
    """Floquet multipliers eig(M), complex, sorted by modulus."""
    rho = np.linalg.eigvals(monodromy).astype(complex)
    return rho[np.argsort(np.abs(rho))]


def border_of(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(b, c): the left and right singular vectors of A's smallest singular value, the bordering that keeps
    [[A, b], [c^T, 0]] best conditioned near a singular A."""
    U, _, Vt = np.linalg.svd(A)
    return U[:, -1].copy(), Vt[-1].copy()


def bordered_test(A: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The bordered test function g of A and its vectors w, v (Govaerts 2000, ch. 3):
    [[A, b], [c^T, 0]] [w; g] = [0; 1] and [v^T, h] [[A, b], [c^T, 0]] = [0, 1]. g = 0 exactly where A is
    singular (for any b, c keeping the bordered matrix regular), with no reference to a branch tangent;
    dg/dy = -v^T (dA/dy) w."""
    n = A.shape[0]
    K = np.zeros((n + 1, n + 1))
    K[:n, :n] = A
    K[:n, n] = b
    K[n, :n] = c
    rhs = np.zeros(n + 1)
    rhs[n] = 1.0
    wg = np.linalg.solve(K, rhs)
    vh = np.linalg.solve(K.T, rhs)
    return float(wg[n]), wg[:n], vh[:n]


def newton_shoot(map_of: Callable[[np.ndarray], PeriodMap], z_guess, tol: float = NEWTON_TOL, max_iter: int = 25,
                 where: str = "") -> PeriodMap:
    """Newton on P(z) - z = 0 (Jacobian M - I) for the period map `map_of` at a fixed parameter: the period map
    at the last iterate z (no extrapolated step) once |P(z) - z|_inf <= tol. Near a fold M - I is nearly
    singular: the residual is then the meaningful measure, the state error is ~ tol / sigma_min(M - I)."""
    z = np.asarray(z_guess, dtype=float)
    for _ in range(max_iter):
        pmap = map_of(z)
        residual = pmap.end - z
        if np.max(np.abs(residual)) <= tol:
            return pmap
        z = z - np.linalg.solve(pmap.monodromy - np.eye(2), residual)
    raise ShootingError(f"Newton shooting did not converge in {max_iter} iterations{where}")


def branch_tangent(monodromy: np.ndarray, d_param: np.ndarray, scale: float, previous: np.ndarray,
                   where: str = "") -> np.ndarray:
    """Unit null vector of dG/du = [M - I, dP/dp * scale] in u = (x0, v0, p / scale) (the cross product of its two
    rows), oriented along `previous`."""
    jac = np.column_stack([monodromy - np.eye(2), d_param * scale])
    t = np.cross(jac[0], jac[1])
    norm = np.linalg.norm(t)
    if norm == 0.0:
        raise ShootingError(f"singular branch Jacobian{where}")
    t /= norm
    return t if np.dot(t, previous) >= 0.0 else -t


def arclength_correct(map_of: Callable[[np.ndarray, float], PeriodMap], u_pred: np.ndarray, normal: np.ndarray,
                      scale: float, tol: float = NEWTON_TOL, max_iter: int = 8,
                      name: str = "omega") -> tuple[PeriodMap, float, int]:
    """Keller's pseudo-arclength corrector: Newton on (P(z, p) - z, normal . (u - u_pred)) = 0 in
    u = (x0, v0, p / scale), `map_of(z, p)` the period map with the sensitivity to p.
    Returns (the period map at the converged point, p, the iteration count); ShootingError if the residual does
    not reach tol."""
    u = np.array(u_pred, dtype=float)
    for iteration in range(max_iter):
        p = u[2] * scale
        pmap = map_of(u[:2], p)
        residual = pmap.end - u[:2]
        if np.max(np.abs(residual)) <= tol:
            return pmap, p, iteration
        jac = np.zeros((3, 3))
        jac[:2, :2] = pmap.monodromy - np.eye(2)
        jac[:2, 2] = pmap.d_param * scale
        jac[2] = normal
        u = u - np.linalg.solve(jac, np.append(residual, np.dot(normal, u - u_pred)))
        if not np.all(np.isfinite(u)):
            break
    raise ShootingError(f"corrector did not converge at {name} ~ {u[2] * scale:.10g}")


@dataclass
class Orbit:
    """A T-periodic orbit of Eq. 3 and its Floquet data (docs/model.md, Averaging and slow flow)."""

    omega: float
    z0: np.ndarray  # (x, x') at tau = 0 (phase of Delta cos omega tau)
    monodromy: np.ndarray
    multipliers: np.ndarray  # eig(M), sorted by modulus
    liouville_error: float  # |rho1 rho2 - exp(-mu T)|
    r: float  # first-harmonic amplitude |2/T int x e^{-i omega tau} dtau|
    phase: float  # arg of that coefficient: x ~ mean + r cos(omega tau + phase)
    mean: float
    x_max: float
    x_min: float
    residual: float  # |P(z0) - z0|_inf
    contact_crossings: int
    d_omega: np.ndarray = field(repr=False)  # dP/domega at z0

    @property
    def kind(self) -> str:
        """'stable' if max |rho| < 1; 'saddle' if a real multiplier > 1; 'flip' if one < -1; else 'unstable'."""
        rho = self.multipliers
        if np.max(np.abs(rho)) < 1.0:
            return "stable"
        real = rho[np.abs(rho.imag) <= 1e-12 * np.abs(rho)].real
        if np.any(real > 1.0):
            return "saddle"
        return "flip" if np.any(real < -1.0) else "unstable"

    @property
    def stable(self) -> bool:
        return self.kind == "stable"


def orbit_harmonic(pmap: PeriodMap) -> tuple[complex, float]:
    """(c1, mean) of the orbit (harmonics.first_harmonic of x at HARMONIC_SAMPLES phases over one period)."""
    s = np.arange(HARMONIC_SAMPLES) * (TWO_PI / HARMONIC_SAMPLES)
    return first_harmonic(pmap.x(s), HARMONIC_SAMPLES)


def orbit_from(model: PeriodicModel, pmap: PeriodMap) -> Orbit:
    """Floquet multipliers, Liouville check, first harmonic, mean and extrema of the orbit through pmap.z0."""
    c1, mean = orbit_harmonic(pmap)
    rho = multipliers(pmap.monodromy)
    x_ends = np.concatenate([pmap.extrema, pmap.z0[:1]])
    return Orbit(
        omega=pmap.omega, z0=pmap.z0, monodromy=pmap.monodromy, multipliers=rho,
        liouville_error=float(abs(np.prod(rho) - math.exp(-model.scene.mu * model.period(pmap.omega)))),
        r=float(abs(c1)), phase=float(np.angle(c1)), mean=mean,
        x_max=float(x_ends.max()), x_min=float(x_ends.min()),
        residual=float(np.max(np.abs(pmap.end - pmap.z0))), contact_crossings=pmap.contact_crossings,
        d_omega=pmap.d_omega)


def shoot(model: PeriodicModel, omega: float, z_guess, tol: float = NEWTON_TOL, max_iter: int = 25) -> Orbit:
    """Newton shooting on P(z) - z = 0 at fixed omega, Jacobian M - I.

    Converged when |P(z) - z|_inf <= tol; the orbit returned is the last iterate z with its own M (no
    extrapolated step). Near a fold M - I is nearly singular: the residual is then the meaningful measure,
    the state error is ~ tol / sigma_min(M - I).
    """
    pmap = newton_shoot(lambda z: period_map(model, z, omega), z_guess, tol, max_iter, f" at omega = {omega:.10g}")
    return orbit_from(model, pmap)


def linear_guess(model: PeriodicModel, omega: float) -> np.ndarray:
    """z0 of the linearised response x_e + Re[Delta e^{i omega tau} / (k1 - omega^2 + i mu omega)]."""
    x_e, k1 = model.equilibrium()
    c = model.scene.Delta / complex(k1 - omega**2, model.scene.mu * omega)
    return np.array([x_e + c.real, -omega * c.imag])


# ----- pseudo-arclength continuation in omega --------------------------------------------------------

@dataclass
class Fold:
    """A turning point in omega (saddle-node of periodic orbits): located by the tangent and by rho = 1."""

    omega: float  # where the omega-component of the branch tangent vanishes
    omega_multiplier: float  # where a Floquet multiplier (eig M) crosses +1
    r: float
    orbit: Orbit


@dataclass
class FrequencyResponse:
    """A branch of T-periodic orbits continued in omega, one entry per point, in arclength order (omega
    goes back and forth through the folds; the last point is the first one at or beyond hi)."""

    omega: np.ndarray
    r: np.ndarray
    mean: np.ndarray
    x_max: np.ndarray
    x_min: np.ndarray
    stable: np.ndarray  # bool
    kind: list
    multipliers: np.ndarray  # (n, 2) complex
    liouville_error: np.ndarray
    folds: list
    orbits: list = field(repr=False)


class _Branch:
    """Points u = (x0, v0, omega / omega_scale) of G(u) = P(z, omega) - z = 0 in scaled coordinates.

    omega_scale makes a step in omega comparable to a step in the state: the arclength is measured in u.
    """

    def __init__(self, model: PeriodicModel, omega_scale: float, tol: float):
        self.model, self.scale, self.tol = model, omega_scale, tol

    def u_of(self, orbit: Orbit) -> np.ndarray:
        return np.array([orbit.z0[0], orbit.z0[1], orbit.omega / self.scale])

    def tangent(self, orbit: Orbit, previous: np.ndarray | None) -> np.ndarray:
        """branch_tangent oriented along `previous` (or towards increasing omega at the start)."""
        reference = previous if previous is not None else np.array([0.0, 0.0, 1.0])
        return branch_tangent(orbit.monodromy, orbit.d_omega, self.scale, reference)

    def correct(self, u_pred: np.ndarray, t: np.ndarray, max_iter: int = 8) -> tuple[Orbit, int]:
        """arclength_correct on the period map in omega: the orbit and the iteration count."""
        pmap, _, iterations = arclength_correct(lambda z, omega: period_map(self.model, z, omega), u_pred, t,
                                                self.scale, self.tol, max_iter)
        return orbit_from(self.model, pmap), iterations

    def point_at(self, u0: np.ndarray, t0: np.ndarray, h: float) -> tuple[Orbit, np.ndarray]:
        """The branch point on the hyperplane t0 . (u - u0) = h, and its tangent."""
        orbit, _ = self.correct(u0 + h * t0, t0)
        return orbit, self.tangent(orbit, t0)


def _multiplier_near_one(orbit: Orbit) -> float:
    """rho - 1 for the multiplier of real part closest to 1 (real near a fold: 1 and ~exp(-mu T))."""
    rho = orbit.multipliers.real
    return float(rho[np.argmin(np.abs(rho - 1.0))] - 1.0)


def _locate_fold(branch: _Branch, u0: np.ndarray, t0: np.ndarray, h: float) -> Fold:
    """Brent on the arclength in (0, h): zero of the tangent's omega-component, and separately the
    crossing of a Floquet multiplier (from eig M) through +1. The tangent's omega-component is det(M - I)
    up to normalisation (cross product), so the two agree to the corrector tolerance unless eig or the
    orientation is wrong: a consistency check of the fold with Floquet theory."""

    def tangent_omega(hh):
        return branch.point_at(u0, t0, hh)[1][2]

    def multiplier(hh):
        return _multiplier_near_one(branch.point_at(u0, t0, hh)[0])

    xtol = 1e-12 * h
    h_fold = brentq(tangent_omega, 0.0, h, xtol=xtol)
    h_rho = brentq(multiplier, 0.0, h, xtol=xtol)
    orbit = branch.point_at(u0, t0, h_fold)[0]
    rho_orbit = branch.point_at(u0, t0, h_rho)[0]
    return Fold(omega=orbit.omega, omega_multiplier=rho_orbit.omega, r=orbit.r, orbit=orbit)


def continue_branch(model: PeriodicModel, start: Orbit, omega_stop: float, *, omega_scale: float,
                    step: float = 0.01, max_step: float = 0.02, min_step: float = 1e-7, max_points: int = 5000,
                    tol: float = NEWTON_TOL, progress: Callable[[int, Orbit], None] | None = None):
    """Pseudo-arclength continuation from `start` towards omega_stop (through folds), with step control.

    Predictor u + h t (Euler step along the tangent), corrector `_Branch.correct`.
    Step control: a step is accepted if the corrector converges in <= 5 iterations and the tangent turns
    by less than 0.2 rad; h grows by 1.5 after an easy step (<= 2 iterations), halves on rejection.
    A sign change of the tangent's omega-component between two points is a fold: it is located by Brent.
    Stops at the first point beyond omega_stop. Returns (orbits, folds).
    """
    branch = _Branch(model, omega_scale, tol)
    direction = 1.0 if omega_stop >= start.omega else -1.0
    u, t = branch.u_of(start), branch.tangent(start, np.array([0.0, 0.0, direction]))
    orbits, folds, h = [start], [], step
    while direction * (orbits[-1].omega - omega_stop) < 0.0 and len(orbits) < max_points:
        try:
            orbit, iterations = branch.correct(u + h * t, t)
            t_new = branch.tangent(orbit, t)
            accepted = iterations <= 5 and np.dot(t, t_new) >= math.cos(0.2)
        except ShootingError:
            accepted, iterations = False, None
        if not accepted:
            h *= 0.5
            if h < min_step:
                raise ShootingError(f"continuation step below {min_step:g} at omega = {orbits[-1].omega:.10g}")
            continue
        if t_new[2] * t[2] < 0.0:
            folds.append(_locate_fold(branch, u, t, h))
        orbits.append(orbit)
        if progress is not None:
            progress(len(orbits) - 1, orbit)
        u, t = branch.u_of(orbit), t_new
        h = min(max_step, 1.5 * h) if iterations <= 2 else h
    return orbits, folds


def frequency_response(model: PeriodicModel, lo: float, hi: float, *, max_step: float = 0.02,
                       progress: Callable[[int, Orbit], None] | None = None, **options) -> FrequencyResponse:
    """The branch of T-periodic orbits from omega = lo (small amplitude, started from the linear response,
    where the response must be unique) to omega = hi, with stability and folds.

    The omega range [lo, hi] counts as arclength 1 (omega_scale = hi - lo), like an amplitude of 1.
    """
    start = shoot(model, lo, linear_guess(model, lo))
    orbits, folds = continue_branch(model, start, hi, omega_scale=hi - lo, max_step=max_step,
                                    step=min(max_step, 0.01), progress=progress, **options)
    return FrequencyResponse(
        omega=np.array([o.omega for o in orbits]), r=np.array([o.r for o in orbits]),
        mean=np.array([o.mean for o in orbits]), x_max=np.array([o.x_max for o in orbits]),
        x_min=np.array([o.x_min for o in orbits]), stable=np.array([o.stable for o in orbits]),
        kind=[o.kind for o in orbits], multipliers=np.array([o.multipliers for o in orbits]),
        liouville_error=np.array([o.liouville_error for o in orbits]), folds=folds, orbits=orbits)
