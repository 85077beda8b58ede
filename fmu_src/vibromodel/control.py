"""Adaptive Lyapunov tracking controller (docs/model.md, Adaptive controller, replaces PAPER Eqs 73-85).

Plant (Eq. 73 = Eq. 7 with U): x1' = x2, x2' = phi^T theta + U with
theta = (mu, a1, ..., a5, Delta, beta, gamma) and the regressor
phi = (-x2, -x1, -x1^2, ..., -x1^5, cos w t, G3(x1) sin W t, 1 - G3(x1) cos 2W t).
Errors (Eq. 74): e1 = x1 - x~, e2 = x2 - x~' + c e1, c = sqrt(lambda1/lambda2) (Eq. 84).
Lyapunov function (Eq. 76, with the gamma term of corrected Eq. (75)-(76)):
V = (lambda1 e1^2 + lambda2 e2^2 + theta~^T Lambda theta~)/2, theta~ = theta^ - theta, Lambda = diag(lambda3..11).

Laws:
- paper-corrected: U = -phi^T theta^ + x~'' - c e2, theta^' = lambda2 Lambda^-1 phi e2 => V' = -lambda1^(3/2) lambda2^(-1/2) e1^2 (Eq. 85).
- damped (the corrected "better variant"): U as above - k e2 => V' = -lambda1 c e1^2 - lambda2 k e2^2. (the corrected extra
  term (c^2 - lambda1/lambda2) e1 vanishes here because c is always Eq. 84's.)
- paper-literal: Eq. 78 and 81 as printed: U uses the true Delta instead of its estimate, and the update law
  of Delta^ reads -(lambda2/lambda9) e2 cos tau, that of gamma^ has cos W tau. V rises (docs/model.md, Adaptive controller table).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from . import forces
from .models import R_OUT_OF_RANGE
from .parameters import ParameterError, Scene, validate
from .snapshot import plain_attributes, restore_attributes

THETA_NAMES = ("mu", "a1", "a2", "a3", "a4", "a5", "Delta", "beta", "gamma")
ESTIMATE_NAMES = tuple(f"{name}_hat" for name in THETA_NAMES)
GAIN_NAMES = tuple(f"lambda{i}" for i in range(1, 12))
# docs/model.md, Adaptive controller simulation: lambda1 = 4, lambda2 = 1, lambda3..11 = 1 (c = 2), wrong initial estimates.
DEFAULT_LAMBDAS = (4.0,) + (1.0,) * 10
ERRATA_INITIAL_ESTIMATES = (0.05, 0.9, 0.1, 0.0, 0.0, 0.0, 0.001, 0.0, 0.001)
DELTA, GAMMA = THETA_NAMES.index("Delta"), THETA_NAMES.index("gamma")


class Law(IntEnum):
    PAPER_CORRECTED = 0
    DAMPED = 1
    PAPER_LITERAL = 2

    @property
    def label(self) -> str:
        return self.name.lower().replace("_", "-")

    @classmethod
    def from_label(cls, label: str) -> "Law":
        for law in cls:
            if law.label == label:
                return law
        raise ParameterError("law", label, f"known laws: {', '.join(law.label for law in cls)}")


def validate_law(law) -> None:
    if law not in set(Law):
        raise ParameterError("law", law, f"must be one of {[int(law) for law in Law]}")


def _positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0.0):
        raise ParameterError(name, value, "gain must be a finite number > 0")


@dataclass(frozen=True)
class Gains:
    """lambda1..lambda11 of Eq. 76 and the damped law's e2 gain k."""

    lambdas: tuple[float, ...] = DEFAULT_LAMBDAS
    k_damping: float = 1.0

    def validate(self) -> None:
        if len(self.lambdas) != len(GAIN_NAMES):
            raise ParameterError("lambdas", self.lambdas, f"need {len(GAIN_NAMES)} gains lambda1..lambda11")
        for name, value in zip(GAIN_NAMES, self.lambdas):
            _positive(name, value)
        _positive("k_damping", self.k_damping)

    @property
    def c(self) -> float:
        """c = sqrt(lambda1/lambda2) (Eq. 84; the paper's phi in Eq. 74)."""
        return math.sqrt(self.lambdas[0] / self.lambdas[1])


def validate_estimates(values) -> None:
    for name, value in zip(ESTIMATE_NAMES, values):
        if not math.isfinite(value):
            raise ParameterError(f"{name}_start", value, "initial estimate must be a finite number")


def true_theta(scene: Scene) -> np.ndarray:
    """theta = (mu, a1..a5, Delta, beta, gamma) of Eq. 73 with the corrected a_i of Eq. 8."""
    a = forces.coefficients(scene.alpha, scene.gamma, scene.R)
    return np.array([scene.mu, *a[1:], scene.Delta, scene.beta, scene.gamma])


class Regressor:
    """phi(x1, x2, t) of Eq. 73 (docs/model.md, Adaptive controller). `delta_frequency`, `delta_sign`, `gamma_frequency` select the
    time functions of the Delta and gamma components: (omega, +1, 2 Omega) correct, (1, -1, Omega) Eq. 81 as printed.
    Each component is (factor of x1, x2) * (1, cos or sin of a frequency): `integral` integrates it exactly in
    time with x1, x2 held."""

    def __init__(self, scene: Scene, delta_frequency: float | None = None, delta_sign: float = 1.0,
                 gamma_frequency: float | None = None):
        self.g3 = forces.series_g3(scene.R)
        self.w_delta = scene.omega if delta_frequency is None else delta_frequency
        self.delta_sign = delta_sign
        self.w_beta = scene.Omega
        self.w_gamma = 2.0 * scene.Omega if gamma_frequency is None else gamma_frequency

    def __call__(self, t: float, x1: float, x2: float) -> np.ndarray:
        G3 = forces.horner(self.g3, x1)
        x1_2 = x1 * x1
        return np.array([-x2, -x1, -x1_2, -x1_2 * x1, -x1_2 * x1_2, -x1_2 * x1_2 * x1,
                         self.delta_sign * math.cos(self.w_delta * t), G3 * math.sin(self.w_beta * t),
                         1.0 - G3 * math.cos(self.w_gamma * t)])

    def integral(self, t: float, h: float, x1: float, x2: float) -> np.ndarray:
        """int_t^(t+h) phi(x1, x2, s) ds with x1, x2 held (zero-order hold), in closed form."""
        G3 = forces.horner(self.g3, x1)
        x1_2 = x1 * x1
        return np.array([-x2 * h, -x1 * h, -x1_2 * h, -x1_2 * x1 * h, -x1_2 * x1_2 * h, -x1_2 * x1_2 * x1 * h,
                         self.delta_sign * _trig_integral(math.cos, self.w_delta, t, h),
                         G3 * _trig_integral(math.sin, self.w_beta, t, h),
                         h - G3 * _trig_integral(math.cos, self.w_gamma, t, h)])


def _dot(a, b) -> float:
    """sum a_i b_i left to right from 0.0: an explicit order, so that the compiled controller (fmu_src/core/
    controller.c) gives the same bits (numpy's @ may use BLAS, and Python 3.12's sum() compensates)."""
    total = 0.0
    for p, q in zip(a, b):
        total += float(p) * float(q)
    return total


def _trig_integral(trig, nu: float, t: float, h: float) -> float:
    """int_t^(t+h) trig(nu s) ds = h trig(nu (t + h/2)) sinc(nu h/2) for trig = cos, sin (exact; fine at nu -> 0)."""
    y = 0.5 * nu * h
    sinc = math.sin(y) / y if y != 0.0 else 1.0
    return h * trig(nu * (t + 0.5 * h)) * sinc


class Controller:
    """One law: U, theta^', V, V' (chain rule) and the V' the law promises."""

    def __init__(self, scene: Scene, gains: Gains, law: Law):
        gains.validate()
        self.law, self.gains = Law(law), gains
        self.c = gains.c
        lambdas = np.array(gains.lambdas)
        self.l1, self.l2, self.Lambda = lambdas[0], lambdas[1], lambdas[2:]
        self.adaptation = self.l2 / self.Lambda  # lambda2 Lambda^-1
        self.promised_e1 = float(-self.l1**1.5 / math.sqrt(self.l2))  # Eq. 85: V' = promised_e1 e1^2
        literal = self.law is Law.PAPER_LITERAL
        try:
            self.theta = true_theta(scene)
            self.phi = Regressor(scene)
            # Eq. 81 as printed: -cos tau for Delta^, cos Omega tau for gamma^
            self.phi_update = Regressor(scene, 1.0, -1.0, scene.Omega) if literal else self.phi
        except ArithmeticError:
            raise ParameterError("R", scene.R, R_OUT_OF_RANGE) from None
        self.true_delta = scene.Delta if literal else None

    def errors(self, x: float, v: float, ref) -> tuple[float, float]:
        """e1 = x1 - x~, e2 = x2 - x~' + c e1 (Eq. 74); ref = (x~, x~', x~'')."""
        e1 = x - ref[0]
        return e1, v - ref[1] + self.c * e1

    def control(self, t: float, x: float, v: float, ref, theta_hat) -> float:
        """U = -phi^T theta^ + x~'' - c e2 (docs/model.md, Adaptive controller; Eq. 78 corrected), - k e2 for the damped law;
        Eq. 78 as printed (paper-literal) has the true Delta in place of Delta^."""
        _, e2 = self.errors(x, v, ref)
        phi = self.phi(t, x, v)
        if self.true_delta is not None:
            theta_hat = np.array(theta_hat)
            theta_hat[DELTA] = self.true_delta
        U = -_dot(phi, theta_hat) + ref[2] - self.c * e2
        if self.law is Law.DAMPED:
            U -= self.gains.k_damping * e2
        return U

    def rates(self, t: float, x: float, v: float, ref) -> np.ndarray:
        """theta^' = lambda2 Lambda^-1 phi e2 (docs/model.md, Adaptive controller update laws; Eq. 81 as printed for paper-literal)."""
        _, e2 = self.errors(x, v, ref)
        return self.adaptation * self.phi_update(t, x, v) * e2

    def increment(self, t: float, h: float, x: float, v: float, ref) -> np.ndarray:
        """theta^(t + h) - theta^(t) with x, v and ref held over [t, t + h]: the update law's right-hand side
        then depends on time only, and is integrated exactly (Regressor.integral)."""
        _, e2 = self.errors(x, v, ref)
        return self.adaptation * self.phi_update.integral(t, h, x, v) * e2

    def lyapunov(self, e1: float, e2: float, theta_hat) -> float:
        """V of Eq. 76."""
        tilde = np.asarray(theta_hat) - self.theta
        return 0.5 * (self.l1 * e1 * e1 + self.l2 * e2 * e2 + _dot(self.Lambda, tilde * tilde))

    def lyapunov_rate(self, x: float, v: float, accel: float, ref, theta_hat, theta_hat_rate) -> float:
        """dV/dt by the chain rule along the trajectory: accel = x2' of the plant (with U),
        e1' = x2 - x~', e2' = x2' - x~'' + c e1'."""
        e1, e2 = self.errors(x, v, ref)
        de1 = v - ref[1]
        de2 = accel - ref[2] + self.c * de1
        tilde = np.asarray(theta_hat) - self.theta
        return self.l1 * e1 * de1 + self.l2 * e2 * de2 + _dot(self.Lambda, tilde * theta_hat_rate)

    def promised_rate(self, e1: float, e2: float) -> float:
        """The V' the law promises: Eq. 85 -lambda1^(3/2) lambda2^(-1/2) e1^2 (paper-corrected and, as claimed by
        the paper, paper-literal); -lambda1 c e1^2 - lambda2 k e2^2 for the damped law (docs/model.md, Adaptive controller)."""
        if self.law is Law.DAMPED:
            return -self.l1 * self.c * e1 * e1 - self.l2 * self.gains.k_damping * e2 * e2
        return self.promised_e1 * e1 * e1


class HeldInputEstimator:
    """The estimates theta^ of one controller advanced over communication steps with the controller's inputs
    (x, v, reference) held over each: the controller FMU's model. Its snapshot is theta^ and the time; the
    controller itself is rebuilt from the arguments. Raises ParameterError for bad arguments."""

    REBUILT = ("controller",)

    def __init__(self, scene: Scene, gains: Gains, law: int, estimates: tuple[float, ...], t0: float = 0.0):
        validate(scene)
        validate_law(law)
        validate_estimates(estimates)
        self.controller = Controller(scene, gains, law)
        self.theta_hat = np.array(estimates, dtype=float)
        self.t = t0

    def advance(self, t: float, h: float, x: float, v: float, ref) -> None:
        """theta^(t + h) = theta^(t) + the exact integral of the update law with x, v, ref held."""
        self.theta_hat = self.theta_hat + self.controller.increment(t, h, x, v, ref)
        self.t = t + h

    def snapshot(self) -> dict:
        return plain_attributes(self, self.REBUILT)

    def restore(self, snapshot: dict) -> None:
        restore_attributes(self, snapshot, self.REBUILT)
