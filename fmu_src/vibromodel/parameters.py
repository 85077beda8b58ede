"""Scene (dimensionless parameters + initial state), validation, physical units (ERRATA §3.1).

Every formula here is the corrected one of ERRATA.md, not the printed one of PAPER.md.
"""
from __future__ import annotations

import math
import sys
from dataclasses import asdict, dataclass, fields, replace

# Paper example (PAPER §4, ERRATA §4): delta*epsilon is the detuning of omega from sqrt(a1).
PAPER_DETUNING = 0.02 * 0.01

# Forcing frequencies beyond this (times the natural frequency) are refused.
MAX_FREQUENCY = 1e4

# Pull-in: the run stops when an electrode gap 1 -/+ 2x/(3R) falls below this.
PULL_IN_GAP = 1e-3


def paper_omega(alpha: float, gamma: float, R: float) -> float:
    """Eq. 9: omega = sqrt(a1) + delta*epsilon, a1 of Eq. 8."""
    a1 = 1.0 - 8.0 * alpha / (3.0 * R) - 4.0 * gamma / (3.0 * R)
    return math.sqrt(a1) + PAPER_DETUNING


# The paper example's forcing frequency, 0.9987322562...
PAPER_OMEGA = paper_omega(alpha=0.001, gamma=0.0002, R=1.0)


class ParameterError(ValueError):
    """A parameter that makes no physical or numerical sense; names the parameter and value."""

    def __init__(self, name: str, value, reason: str):
        self.name, self.value, self.reason = name, value, reason
        super().__init__(f"parameter {name} = {value!r}: {reason}")


@dataclass(frozen=True)
class Scene:
    """Dimensionless parameters of Eq. 3 and the initial state x(0), x'(0)."""

    mu: float = 0.1
    Delta: float = 0.0007
    omega: float = PAPER_OMEGA
    Omega: float = 2.0
    alpha: float = 0.001
    beta: float = 0.0001
    gamma: float = 0.0002
    R: float = 1.0
    x_start: float = 0.04
    v_start: float = 0.0

    def with_values(self, **values) -> "Scene":
        unknown = set(values) - set(scene_names())
        if unknown:
            name = sorted(unknown)[0]
            raise ParameterError(name, values[name], f"unknown parameter; known: {', '.join(scene_names())}")
        return replace(self, **values)

    def as_dict(self) -> dict:
        return asdict(self)


def scene_names() -> list[str]:
    return [f.name for f in fields(Scene)]


def electrode_gaps(x: float, R: float) -> tuple[float, float]:
    """Gaps to the upper and lower electrode over R*z_s: 1 - 2x/(3R), 1 + 2x/(3R)."""
    u = 2.0 * x / (3.0 * R)
    return 1.0 - u, 1.0 + u


def validate(scene: Scene) -> None:
    """Raise ParameterError for the first parameter that makes no sense."""
    for name in scene_names():
        value = getattr(scene, name)
        if not math.isfinite(value):
            raise ParameterError(name, value, "must be a finite number")
    if scene.R <= 0:
        raise ParameterError("R", scene.R, "electrode gap ratio must be > 0")
    for name in ("mu", "alpha", "gamma"):
        if getattr(scene, name) < 0:
            raise ParameterError(name, getattr(scene, name), "must be >= 0")
    for name in ("omega", "Omega"):
        if not 0.0 <= getattr(scene, name) <= MAX_FREQUENCY:
            raise ParameterError(name, getattr(scene, name),
                                 f"forcing frequency must be in [0, {MAX_FREQUENCY:g}] (the integrators resolve "
                                 "every forcing period: faster forcing would make a doStep take forever)")
    upper, lower = electrode_gaps(scene.x_start, scene.R)
    if upper <= PULL_IN_GAP:
        raise ParameterError(
            "x_start", scene.x_start,
            f"at or beyond pull-in x = 3R/2 = {1.5 * scene.R:g} (gap 1-2x/(3R) = {upper:.3g})")
    if lower <= PULL_IN_GAP:
        raise ParameterError(
            "x_start", scene.x_start,
            f"at or beyond the lower electrode x = -3R/2 = {-1.5 * scene.R:g} (gap 1+2x/(3R) = {lower:.3g})")


MIN_RTOL = 100.0 * sys.float_info.epsilon  # below it the error control only sees rounding (scipy's floor too)


def validate_tolerance(rtol: float) -> None:
    """NaN, inf and rtol <= 0 are errors; a tolerance below MIN_RTOL is not (clamp_tolerance raises it)."""
    if not (math.isfinite(rtol) and rtol > 0):
        raise ParameterError("rtol", rtol, "must be a finite number > 0")


def clamp_tolerance(rtol: float) -> tuple[float, str | None]:
    """(the relative tolerance the integrators use, a warning or None) for a requested rtol.

    Below MIN_RTOL the error estimate of a step is rounding noise: the step size would shrink chasing it
    without making the solution more accurate (and could collapse). Such a request is served at MIN_RTOL, the
    most accurate tolerance that means something, with a warning. Raises ParameterError for NaN, inf, <= 0.
    """
    validate_tolerance(rtol)
    if rtol < MIN_RTOL:
        return MIN_RTOL, (f"parameter rtol = {rtol!r} is below {MIN_RTOL:.3g} (100 machine epsilons: the error "
                          f"control would see only rounding): using rtol = {MIN_RTOL:.3g}")
    return rtol, None


def validate_max_step(max_step: float) -> None:
    if not (math.isfinite(max_step) and max_step > 0):
        raise ParameterError("max_step", max_step, "must be a finite number > 0")


def consistency_warning(scene: Scene) -> str | None:
    """ERRATA §3.1: physically beta^2 = 8 alpha gamma; say so when a set violates it."""
    lhs, rhs = scene.beta**2, 8.0 * scene.alpha * scene.gamma
    if abs(lhs - rhs) > 1e-6 * max(lhs, rhs, 1e-300):
        return (f"beta^2 = {lhs:.3g} but 8*alpha*gamma = {rhs:.3g}: no pair of bias and AC voltages gives this "
                f"(alpha, beta, gamma), because alpha ~ V_b^2, beta ~ V_b V_ac and gamma ~ V_ac^2/4 share one "
                f"factor; the equation of motion is still well defined and is solved as given (the paper's own "
                f"example is such a set; see docs/model.md, 'Scaling')")
    return None


@dataclass(frozen=True)
class PhysicalParameters:
    """SI parameters of Eq. 1 + 2 with the electrode geometry of ERRATA §3.1.

    m [kg], c [N s/m], k [N/m^1.5] (Hertz), N [N] static load, Delta [-] load ratio,
    C0 = eps0*S [F m], d [m] upper electrode position, V_bias, V_AC [V], nu1, nu2 [rad/s].
    The lower electrode sits at z = z_s(1 - R), symmetric about the loaded equilibrium.
    """

    m: float
    c: float
    k: float
    N: float
    Delta: float
    C0: float
    d: float
    V_bias: float
    V_AC: float
    nu1: float
    nu2: float

    @property
    def z_s(self) -> float:
        return (self.N / self.k) ** (2.0 / 3.0)  # Eq. 4

    @property
    def omega0(self) -> float:
        return math.sqrt(1.5 * self.k / self.m * math.sqrt(self.z_s))  # ERRATA (4): z_s^(1/2)

    def to_scene(self, z_start: float, zdot_start: float) -> Scene:
        """Map to the dimensionless set of Eq. 3 (ERRATA §3.1) with the initial state."""
        z_s, w0 = self.z_s, self.omega0
        R = self.d / z_s - 1.0  # d = z_s (1 + R)
        scale = self.k * R**2 * z_s**3.5  # ERRATA (4): z_s^(7/2)
        return Scene(
            mu=self.c / (self.m * w0),
            Delta=self.Delta,
            omega=self.nu1 / w0,
            Omega=self.nu2 / w0,
            alpha=self.C0 * self.V_bias**2 / (2.0 * scale),
            beta=self.C0 * self.V_bias * self.V_AC / scale,
            gamma=self.C0 * self.V_AC**2 / (4.0 * scale),
            R=R,
            x_start=1.5 * (z_start / z_s - 1.0),
            v_start=1.5 * zdot_start / (z_s * w0),
        )

    def z_of_x(self, x):
        """z = z_s (1 + 2x/3)."""
        return self.z_s * (1.0 + 2.0 * x / 3.0)

    def t_of_tau(self, tau):
        """t = tau / omega0."""
        return tau / self.omega0

    def accel_eq1(self, t: float, z: float, zdot: float) -> float:
        """z'' of Eq. 1 + 2 in SI units, electrodes at z = d and z = z_s(1 - R)."""
        z_s = self.z_s
        g0 = self.d - z_s
        w = z - z_s
        hertz = self.k * max(z, 0.0) ** 1.5
        drive = self.V_bias + self.V_AC * math.sin(self.nu2 * t)
        f_em = self.C0 * drive**2 / (2.0 * (g0 - w) ** 2) - self.C0 * self.V_bias**2 / (2.0 * (g0 + w) ** 2)
        load = self.N * (1.0 + self.Delta * math.cos(self.nu1 * t))
        return (load + f_em - self.c * zdot - hertz) / self.m
