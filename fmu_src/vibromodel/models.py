"""The plant's models; each gives x'' = accel(t, x, v, U) and its events (fidelities.py says which level uses which).

ExactModel: exact Eq. 3 (+ input force U). PolynomialModel: polynomial Eq. 7 with the corrected a0..a5, or with
the paper's printed a0..a5 (printed=True). A scene pays only for the physics it switches on:
terms whose amplitude is zero are not evaluated.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Callable

from . import forces
from .messages import text
from .parameters import MIN_RTOL, PULL_IN_GAP, ParameterError, Scene, model_parameter_names
from .solvers import solver_entry



class CModel(IntEnum):
    """The compiled core's model of a level's forces (and x'' of an integrated level): core/model.h's VkModel
    (polynomial = 0 or 1) and, for the native FMUs, which coefficients of Eq. 7 (native/series.c). Each model class
    says which it is (`c_model`) and gives its VkModel's fields (`compiled_fields()`)."""
    EXACT = 0  # Eq. 3 (ExactModel)
    POLYNOMIAL = 1  # Eq. 7 with the corrected a0..a5 (PolynomialModel)
    POLYNOMIAL_PRINTED = 2  # Eq. 7 with the paper's printed a0..a5 (PolynomialModel(printed=True))


R_OUT_OF_RANGE = "out of range of the series of Eq. 7 (powers of R up to R^5 overflow or vanish)"


@dataclass(frozen=True)
class Event:
    """A zero of g(x) that an integrator must not step across blindly.

    terminal: the run stops there (pull-in); otherwise the step is cut there (contact kink).
    affine: (c0, cx) when g(x) = c0 + cx x, evaluated so (affine_event): integrate.Dop853 needs it to bound g on
    a step's dense output.
    """

    name: str
    g: Callable[[float], float]
    terminal: bool
    affine: tuple[float, float] | None = None


def affine_event(name: str, c0: float, cx: float, terminal: bool) -> Event:
    """The event g(x) = c0 + cx x (the C solver's form, core/dop853.h)."""
    return Event(name, lambda x: c0 + cx * x, terminal, (c0, cx))


def pull_in_slope(R: float) -> float:
    """c = 2/(3R): the electrode gaps are 1 - c x and 1 + c x."""
    return 2.0 / (3.0 * R)


def pull_in_events(R: float) -> tuple[Event, Event]:
    """Gaps 1 -/+ 2x/(3R) reaching PULL_IN_GAP: the electrostatic force is singular at gap 0."""
    c = pull_in_slope(R)
    return (
        affine_event(f"pull-in: upper gap 1 - 2x/(3R) below {PULL_IN_GAP:g}", 1.0 - PULL_IN_GAP, -c, True),
        affine_event(f"pull-in: lower gap 1 + 2x/(3R) below {PULL_IN_GAP:g}", 1.0 - PULL_IN_GAP, c, True),
    )


# The contact indentation 1 + 2x/3 as an affine form: g = 1 + (2/3) x (within an ulp of forces.contact_indentation).
CONTACT_EVENT = affine_event("contact", 1.0, 2.0 / 3.0, False)


def drive_frequencies(s: Scene) -> tuple[float, float, float]:
    """The frequencies of the drive terms' time functions cos(omega t), sin(Omega t), cos(2 Omega t), as a model's
    accel_phased takes them: phases = [cos f0 t, sin f0 t, cos f1 t, sin f1 t, cos f2 t, sin f2 t] for these f
    (0 for a term the model leaves out; core/plant.c's plant_frequencies)."""
    ac = s.beta != 0.0 or s.gamma != 0.0
    return (s.omega if s.Delta != 0.0 else 0.0, s.Omega if ac else 0.0, 2.0 * s.Omega if ac else 0.0)


# The adaptive solver's default step ceiling (max_step = 0): a step turns the fastest forcing term the scene switches
# on by at most DRIVE_STEP_TURN radians (issue 25: at Omega = 9.3, rtol 1e-3, lightly damped, DOP853 stepped over
# the drive and erred by 310 rtol max|x|; max_step = 3/(2 Omega) brought it to 0.3). The error control alone lets a
# step turn a small drive term by any angle when the rest of the motion is smooth: its error per step is then below
# the tolerance, but not random, and over a lightly damped run the steps' errors add up.
# Why 4 (0.64 of the fastest drive's period per step): `python -m vibrofmu.analyses.domains turns N SEED`
# (domains.turn_campaign: every run at several turns) with DOP853's PI step controller, error over the bound 100 rtol
# max|x| of the acceptance, at the turns 2.25 / 4 / none: 200 contact-loss scenes (seed 0) worst 0.051 at each, every
# contact change along the output grid the reference's; 200 of them with drives up to omega, Omega = 100: 0.42 /
# 0.34 / 0.34; long lightly damped grazing runs (Omega up to 10, tau up to 5,000) 60 of seed 0: 0.047 / 0.24 / 0.23,
# 100 of seed 2: 0.066 / 0.11 / 0.096; every run within at every turn. Where the ceiling decides, in rtol max|x|: the
# Omega = 9.3 test scene at rtol 1e-3 (tests/model/test_rung_domains.py) 2.3e-7 / 1.5e-5 / 1.89; the contact-loss
# campaign's worst run (tests/model/test_event_location.py) 0.017 / 0.30 / 0.30; the error grows with the turn, at 4
# still orders below the bound. The per-step estimate is not a bound on such steps (docs/events.md: in a sample of
# 11,000 trial steps the true local error reached 17.6 tolerances at h omega_max = 2.2, 1.3 ... 2.9 from 2.5 to 5:
# sporadic, not ordered by the turn). The turn was 2.25 before (the paper scene's largest accepted step at rtol 1e-8,
# h omega_max = 2.243, not cut; 1.8 before it made the step grid move with the last bit of any input): at loose
# tolerances it, not rtol, set the paper scene's steps (357 steps over [0, 200] from rtol 1e-4 to 1e-6, error 1.8e-9
# whatever the rtol asked). At 4 the ceiling (1.0 on the paper scene) cuts no step of it at rtol <= 1e-7 and binds
# at looser ones: rtol 1e-4 204 steps (3,062 RHS calls instead of 5,357), error 1.8e-7; without any ceiling 179 steps,
# 2.9e-6. max_step > 0 overrides it (max_step = 1000, the rule's top, is in effect no ceiling).
DRIVE_STEP_TURN = 4.0


def drive_step_ceiling(s: Scene, extra: float = 0.0) -> float:
    """DRIVE_STEP_TURN / the fastest angular frequency among the forcing terms switched on (omega if Delta != 0,
    Omega if beta != 0, 2 Omega if gamma != 0) and `extra` (a closed loop's reference); inf when none (core twin:
    native/plant_setup.c native_drive_ceiling)."""
    fastest = max(s.omega if s.Delta != 0.0 else 0.0, s.Omega if s.beta != 0.0 else 0.0,
                  2.0 * s.Omega if s.gamma != 0.0 else 0.0, extra)
    return DRIVE_STEP_TURN / fastest if fastest > 0.0 else math.inf


# The adaptive plant's tolerance over a long, lightly damped run (issue 25). DOP853 keeps the error of each step within
# rtol; the errors of the steps add up over the time the response remembers them: 2/mu (the free motion's envelope
# e^(-mu t / 2)), or the run's span if that is shorter. Over the grazing campaign (vibrofmu.analyses.domains graze:
# near-resonant loads that reach the contact edge, mu in [1e-3, 2e-2], tau up to 5,000) the error at a requested
# rtol grew with that memory M -- its median about as M^2 (8e-4, 5e-3, 2e-2, 0.1 of 100 rtol max|x| for M in
# [100, 200), [200, 400), [400, 800), [1200, 2100)) -- and stayed proportional to the tolerance (error at rtol f for
# f = 1, 0.5, 0.25, 0.1, 0.01: 2.26, 1.45, 0.60, 0.28, 0.024 of the bound on the worst run). So the solver runs at
# rtol * tolerance_factor: ERROR_MEMORY_REFERENCE / M (at most 1, at least TOLERANCE_FACTOR_FLOOR), i.e. rtol is
# what the run may lose per ERROR_MEMORY_REFERENCE time units of memory. Why 150: measured over 1,217 campaign runs
# (seeds 0 and 1), the largest error was 2.48 bounds with no factor (6 and 17 runs above 1) and 0.36 with 150 (0.55
# with 200, 0.59 with 300), for 5.5 ... 7.9 % more RHS calls than no factor; on seed 2, run after the choice, 1,000 of
# 1,000 runs within, the worst at 0.31 (13 above 1 without the factor; docs/rungs.md, Domains). A scene with
# mu >= 2/150 = 0.0133 (the paper's mu = 0.1 among them), or a span <= 150, runs at rtol unchanged: its results are
# the same bits. The floor 0.01 is reached for M >= 15,000 (mu = 0 with an open-ended or very long run): DOP853's
# cost grows as factor^(-1/8), 1.78 times at the floor.
ERROR_MEMORY_REFERENCE = 150.0
TOLERANCE_FACTOR_FLOOR = 0.01


def error_memory(s: Scene, span: float | None = None) -> float:
    """The time over which the plant's response remembers an error: 2/mu (inf for mu = 0), or the run's span (stop
    time - start time) if that is shorter; a span that is None, not > 0 or NaN is not known (core twin:
    native/plant_setup.c native_tolerance_factor)."""
    memory = 2.0 / s.mu if s.mu > 0.0 else math.inf
    if span is not None and span > 0.0 and span < memory:
        memory = span
    return memory


def tolerance_factor(s: Scene, span: float | None = None) -> float:
    """The adaptive plant's rtol factor: ERROR_MEMORY_REFERENCE / error_memory, within [TOLERANCE_FACTOR_FLOOR, 1]
    (comment above)."""
    factor = ERROR_MEMORY_REFERENCE / error_memory(s, span)
    if factor < TOLERANCE_FACTOR_FLOOR:
        factor = TOLERANCE_FACTOR_FLOOR
    if factor > 1.0:
        factor = 1.0
    return factor


def solver_tolerance(s: Scene, settings, t0: float = 0.0, stop_time: float | None = None) -> tuple[float, list[str]]:
    """(the rtol the plant's solver runs with, notes for the log) for `settings` (settings.Settings: rtol, solver) over
    [t0, stop_time] (None: open-ended): rtol * tolerance_factor, not below MIN_RTOL; one note when the factor is below
    1 and the solver reads rtol (a fixed-step solver ignores it). Plant and CompiledPlant both call it (core twin: the
    native plant's model_initialise)."""
    span = None if stop_time is None else stop_time - t0
    factor = tolerance_factor(s, span)
    if factor == 1.0:
        return settings.rtol, []
    solver_rtol = max(MIN_RTOL, settings.rtol * factor)
    if solver_entry(settings.solver).fixed_step:
        return solver_rtol, []
    return solver_rtol, [text("TOLERANCE_FACTOR", solver_rtol=solver_rtol, rtol=settings.rtol, factor=factor,
                              memory=error_memory(s, span), reference=ERROR_MEMORY_REFERENCE)]


def scene_fields(s: Scene) -> dict:
    """The VkModel fields (core/model.h) every model fills from its own scene: the parameters, the pull-in events'
    constants and the switches of the drive terms."""
    fields = {name: getattr(s, name) for name in model_parameter_names()}
    ac = s.beta != 0.0 or s.gamma != 0.0
    fields.update(pull_in_c=pull_in_slope(s.R), pull_in_gap=PULL_IN_GAP, load_forcing=int(s.Delta != 0.0), ac=int(ac))
    return fields


class ExactModel:
    """Eq. 3 with U added: x'' = 1 + Delta cos(omega t) + F_em(t, x) - H(x) - mu x' + U."""

    c_model = CModel.EXACT

    def compiled_fields(self) -> dict:
        """core/model.h's VkModel of this model, from its own scene (compiled*.py hand it to the C; the native FMUs
        compute it from their parameters in native/plant_setup.c, which fidelities.native_mismatch checks)."""
        fields = scene_fields(self.scene)
        return fields | dict(polynomial=0, electrostatics=int(self.scene.alpha != 0.0 or bool(fields["ac"])))

    def __init__(self, scene: Scene):
        self.scene = scene
        self.events = (CONTACT_EVENT,) + pull_in_events(scene.R)
        self.accel, self.accel_phased = self._make_accel(scene)
        self.drive_frequencies = drive_frequencies(scene)

    @staticmethod
    def _make_accel(s: Scene):
        mu, Delta, omega = s.mu, s.Delta, s.omega
        alpha, beta, gamma, Omega, R = s.alpha, s.beta, s.gamma, s.Omega, s.R
        load_forcing = Delta != 0.0
        electrostatics = alpha != 0.0 or beta != 0.0 or gamma != 0.0
        cos, electrostatic, hertz = math.cos, forces.electrostatic, forces.hertz

        def accel(t, x, v, U):
            a = 1.0 + U - mu * v
            a -= hertz(x)  # Hertz contact, zero without contact
            if load_forcing:
                a += Delta * cos(omega * t)
            if electrostatics:
                a += electrostatic(t, x, alpha, beta, gamma, Omega, R)
            return a

        def accel_phased(t, phases, x, v, U):  # accel with the drive's phasors given (drive_frequencies)
            a = 1.0 + U - mu * v
            a -= hertz(x)
            if load_forcing:
                a += Delta * phases[0]
            if electrostatics:
                a += electrostatic(t, x, alpha, beta, gamma, Omega, R, (phases[3], phases[4]))
            return a

        return accel, accel_phased

    def forces(self, t: float, x: float) -> tuple[float, float]:
        """(F_contact, F_electrostatic) as they enter Eq. 3."""
        s = self.scene
        return forces.hertz(x), forces.electrostatic(t, x, s.alpha, s.beta, s.gamma, s.Omega, s.R)


class PolynomialModel:
    """Eq. 7: x'' = -mu x' - sum a_k x^k + Delta cos(omega t) + (beta sin Omega t - gamma cos 2 Omega t) G3(x) + U.

    Its events are the exact model's pull-in events (same rule, same message): the series of Eq. 7 is smooth across
    the electrodes, but the device it approximates is not, and a polynomial run beyond x = +-3R/2 is no answer
    (issue 25: fidelities 1 and 2 returned |x| up to 34.6 with fmi2OK). No contact event: Eq. 7 has no kink there.
    """

    def __init__(self, scene: Scene, printed: bool = False):
        self.scene = scene
        self.c_model = CModel.POLYNOMIAL_PRINTED if printed else CModel.POLYNOMIAL
        self.events: tuple[Event, ...] = pull_in_events(scene.R)
        make = forces.coefficients_printed if printed else forces.coefficients
        try:
            self.a = make(scene.alpha, scene.gamma, scene.R)
            self.g1 = forces.series_g1_printed(scene.R) if printed else forces.series_g1()
            self.g2 = forces.series_g2(scene.R)
            self.g3 = forces.series_g3(scene.R)
        except ArithmeticError:
            raise ParameterError("R", scene.R, R_OUT_OF_RANGE) from None
        self.accel, self.accel_phased = self._make_accel(scene, self.a, self.g3)
        self.drive_frequencies = drive_frequencies(scene)

    @staticmethod
    def _make_accel(s: Scene, a, g3):
        mu, Delta, omega, beta, gamma, Omega = s.mu, s.Delta, s.omega, s.beta, s.gamma, s.Omega
        a0, a1, a2, a3, a4, a5 = a
        g30, g31, g32, g33, g34, g35 = g3
        load_forcing = Delta != 0.0
        ac = beta != 0.0 or gamma != 0.0
        sin, cos, cos_double_angle = math.sin, math.cos, forces.cos_double_angle

        def accel(t, x, v, U):
            acc = U - mu * v - (a0 + x * (a1 + x * (a2 + x * (a3 + x * (a4 + x * a5)))))
            if load_forcing:
                acc += Delta * cos(omega * t)
            if ac:
                G3 = g30 + x * (g31 + x * (g32 + x * (g33 + x * (g34 + x * g35))))
                s = sin(Omega * t)
                acc += (beta * s - gamma * cos_double_angle(s)) * G3
            return acc

        def accel_phased(t, phases, x, v, U):  # accel with the drive's phasors given (drive_frequencies)
            acc = U - mu * v - (a0 + x * (a1 + x * (a2 + x * (a3 + x * (a4 + x * a5)))))
            if load_forcing:
                acc += Delta * phases[0]
            if ac:
                G3 = g30 + x * (g31 + x * (g32 + x * (g33 + x * (g34 + x * g35))))
                acc += (beta * phases[3] - gamma * phases[4]) * G3
            return acc

        return accel, accel_phased

    def compiled_fields(self) -> dict:
        """ExactModel.compiled_fields for Eq. 7: its coefficients and series."""
        fields = scene_fields(self.scene)
        return fields | dict(polynomial=1, electrostatics=fields["ac"], poly=self.a, g1=self.g1, g2=self.g2,
                             g3=self.g3)

    def forces(self, t: float, x: float) -> tuple[float, float]:
        """(G1(x), alpha G2(x) + (beta sin + gamma(1 - cos 2 Omega t)) G3(x)): the series of Eq. 5."""
        s = self.scene
        sine = math.sin(s.Omega * t)
        drive = s.beta * sine + s.gamma * (1.0 - forces.cos_double_angle(sine))
        return forces.horner(self.g1, x), s.alpha * forces.horner(self.g2, x) + drive * forces.horner(self.g3, x)



def scene_model(scene: Scene, c_model: CModel):
    """The model of kind c_model made from the scene alone: what the native FMUs compute from their parameters
    (native/plant_setup.c native_plant_model, native/series.c)."""
    return ExactModel(scene) if c_model == CModel.EXACT else PolynomialModel(
        scene, printed=c_model == CModel.POLYNOMIAL_PRINTED)
