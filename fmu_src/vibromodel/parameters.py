"""Scene (dimensionless parameters + initial state), validation, physical units (docs/model.md, Scaling).

Every formula here is the corrected one (docs/model.md), not the one printed in the paper.
"""
from __future__ import annotations

import math
import sys
from dataclasses import asdict, dataclass, field, fields, replace

from . import forces, solvers
from .messages import text

# Paper example (PAPER §4, docs/model.md, The paper's example reproduced): delta*epsilon is the detuning of omega from sqrt(a1).
PAPER_DETUNING = 0.02 * 0.01

# Forcing frequencies beyond this (times the natural frequency) are refused.
MAX_FREQUENCY = 1e4

# Pull-in: the run stops when an electrode gap 1 -/+ 2x/(3R) falls below this.
PULL_IN_GAP = 1e-3


def paper_omega(alpha: float, gamma: float, R: float) -> float:
    """Eq. 9: omega = sqrt(a1) + delta*epsilon, a1 of Eq. 8 (forces.coefficients, the model's own a1)."""
    return math.sqrt(forces.coefficients(alpha, gamma, R)[1]) + PAPER_DETUNING


# The paper example's forcing frequency, 0.9987322562...
PAPER_OMEGA = paper_omega(alpha=0.001, gamma=0.0002, R=1.0)


class ParameterError(ValueError):
    """A parameter that makes no physical or numerical sense; names the parameter and value."""

    def __init__(self, name: str, value, reason: str):
        self.name, self.value, self.reason = name, value, reason
        super().__init__(f"parameter {name} = {value!r}: {reason}")


class NonFiniteOutput(ArithmeticError):
    """A model produced a non-finite output (never published with fmi2OK): names the output and its value."""

    def __init__(self, name: str, value: float):
        self.name, self.value = name, value
        super().__init__(f"output {name} = {value!r} is not finite; the parameters are beyond the model's "
                         "numerical range")


def check_finite(values: dict) -> None:
    """Raise NonFiniteOutput for the first of `values` (output name -> value) that is not finite."""
    for name, value in values.items():
        if not math.isfinite(value):
            raise NonFiniteOutput(name, float(value))  # a plain float: numpy scalars would print as np.float64(inf)


def _parameter(default: float, description: str):
    """A Scene field: its default and the description its FMU variable carries (fmus/fmu_variables.py)."""
    return field(default=default, metadata={"description": description})


# The symbols are those of the dimensionless equation of motion (Eq. 3 corrected):
# x'' + mu x' + (1 + 2x/3)^(3/2) = 1 + Delta cos(omega tau) + alpha [(1-u)^-2 - (1+u)^-2]
#                                  + (beta sin(Omega tau) + gamma (1 - cos(2 Omega tau))) (1-u)^-2,  u = 2x/(3R).
@dataclass(frozen=True)
class Scene:
    """Dimensionless parameters of Eq. 3 and the initial state x(0), x'(0)."""

    mu: float = _parameter(0.1, "damping coefficient mu")
    Delta: float = _parameter(0.0007, "amplitude Delta of the mechanical forcing Delta cos(omega tau)")
    omega: float = _parameter(PAPER_OMEGA, "frequency omega of the mechanical forcing")
    Omega: float = _parameter(2.0, "frequency Omega of the AC voltage")
    alpha: float = _parameter(0.001, "electrostatic coefficient alpha of the DC bias (both electrodes)")
    beta: float = _parameter(0.0001, "electrostatic coefficient beta of the DC x AC term beta sin(Omega tau)")
    gamma: float = _parameter(0.0002, "electrostatic coefficient gamma of the AC^2 term gamma (1 - cos(2 Omega tau))")
    R: float = _parameter(1.0, "electrode gap over the static compression (pull-in at |x| = 3R/2)")
    x_start: float = _parameter(0.04, "initial displacement x(0)")
    v_start: float = _parameter(0.0, "initial velocity x'(0)")

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


# The scene's initial state: its names that are not parameters of the equation of motion
INITIAL_STATE = ("x_start", "v_start")


def model_parameter_names() -> list[str]:
    """The scene's parameters of the equation of motion (scene_names() but the initial state), in that order: the
    core's VkModel has a field of each name (models.scene_fields; the native FMUs copy them, rules.h)."""
    return [name for name in scene_names() if name not in INITIAL_STATE]


def scene_descriptions() -> dict[str, str]:
    """The description of each scene parameter's FMU variable, by name."""
    return {f.name: f.metadata["description"] for f in fields(Scene)}


def electrode_gaps(x: float, R: float) -> tuple[float, float]:
    """Gaps to the upper and lower electrode over R*z_s: 1 - 2x/(3R), 1 + 2x/(3R)."""
    u = 2.0 * x / (3.0 * R)
    return 1.0 - u, 1.0 + u


MIN_RTOL = 100.0 * sys.float_info.epsilon  # below it the error control only sees rounding (scipy's floor too)


# -- valid ranges: one table of rules, as data ---------------------------------------------------------------
# Every parameter of the three FMUs has a rule: a finite number (a whole number for `integer` rules) in
# [low, high] (ends open where not inclusive), or exactly `automatic` where that value means "choose for me".
# `when` restricts a rule to some values of another parameter (e.g. fidelity 3 and 4 only). check_parameters
# applies the table in its order, so the first parameter out of range is the one named; rules_as_records exports
# it as plain records, from which the native FMUs' C checks are generated. Rules between parameters (x_start
# inside the electrodes 3R/2, tau_star < oafm_tau_end, a1 > 0 for fidelity 4) stay in code: validate() and the
# models check them after the table.

# A rate or an amplitude (relative to the natural frequency 1 and the static load 1) beyond MAX_SCALE needs more
# than ~1e4 integration steps per unit of time, the same limit as the forcing frequencies (MAX_FREQUENCY), and
# beyond it products of parameters overflow (issue 15: alpha = 1e308 gave a = inf, gamma = 1.797e308 a = NaN).
MAX_SCALE = 1e4
# Eq. 3's electrostatic terms carry 1/R^2 and the series of Eq. 7 powers of R up to R^5: outside [R_MIN, R_MAX]
# they under- or overflow (R^5 at 1e-6 is 1e-30 and at 1e6 is 1e30, still far inside double range).
R_MIN, R_MAX = 1e-6, 1e6
MAX_RTOL = 0.1  # above it the error control accepts O(1) relative errors: no significant digit is left
MAX_STEP_LIMIT = 1e3  # no time scale of the models is that long; an RK4 step that long is unstable (limit ~2.8)
# fidelity 4's fit: memory and set-up time grow in proportion to its span (issue 15: 1e4 took 19 s and 635 MB)
MAX_FIT_SPAN = 1e4
# fidelities 3 and 4 are built per forcing period 2 pi/omega: below 1e-3 a period exceeds any run they can afford
# (issue 15: omega = 5e-324 took 150 s to initialise, omega = 0 divided by zero in the slow flow)
MIN_AVERAGED_FREQUENCY = 1e-3
# the update law multiplies by the inverse Lyapunov weights (Eq. 76-81): below 1e-6 the estimate rates are 1e6
# times the errors and overflow (issue 15: lambda3 = 5e-324); above 1e6 the estimates are frozen below rounding
GAIN_MIN, GAIN_MAX = 1e-6, 1e6
# initial estimates of theta: its true entries are products of scene parameters bounded by MAX_SCALE and R;
# 1e12 keeps the Lyapunov function sum(theta~^2/lambda) <= 1e30 and the control force inside double range
MAX_ESTIMATE = 1e12
MAX_INPUT_RATE = 1e8  # speeds and accelerations the controller accepts as inputs
# The status shim's fast path sets inputs within [-1e6, 1e6] itself and hands any other value to the slave, which
# applies the rule: every input rule must contain that interval (tests/fmus/test_parameter_ranges.py checks it).
FAST_INPUT_LIMIT = 1e6


@dataclass(frozen=True)
class Rule:
    """A parameter's valid range (see the table above)."""

    name: str
    low: float
    high: float
    low_inclusive: bool = True
    high_inclusive: bool = True
    reason: str = ""
    integer: bool = False
    automatic: float | None = None  # a value outside [low, high] that means "automatic"
    when: tuple | None = None  # (other parameter, allowed values): the rule applies only then
    causality: str = "parameter"  # or "input": checked when the input is set

    def describe(self) -> str:
        left, right = "[" if self.low_inclusive else "(", "]" if self.high_inclusive else ")"
        kind = "a whole number" if self.integer else "a finite number"
        auto = "" if self.automatic is None else f" or {self.automatic:g} (automatic)"
        return f"must be {kind} in {left}{self.low:g}, {self.high:g}{right}{auto}"

    def applies(self, values: dict) -> bool:
        return self.when is None or values.get(self.when[0]) in self.when[1]

    def refusal(self, value) -> str | None:
        """Why value breaks the rule (with the reason), or None."""
        try:
            number = float(value)
        except (TypeError, ValueError):
            return f"{self.describe()}; {self.reason}"
        if self.automatic is not None and number == self.automatic:
            return None
        ok = math.isfinite(number) and (not self.integer or number == int(number))
        ok = ok and (number >= self.low if self.low_inclusive else number > self.low)
        ok = ok and (number <= self.high if self.high_inclusive else number < self.high)
        return None if ok else f"{self.describe()}; {self.reason}"


_AMPLITUDE = (f"an amplitude beyond {MAX_SCALE:g} times the static load drives accelerations the integrators cannot "
              "follow and overflows the polynomial model")
_RATE = f"a rate beyond {MAX_SCALE:g} times the natural frequency needs more than that many steps per unit time"
_FREQUENCY = (f"forcing frequency: the integrators resolve every forcing period, beyond {MAX_FREQUENCY:g} a doStep "
              "would take forever")
_AVERAGED = (f"fidelities 3 and 4 are built per forcing period: below {MIN_AVERAGED_FREQUENCY:g} a period is longer "
             "than any run they can afford (0 divides by zero)")
_GAIN = (f"Lyapunov weight: the update law divides by it, below {GAIN_MIN:g} the estimate rates overflow, above "
         f"{GAIN_MAX:g} the estimates stop moving")

RULES: tuple[Rule, ...] = (
    # the plant's settings first: they decide which other rules apply
    Rule("fidelity", 0, 4, reason="0 exact, 1 and 2 polynomial, 3 averaged, 4 analytic, -1 auto", integer=True,
         automatic=-1),
    Rule("tolerance", 0.0, 1.5 * R_MAX, low_inclusive=False,
         reason="fidelity auto's bound on the largest error of x over the run, in x's units (x stays inside the "
                "electrodes at +-3R/2)"),
    Rule("solver", 0, len(solvers.SOLVERS) - 1, reason=solvers.RULE_TEXT, integer=True),
    Rule("kernel", 0, 1, reason="0 compiled, 1 pure Python", integer=True),
    Rule("rtol", 0.0, MAX_RTOL, low_inclusive=False,
         reason=f"relative tolerance: above {MAX_RTOL:g} no significant digit is left (below {MIN_RTOL:.3g} it is "
                "raised to that floor with a warning)"),
    Rule("max_step", 0.0, MAX_STEP_LIMIT, low_inclusive=False, automatic=0.0,
         reason=f"step ceiling: no time scale of the models exceeds {MAX_STEP_LIMIT:g}, and an RK4 step that long "
                "is unstable"),
    # the scene (Eq. 3)
    Rule("mu", 0.0, MAX_SCALE, reason=f"damping: {_RATE}"),
    Rule("Delta", -MAX_SCALE, MAX_SCALE, reason=f"load modulation: {_AMPLITUDE}"),
    Rule("omega", 0.0, MAX_FREQUENCY, reason=_FREQUENCY),
    Rule("Omega", 0.0, MAX_FREQUENCY, reason=_FREQUENCY),
    Rule("omega", MIN_AVERAGED_FREQUENCY, MAX_FREQUENCY, reason=_AVERAGED, when=("fidelity", (3, 4))),
    Rule("Omega", MIN_AVERAGED_FREQUENCY, MAX_FREQUENCY, reason=_AVERAGED, when=("fidelity", (3, 4))),
    Rule("alpha", 0.0, MAX_SCALE, reason=f"DC electrostatic load: {_AMPLITUDE}"),
    Rule("beta", -MAX_SCALE, MAX_SCALE, reason=f"DC x AC electrostatic load: {_AMPLITUDE}"),
    Rule("gamma", 0.0, MAX_SCALE, reason=f"AC electrostatic load: {_AMPLITUDE}"),
    Rule("R", R_MIN, R_MAX, reason="electrode gap ratio: the electrostatic terms carry 1/R^2 and Eq. 7's series "
                                   f"powers of R up to R^5, which under- or overflow outside [{R_MIN:g}, {R_MAX:g}]"),
    Rule("x_start", -1.5 * R_MAX, 1.5 * R_MAX, reason="initial x: inside the electrodes at -3R/2 and 3R/2"),
    Rule("v_start", -MAX_SCALE, MAX_SCALE, reason=f"initial speed: {_RATE}"),
    # fidelity 4 (OAFM)
    Rule("oafm_order", 1, 8, reason="order of the harmonic OAFM basis", integer=True),
    Rule("tau_star", 0.0, MAX_FIT_SPAN, low_inclusive=False, automatic=0.0,
         reason=f"end of the transient domain, inside the fit (at most {MAX_FIT_SPAN:g})"),
    Rule("oafm_tau_end", 0.0, MAX_FIT_SPAN, low_inclusive=False, automatic=0.0,
         reason="end of the fit: its memory and set-up time grow with its span (1e4: 19 s, 635 MB)"),
    # the controller (docs/model.md, Adaptive controller) and the closed loop's reference
    Rule("law", 0, 2, reason="0 paper-corrected, 1 damped, 2 paper-literal", integer=True),
    *(Rule(f"lambda{i}", GAIN_MIN, GAIN_MAX, reason=_GAIN) for i in range(1, 12)),
    Rule("k_damping", GAIN_MIN, GAIN_MAX, reason="the damped law's e2 gain, bounded as the Lyapunov weights"),
    *(Rule(f"{name}_hat_start", -MAX_ESTIMATE, MAX_ESTIMATE,
           reason=f"initial estimate: beyond {MAX_ESTIMATE:g} the Lyapunov function overflows")
      for name in ("mu", "a1", "a2", "a3", "a4", "a5", "Delta", "beta", "gamma")),  # control.THETA_NAMES
    Rule("reference", 0, 2, reason="0 OAFM, 1 docs/model.md, Adaptive controller harmonic, 2 harmonic + tones", integer=True),
    Rule("x_ref_start", -1.5 * R_MAX, 1.5 * R_MAX, reason="the reference's initial x: inside the electrodes"),
    Rule("v_ref_start", -MAX_SCALE, MAX_SCALE, reason=f"the reference's initial speed: {_RATE}"),
    # the controller's inputs: the plant's state and the reference (a doStep and V are polynomials of degree <= 5
    # in x and 2 in the errors: with these bounds and the gains' they stay below ~1e60, far inside double range)
    *(Rule(name, -1.5 * R_MAX, 1.5 * R_MAX, reason=f"{name} of the plant: inside the electrodes at +-3R/2",
           causality="input") for name in ("x", "x_ref")),
    *(Rule(name, -MAX_INPUT_RATE, MAX_INPUT_RATE, reason=f"{name}: beyond {MAX_INPUT_RATE:g} the control law and "
                                                          "its Lyapunov function overflow", causality="input")
      for name in ("v", "v_ref", "a_ref")),
)


def check_parameters(values: dict) -> None:
    """Raise ParameterError for the first of `values` (name -> value) that breaks its rule, in the table's order.
    Names without a rule are left alone (an FMU's parameters all have one: tests/fmus/test_parameter_ranges.py)."""
    for rule in RULES:
        if rule.name in values and rule.applies(values):
            reason = rule.refusal(values[rule.name])
            if reason is not None:
                raise ParameterError(rule.name, values[rule.name], reason)


def rules_as_records() -> list[dict]:
    """The table as plain records (name, low, high, low_inclusive, high_inclusive, integer, automatic, when,
    reason), in checking order, for generating the same checks elsewhere (the native FMUs' C)."""
    return [asdict(rule) | {"when": None if rule.when is None else {"name": rule.when[0],
                                                                     "values": list(rule.when[1])}}
            for rule in RULES]


def validate(scene: Scene) -> None:
    """Raise ParameterError for the first parameter that makes no sense: the rules of the table, then x_start
    against the electrodes."""
    check_parameters(scene.as_dict())
    upper, lower = electrode_gaps(scene.x_start, scene.R)
    if upper <= PULL_IN_GAP:
        raise ParameterError("x_start", scene.x_start, text("PULL_IN_START", bound=1.5 * scene.R, gap=upper))
    if lower <= PULL_IN_GAP:
        raise ParameterError("x_start", scene.x_start, text("LOWER_START", bound=-1.5 * scene.R, gap=lower))




def validate_tolerance(rtol: float) -> None:
    """NaN, inf, rtol <= 0 and rtol > MAX_RTOL are errors; a tolerance below MIN_RTOL is not (clamp_tolerance
    raises it)."""
    check_parameters({"rtol": rtol})


def clamp_tolerance(rtol: float) -> tuple[float, str | None]:
    """(the relative tolerance the integrators use, a warning or None) for a requested rtol.

    Below MIN_RTOL the error estimate of a step is rounding noise: the step size would shrink chasing it
    without making the solution more accurate (and could collapse). Such a request is served at MIN_RTOL, the
    most accurate tolerance that means something, with a warning. Raises ParameterError for NaN, inf, <= 0.
    """
    validate_tolerance(rtol)
    if rtol < MIN_RTOL:
        return MIN_RTOL, text("RTOL_CLAMPED", requested=repr(rtol), floor=MIN_RTOL)
    return rtol, None


def validate_max_step(max_step: float) -> None:
    check_parameters({"max_step": max_step})


def consistency_warning(scene: Scene) -> str | None:
    """docs/model.md, Scaling: physically beta^2 = 8 alpha gamma; say so when a set violates it."""
    lhs, rhs = scene.beta**2, 8.0 * scene.alpha * scene.gamma
    if abs(lhs - rhs) > 1e-6 * max(lhs, rhs, 1e-300):
        return (f"beta^2 = {lhs:.3g} but 8*alpha*gamma = {rhs:.3g}: no pair of bias and AC voltages gives this "
                f"(alpha, beta, gamma), because alpha ~ V_b^2, beta ~ V_b V_ac and gamma ~ V_ac^2/4 share one "
                f"factor; the equation of motion is still well defined and is solved as given (the paper's own "
                f"example is such a set; see docs/model.md, 'Scaling')")
    return None


@dataclass(frozen=True)
class PhysicalParameters:
    """SI parameters of Eq. 1 + 2 with the electrode geometry of docs/model.md, Scaling.

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
        return math.sqrt(1.5 * self.k / self.m * math.sqrt(self.z_s))  # corrected Eq. (4): z_s^(1/2)

    def to_scene(self, z_start: float, zdot_start: float) -> Scene:
        """Map to the dimensionless set of Eq. 3 (docs/model.md, Scaling) with the initial state."""
        z_s, w0 = self.z_s, self.omega0
        R = self.d / z_s - 1.0  # d = z_s (1 + R)
        scale = self.k * R**2 * z_s**3.5  # corrected Eq. (4): z_s^(7/2)
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
