"""Averaging, slow flow and local stability of the primary resonance (docs/model.md, Averaging and slow flow; replaces PAPER Eqs 45-72).

Chain: fast AC moments m_j, q_j -> averaged coefficients A_k -> static equilibrium x_e and the shifted
coefficients k_j -> backbone kappa(r) -> slow flow for (A, B) -> steady states at a forcing frequency,
their Jacobian, eigenvalues and type -> fold (jump) frequencies.

The averaged equation is valid for Omega >> sqrt(a1) with Omega away from omega, 2 omega and omega/2,
and weak nonlinearity at the amplitude r (docs/model.md, Averaging and slow flow, (b)): `validity_notes` says where a scene
leaves that range; nothing is refused.

scipy is imported inside the functions that use it: at module level its import would be most of the
plant FMU's first instantiation, which needs none of this module.
"""
from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, replace
from math import comb

import numpy as np
from numpy.polynomial import polynomial as P

from . import forces
from .parameters import ParameterError, Scene

ORDER = 5  # the polynomial model Eq. 7 has degree 5
FOLD_DET_TOLERANCE = 1e-12  # |det J| below this times its scale counts as a fold (det J = 0)


# --- (a) fast/slow split -------------------------------------------------------------------------

def fast_moments(beta: float, gamma: float, Omega: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """m_j = <psi^j> and q_j = <(beta sin Omega t - gamma cos 2 Omega t) psi^j>, j = 0..5 (docs/model.md, Averaging and slow flow).

    psi = -beta sin(Omega t)/Omega^2 + gamma cos(2 Omega t)/(4 Omega^2) is the fast AC response (Eq. 46).
    """
    if beta == 0.0 and gamma == 0.0:
        return (1.0, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0,) * 6
    b2, g2, W = beta * beta, gamma * gamma, Omega * Omega
    m = (1.0, 0.0,
         (16 * b2 + g2) / (32 * W**2),
         -3 * b2 * gamma / (16 * W**3),
         3 * (256 * b2**2 + 64 * b2 * g2 + g2**2) / (2048 * W**4),
         -5 * b2 * gamma * (32 * b2 + 3 * g2) / (512 * W**5))
    q = (0.0,
         -(4 * b2 + g2) / (8 * W),
         3 * b2 * gamma / (8 * W**2),
         -3 * (64 * b2**2 + 40 * b2 * g2 + g2**2) / (512 * W**3),
         b2 * gamma * (128 * b2 + 21 * g2) / (256 * W**4),
         -5 * (1024 * b2**3 + 1344 * b2**2 * g2 + 108 * b2 * g2**2 + g2**3) / (16384 * W**5))
    return m, q


def averaged_coefficients(scene: Scene) -> tuple[float, ...]:
    """A_0..A_5 of the slow equation X'' + mu X' + sum A_k X^k = Delta cos(omega t) (docs/model.md, Averaging and slow flow).

    A_k = sum_{n>=k} C(n,k) a_n m_{n-k} - sum_{n>=k+1} C(n,k) f_n q_{n-k}; a_n of Eq. 8 (a_0 = -gamma),
    f_n of G3 (Eq. 5).
    """
    a = forces.coefficients(scene.alpha, scene.gamma, scene.R)
    f = forces.series_g3(scene.R)
    m, q = fast_moments(scene.beta, scene.gamma, scene.Omega)
    return tuple(sum(comb(n, k) * a[n] * m[n - k] for n in range(k, ORDER + 1))
                 - sum(comb(n, k) * f[n] * q[n - k] for n in range(k + 1, ORDER + 1))
                 for k in range(ORDER + 1))


# --- (b) static equilibrium ----------------------------------------------------------------------

@dataclass(frozen=True)
class Equilibrium:
    """x_e, the averaged A_k, and k_j = sum_{n>=j} C(n,j) A_n x_e^(n-j) (k_0 = 0): y = x - x_e obeys
    y'' + mu y' + k1 y + ... + k5 y^5 = Delta cos(omega t) (docs/model.md, Averaging and slow flow)."""

    x_e: float
    A: tuple[float, ...]
    k: tuple[float, ...]

    @property
    def omega_e(self) -> float:
        return math.sqrt(self.k[1])


def shifted(A, x_e: float) -> tuple[float, ...]:
    """k_j = sum_{n>=j} C(n, j) A_n x_e^(n-j): the Taylor coefficients of sum A_n x^n at x_e."""
    return tuple(float(sum(comb(n, j) * A[n] * x_e ** (n - j) for n in range(j, len(A)))) for j in range(len(A)))


EPS = float(np.finfo(float).eps)


def _horner(x: float, c) -> float:
    """numpy.polynomial's polyval(x, c) for a float x, operation for operation (c ascending): its bits, without
    numpy's per-call cost (fidelity 3's set-up)."""
    value = c[-1] + x * 0
    for coefficient in reversed(c[:-1]):
        value = coefficient + value * x
    return value


def equilibrium(scene: Scene) -> Equilibrium:
    """Root x_e of sum A_k x^k near -Gamma/A_1, by Newton's method (docs/model.md, Averaging and slow flow)."""
    A = averaged_coefficients(scene)
    dA = [j * A[j] for j in range(1, len(A))]  # numpy.polynomial's polyder(A), term for term
    x = -A[0] / A[1]
    for _ in range(50):
        value, slope = _horner(x, A), _horner(x, dA)
        step = value / slope if slope else float(np.float64(value) / slope)  # numpy's inf or nan at a zero slope
        x -= step
        if abs(step) <= 4 * EPS * max(1.0, abs(x)):
            break
    x = float(x)
    k = shifted(A, x)
    return Equilibrium(x_e=x, A=A, k=(0.0,) + k[1:])


# --- (c) backbone and slow flow ------------------------------------------------------------------

BACKBONES = ("lindstedt", "first-order")


@dataclass(frozen=True)
class Backbone:
    """kappa(r) = kappa2 r^2 + kappa4 r^4: amplitude-dependent frequency shift (docs/model.md, Averaging and slow flow)."""

    kappa2: float
    kappa4: float
    kind: str

    def kappa(self, r):
        r2 = r * r
        return r2 * (self.kappa2 + self.kappa4 * r2)

    def slope(self, r):
        """kappa'(r)."""
        return r * (2.0 * self.kappa2 + 4.0 * self.kappa4 * r * r)


def backbone(eq: Equilibrium, kind: str = "lindstedt") -> Backbone:
    """Strict first order: 3k3/(8 w_e), 5k5/(16 w_e). Lindstedt (k2 not small): docs/model.md, Averaging and slow flow."""
    _, k1, k2, k3, k4, k5 = eq.k
    if kind == "first-order":
        w = math.sqrt(k1)
        return Backbone(3 * k3 / (8 * w), 5 * k5 / (16 * w), kind)
    if kind == "lindstedt":
        kappa2 = (9 * k1 * k3 - 10 * k2**2) / (24 * k1**1.5)
        kappa4 = (2160 * k1**3 * k5 - 6048 * k1**2 * k2 * k4 - 405 * k1**2 * k3**2 + 6228 * k1 * k2**2 * k3
                  - 1940 * k2**4) / (6912 * k1**3.5)
        return Backbone(kappa2, kappa4, kind)
    raise ValueError(f"backbone kind {kind!r}: must be one of {BACKBONES}")


@dataclass(frozen=True)
class SlowFlow:
    """A' = -mu/2 A - nu(r) B, B' = -mu/2 B + nu(r) A + Delta/(2 omega) (docs/model.md, Averaging and slow flow), tau-time.

    y = x - x_e ~ A cos(omega t) + B sin(omega t); nu(r) = detuning - kappa(r), with the detuning
    (omega^2 - k1)/(2 omega) ~ omega - omega_e and the drive Delta/(2 omega).
    """

    mu: float
    omega: float
    detuning: float
    drive: float
    backbone: Backbone

    def nu(self, r):
        return self.detuning - self.backbone.kappa(r)

    def rhs(self, A, B):
        """(A', B'); A and B may be floats or numpy arrays."""
        nu = self.nu((A * A + B * B) ** 0.5)
        half_mu = 0.5 * self.mu
        return -half_mu * A - nu * B, -half_mu * B + nu * A + self.drive

    def jacobian(self, A: float, B: float) -> np.ndarray:
        """docs/model.md, Averaging and slow flow."""
        r = math.hypot(A, B)
        nu, half_mu = self.nu(r), 0.5 * self.mu
        g = self.backbone.slope(r) / r if r > 0.0 else 0.0  # kappa'(r)/r, finite as r -> 0
        return np.array([[-half_mu + g * A * B, -nu + g * B * B],
                         [nu - g * A * A, -half_mu - g * A * B]])


@dataclass(frozen=True)
class Averaged:
    """The averaged model of a scene (docs/model.md, Averaging and slow flow): its equilibrium, backbone, and slow flow at any omega."""

    scene: Scene
    eq: Equilibrium
    backbone: Backbone

    @property
    def omega_e(self) -> float:
        return self.eq.omega_e

    @property
    def r_max(self) -> float:
        """Largest amplitude before x = x_e - r leaves the contact (1 + 2x/3 = 0): the series' edge."""
        return 1.5 + self.eq.x_e

    def flow(self, omega: float | None = None) -> SlowFlow:
        s = self.scene
        omega = s.omega if omega is None else omega
        return SlowFlow(s.mu, omega, (omega * omega - self.eq.k[1]) / (2.0 * omega), s.Delta / (2.0 * omega),
                        self.backbone)


def averaged(scene: Scene, kind: str = "lindstedt") -> Averaged:
    eq = equilibrium(scene)
    return Averaged(scene, eq, backbone(eq, kind))


def equilibrium_problem(scene: Scene) -> str | None:
    """Why the averaged model of the scene has no stable static equilibrium to average about, or None.

    The averaging expands about x_e, a root of sum A_k x^k with stiffness k1 = d/dx sum A_k x^k > 0 there (the
    backbone divides by k1^(3/2) and omega_e = sqrt(k1)). A strong electrostatic pull (alpha, gamma or the AC
    moments of beta) can leave no such root inside the contact: static pull-in, which the slow flow cannot describe
    (alpha = 3 used to end in TypeError('must be real number, not complex'), naming nothing)."""
    return _examined(scene)[0]


def _examined(scene: Scene) -> tuple[str | None, Averaged | None]:
    """(equilibrium_problem's answer, the averaged model when there is none): the equilibrium found once."""
    try:
        eq = equilibrium(scene)
        kappa = backbone(eq)
        value = float(P.polyval(eq.x_e, eq.A))
        scale = float(np.sum(np.abs(eq.A) * abs(eq.x_e) ** np.arange(len(eq.A))))
    except (ArithmeticError, ValueError, TypeError) as error:
        return f"no equilibrium found ({error})", None
    if not (math.isfinite(eq.x_e) and math.isfinite(eq.k[1]) and eq.k[1] > 0.0):
        return f"stiffness k1 = {eq.k[1]:.4g} at x_e = {eq.x_e:.4g} (needs k1 > 0)", None
    if not abs(value) <= 1e-9 * scale:  # Newton did not converge: no root near -A0/A1
        return f"Newton's method found no root of the averaged force (residual {value:.3g} at x = {eq.x_e:.4g})", None
    if not all(isinstance(k, float) and math.isfinite(k) for k in (kappa.kappa2, kappa.kappa4)):
        return "the backbone's coefficients are not finite", None
    if not (eq.x_e > -1.5 and abs(eq.x_e) < 1.5 * scene.R):
        return f"x_e = {eq.x_e:.4g} lies outside the contact (x > -3/2) or beyond an electrode (|x| < 3R/2)", None
    return None, Averaged(scene, eq, kappa)  # averaged(scene): the Lindstedt backbone of this equilibrium


def checked_averaged(scene: Scene) -> Averaged:
    """averaged(scene), or ParameterError when it has no stable equilibrium (equilibrium_problem), naming the
    actuation parameter (alpha, gamma or beta) whose removal alone gives the scene one (alpha if none does)."""
    problem, model = _examined(scene)
    if problem is None:
        return model
    name = next((name for name in ("alpha", "gamma", "beta") if getattr(scene, name) != 0.0
                 and equilibrium_problem(replace(scene, **{name: 0.0})) is None), "alpha")
    raise ParameterError(name, getattr(scene, name), f"fidelity 3 averages about a stable static equilibrium of the "
                         f"averaged model and this scene has none: {problem} (the electrostatic pull overcomes the "
                         "contact: static pull-in); use fidelity 0")


# --- (d), (e) steady states and their stability --------------------------------------------------

@dataclass(frozen=True)
class SteadyState:
    """An equilibrium (A, B) of the slow flow = a T-periodic vibration of amplitude r (docs/model.md, Averaging and slow flow-(f))."""

    A: float
    B: float
    r: float
    nu: float
    det: float  # det J = mu^2/4 + nu (nu - r kappa'(r))
    eigenvalues: tuple[complex, complex]  # lambda = -mu/2 +- sqrt(nu (r kappa' - nu)), tau-time
    kind: str

    def multipliers(self, omega: float) -> tuple[complex, complex]:
        """exp(lambda T), T = 2 pi/omega: the Floquet multipliers to O(epsilon) (docs/model.md, Averaging and slow flow)."""
        T = 2.0 * math.pi / omega
        return tuple(cmath.exp(lam * T) for lam in self.eigenvalues)

    @property
    def stable(self) -> bool:
        return self.kind.startswith("stable")


def classify(mu: float, det: float, discriminant: float, scale: float) -> str:
    """Type of an equilibrium from tr J = -mu and det J (docs/model.md, Averaging and slow flow, §5.1 corrected)."""
    if abs(det) <= FOLD_DET_TOLERANCE * scale:
        return "fold"
    if det < 0.0:
        return "saddle"
    shape = "node" if discriminant >= 0.0 else "focus"
    if mu > 0.0:
        return f"stable {shape}"
    return "center" if mu == 0.0 else f"unstable {shape}"


def steady_state(flow: SlowFlow, r: float) -> SteadyState:
    """The equilibrium of amplitude r (a root of the frequency-response equation) with its stability."""
    nu, mu, d = flow.nu(r), flow.mu, flow.drive
    denominator = mu * mu + 4 * nu * nu
    A, B = -4 * nu * d / denominator, 2 * mu * d / denominator  # docs/model.md, Averaging and slow flow
    r_kappa = r * flow.backbone.slope(r)
    det = mu * mu / 4 + nu * (nu - r_kappa)
    discriminant = nu * (r_kappa - nu)  # (lambda + mu/2)^2
    root = cmath.sqrt(discriminant)
    scale = mu * mu / 4 + nu * nu + abs(nu * r_kappa)
    return SteadyState(float(A), float(B), float(math.hypot(A, B)), float(nu), float(det),
                       (-mu / 2 + root, -mu / 2 - root), classify(mu, det, discriminant, scale))


def response_polynomial(flow: SlowFlow) -> np.ndarray:
    """Coefficients (ascending in u = r^2) of u (mu^2/4 + nu(u)^2) - drive^2 (docs/model.md, Averaging and slow flow)."""
    nu = np.array([flow.detuning, -flow.backbone.kappa2, -flow.backbone.kappa4])
    inner = P.polyadd([flow.mu**2 / 4], P.polymul(nu, nu))
    return P.polysub(P.polymul([0.0, 1.0], inner), [flow.drive**2])


def steady_states(flow: SlowFlow, r_max: float = math.inf) -> list[SteadyState]:
    """Every steady state of the flow with 0 < r < r_max, by increasing r.

    The real positive roots u of the response polynomial are polished by Newton's method and checked
    against the residual; r_max drops roots outside the model's range (beyond contact loss).
    """
    if flow.drive == 0.0:
        return [steady_state(flow, 0.0)]
    poly = np.trim_zeros(response_polynomial(flow), "b")
    derivative = P.polyder(poly)
    radii = []
    for root in P.polyroots(poly):
        u = root.real
        if abs(root.imag) > 1e-6 * max(abs(u), flow.drive**2) or u <= 0.0:
            continue
        for _ in range(8):
            slope = P.polyval(u, derivative)
            if slope == 0.0:
                break
            u -= P.polyval(u, poly) / slope
        scale = np.sum(np.abs(poly) * np.abs(u) ** np.arange(len(poly)))
        if u > 0.0 and abs(P.polyval(u, poly)) <= 1e-9 * scale and math.sqrt(u) < r_max:
            radii.append(math.sqrt(u))
    return [steady_state(flow, r) for r in sorted(set(radii))]


# --- folds -----------------------------------------------------------------------------------------

def frequency_on_curve(model, r: float, side: int) -> float | None:
    """omega at which amplitude r is a steady state, left (side = -1, nu < 0) or right (+1) of the
    backbone: detuning(omega) = kappa(r) + side sqrt(drive(omega)^2/r^2 - mu^2/4) (docs/model.md, Averaging and slow flow).

    model: anything with omega_e and flow(omega) (the corrected `Averaged` or the printed one).
    """
    from scipy.optimize import brentq  # lazily, see the module docstring

    def mismatch(omega):
        flow = model.flow(omega)
        radicand = (flow.drive / r) ** 2 - flow.mu**2 / 4
        return flow.nu(r) - side * math.sqrt(max(radicand, 0.0))

    centre = model.omega_e + model.backbone.kappa(r)  # detuning ~ omega - omega_e
    width = 2.0 * (model.flow(centre).drive / r + model.scene.mu) + 1e-12
    lo, hi = (centre - width, centre) if side < 0 else (centre, centre + width)
    for _ in range(20):  # widen until the root is bracketed
        if mismatch(lo) * mismatch(hi) <= 0.0:
            return brentq(mismatch, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps)
        lo, hi = (lo - width, hi) if side < 0 else (lo, hi + width)
        width *= 2.0
        if lo <= 0.0:
            return None
    return None


@dataclass(frozen=True)
class Fold:
    omega: float
    r: float
    side: int  # -1: left of the backbone, +1: right


def folds(model, samples: int = 2000) -> list[Fold]:
    """Saddle-node points (det J = 0, d omega/dr = 0) of the frequency-response curve (docs/model.md, Averaging and slow flow).

    The curve is traced by amplitude r on both sides of the backbone up to the peak (or the model's
    r_max); det J changes sign at a fold, which is located there by Brent's method.
    """
    from scipy.optimize import brentq  # lazily, see the module docstring

    s = model.scene
    if s.Delta == 0.0 or s.mu <= 0.0:
        return []
    r_peak = min(s.Delta / (s.mu * model.omega_e), model.r_max)  # drive^2/r^2 >= mu^2/4
    found = []
    radii = np.geomspace(r_peak * 1e-4, r_peak * (1 - 1e-9), samples)
    for side in (-1, 1):
        def det_on_curve(r):
            omega = frequency_on_curve(model, r, side)
            return math.nan if omega is None else steady_state(model.flow(omega), r).det

        values = [det_on_curve(r) for r in radii]
        for r0, r1, d0, d1 in zip(radii, radii[1:], values, values[1:]):
            if d0 * d1 < 0.0:
                r = brentq(det_on_curve, r0, r1, xtol=1e-14)
                found.append(Fold(frequency_on_curve(model, r, side), r, side))
    return sorted(found, key=lambda fold: fold.omega)


def validity_notes(model: Averaged) -> list[str]:
    """Where the scene leaves the averaging's range of validity (docs/model.md, Averaging and slow flow, (b)); empty if inside."""
    s, w = model.scene, model.omega_e
    notes = []
    if s.beta or s.gamma:
        if s.Omega < 2.0 * w:
            notes.append(f"Omega = {s.Omega:g} is not >> sqrt(A1) = {w:.4g}")
        for label, value in (("omega", s.omega), ("2 omega", 2 * s.omega), ("omega/2", s.omega / 2)):
            if abs(s.Omega - value) < 0.05 * value:
                notes.append(f"Omega = {s.Omega:g} is near {label} = {value:.4g}")
    if abs(s.omega - w) > 0.2 * w:
        notes.append(f"omega = {s.omega:.4g} is far from resonance omega_e = {w:.4g}: averaging assumes "
                     "|omega - omega_e| small")
    return notes


# The averaging's own domain (fidelity 3; issue 25). Thresholds from a grid against fidelity 0 on [0, 50] (the paper
# scene with one parameter changed; relative error = max|x3 - x0| / max|x0|):
# - detuning: the slow flow rotates the free vibration at omega - nu = (omega^2 + k1)/(2 omega) instead of omega_e,
#   wrong by ~(omega - omega_e)^2/(2 omega), so its phase error grows with |omega - omega_e|/omega_e =: d. Measured:
#   d = 0.1 -> 4.6 %, 0.2 -> 14 %, 1.0 -> 117 %, 2.0 -> 157 %. Warned above DETUNING_WARN, refused above
#   DETUNING_REFUSE (about 20 % expected there; at d = 0.5 the start's slow state no longer converges).
# - parametric pumping: the AC terms modulate the stiffness, beta sin(Omega t) g31 x and gamma cos(2 Omega t) g31 x
#   (g31 = dG3/dx at 0). The averaged model keeps their means only; near Omega = 2 omega_e (beta) or Omega = omega_e
#   (gamma) the modulation q pumps the resonance: Mathieu's first tongue grows at
#   lambda = sqrt((q/(4 omega_e))^2 - (nu/2 - omega_e)^2) - mu/2 (Nayfeh & Mook, Nonlinear Oscillations, §5.4).
#   lambda > 0: fidelity 0 grows to pull-in (beta = 0.3: lambda = +0.048, pull-in at tau = 28.6; beta = 1: +0.20,
#   tau = 3.1) where fidelity 3 stays bounded: refused. Pumping that eats a share of the damping,
#   (lambda + mu/2)/(mu/2) > PUMPING_WARN, is warned (beta = 0.01: share 0.07, 6.7 % error; beta = 0.03: 0.2, 17 %;
#   beta = 0.1: 0.67, 42 %; the paper scene, beta = 1e-4: 0).
# - damping: first-order averaging needs mu/(2 omega_e) small (mu = 1: 0.5, 14 %): warned above DAMPING_WARN.
DETUNING_WARN = 0.05
DETUNING_REFUSE = 0.3
PUMPING_WARN = 0.05
DAMPING_WARN = 0.25


def parametric_growth(scene: Scene, omega_e: float) -> list[tuple[str, float, float]]:
    """(parameter, Mathieu growth rate lambda, pumping share (lambda + mu/2)/(mu/2)) of each AC term that is on
    (comment at DETUNING_WARN). The share is inf without damping."""
    g31 = forces.series_g3(scene.R)[1]
    rows = []
    for name, amplitude, nu in (("beta", scene.beta, scene.Omega), ("gamma", scene.gamma, 2.0 * scene.Omega)):
        if amplitude == 0.0:
            continue
        q = abs(amplitude * g31)
        radicand = (q / (4.0 * omega_e)) ** 2 - (0.5 * nu - omega_e) ** 2
        pump = math.sqrt(radicand) if radicand > 0.0 else 0.0
        growth = pump - 0.5 * scene.mu
        rows.append((name, growth, pump / (0.5 * scene.mu) if scene.mu > 0.0 else math.inf if pump else 0.0))
    return rows


def validity_estimates(model: Averaged) -> tuple[ParameterError | None, list[str]]:
    """(the refusal, else None; the warnings) of the averaging's domain (comment at DETUNING_WARN), each naming the
    parameter, its value, the estimate and the rule, and the rung to use instead."""
    s, w = model.scene, model.omega_e
    warnings = []
    detuning = abs(s.omega - w) / w
    # the free vibration turns at omega - nu whether or not the load drives it
    if detuning > DETUNING_REFUSE:
        return ParameterError("omega", s.omega, f"fidelity 3's detuning |omega - omega_e|/omega_e = {detuning:.3g} "
                              f"exceeds {DETUNING_REFUSE:g} (omega_e = {w:.6g}): the averaged slow flow is built "
                              "near resonance and its free vibration turns at the wrong frequency here (error "
                              "~ the amplitude); use fidelity 0"), []
    if detuning > DETUNING_WARN:
        warnings.append(f"omega = {s.omega:g}: fidelity 3's detuning |omega - omega_e|/omega_e = {detuning:.3g} "
                        f"exceeds {DETUNING_WARN:g} (omega_e = {w:.6g}): expect an error of x of the order of "
                        f"{0.7 * detuning:.2g} of its amplitude; use fidelity 0 for accuracy")
    for name, growth, share in parametric_growth(s, w):
        value = getattr(s, name)
        if growth > 0.0:
            return ParameterError(name, value, f"fidelity 3's averaged model leaves out the parametric pumping of "
                                  f"the AC term {name} at Omega = {s.Omega:g} near omega_e = {w:.6g}: the Mathieu "
                                  f"growth rate {growth:.3g} > 0 says the vibration grows (towards pull-in) where the "
                                  "averaged one stays bounded; use fidelity 0"), []
        if share > PUMPING_WARN:
            warnings.append(f"{name} = {value:g}: fidelity 3's averaged model leaves out the parametric pumping of "
                            f"its AC term, which offsets {share:.2g} of the damping here (above {PUMPING_WARN:g}; "
                            "Mathieu's first tongue): expect errors of x of that share of its amplitude; use fidelity "
                            "0 for accuracy")
    if s.mu / (2.0 * w) > DAMPING_WARN:
        warnings.append(f"mu = {s.mu:g}: fidelity 3's small parameter mu/(2 omega_e) = {s.mu / (2.0 * w):.3g} exceeds "
                        f"{DAMPING_WARN:g}: first-order averaging errs by about that share; use fidelity 0 for "
                        "accuracy")
    return None, warnings


def ghost_margin(model, fold: Fold, wait: float) -> float:
    """How far past a fold a sweep that waits `wait` (tau) can still sit on the vanished branch.

    Past a saddle-node the flow creeps through the fold's ghost: on the centre direction the slow flow is
    s' = a (omega - omega_f) + b s^2, and the passage takes pi / sqrt(|a b d omega|) (Strogatz, Nonlinear
    Dynamics and Chaos, §4.3). This returns the d omega at which that equals `wait`. a and b come from the
    slow flow at the fold: left and right null vectors w, v of J; a = w.dF/domega / w.v,
    b = w.D2F[v, v] / (2 w.v), by central differences.
    """
    flow = model.flow(fold.omega)
    state = steady_state(flow, fold.r)
    Z = np.array([state.A, state.B])
    J = flow.jacobian(*Z)
    values, right = np.linalg.eig(J)
    v = right[:, np.argmin(np.abs(values))].real
    values, left = np.linalg.eig(J.T)
    w = left[:, np.argmin(np.abs(values))].real

    def F(point, omega):
        return np.array(model.flow(omega).rhs(*point))

    d_omega, d_state = 1e-7 * fold.omega, 1e-4 * fold.r
    a = w @ (F(Z, fold.omega + d_omega) - F(Z, fold.omega - d_omega)) / (2 * d_omega) / (w @ v)
    b = 0.5 * w @ (F(Z + d_state * v, fold.omega) - 2 * F(Z, fold.omega) + F(Z - d_state * v, fold.omega)) \
        / d_state**2 / (w @ v)
    return float(math.pi**2 / (abs(a * b) * wait**2))
