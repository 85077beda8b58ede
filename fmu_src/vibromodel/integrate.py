"""Integrators of x' = v, v' = accel(t, x, v, U) that live inside the FMU between doSteps.

- Dop853: adaptive embedded Runge-Kutta 8(5,3) of Hairer, Norsett and Wanner (the algorithm and
  coefficients of scipy's DOP853), with error control, 7th-order dense output and event location.
  It keeps its step size, its last derivative (FSAL) and its last step's interpolant between
  communication points: a communication point inside a step is read from the dense output, so a
  doStep costs no restart. A step that would cross a contact event is cut at the event (the contact
  force has a kink there); a terminal event (pull-in) stops the run at the event.
- Rk4: classic fixed-step Runge-Kutta 4; each communication interval is split into equal steps no
  longer than max_step.

Both work on Python floats (a 2-state system is far faster this way than with numpy arrays).

Extra first-order states (a closed loop's parameter estimates) ride in the input slot: by default the
input U is held between set_input calls (U' = 0, zero-order hold); given `rates`, U is a numpy vector
integrated with x and v by the same stages, U' = rates(t, x, v, U), and accel(t, x, v, U) reads it.
The plant's scalar path only pays one `is None` test per stage.
"""
from __future__ import annotations

import abc
import errno
import importlib.util
import math
import os
import sys
from fractions import Fraction
from math import comb

import numpy as np


class IntegrationError(RuntimeError):
    """The integrator cannot continue; the message says where and why."""

    def __init__(self, message: str, t: float, x: float, v: float):
        super().__init__(message)
        self.t, self.x, self.v = t, x, v


class TerminalEvent(IntegrationError):
    """A terminal event (pull-in) was reached at (t, x, v)."""


def _dop853_coefficients():
    """scipy's DOP853 tableau (scipy/integrate/_ivp/dop853_coefficients.py, numpy only), loaded from its file
    unless scipy.integrate is already imported: importing scipy.integrate would cost ~0.6 s."""
    name = "scipy.integrate._ivp.dop853_coefficients"
    if name in sys.modules:
        return sys.modules[name]
    scipy_dir = importlib.util.find_spec("scipy").submodule_search_locations[0]
    spec = importlib.util.spec_from_file_location(f"vibromodel._{name}", f"{scipy_dir}/integrate/_ivp/dop853_coefficients.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_dop = _dop853_coefficients()


def _rows(matrix, n_rows, start=0):
    return tuple(tuple(float(a) for a in matrix[s, :s]) for s in range(start, start + n_rows))


# Butcher tableau of DOP853 (12 stages + FSAL stage), error weights and dense-output extension.
N_STAGES = _dop.N_STAGES
A = _rows(_dop.A, N_STAGES)
B = tuple(float(b) for b in _dop.B)
C = tuple(float(c) for c in _dop.C[:N_STAGES])
E3 = tuple(float(e) for e in _dop.E3)
E5 = tuple(float(e) for e in _dop.E5)
D = tuple(tuple(float(d) for d in row) for row in _dop.D)
A_EXTRA = _rows(_dop.A, 3, start=N_STAGES + 1)
C_EXTRA = tuple(float(c) for c in _dop.C[N_STAGES + 1:])
# Stages 2..12 (row of A, node c), then the first-same-as-last stage at the new state (row B, node 1).
STAGES = tuple(zip(A[1:], C[1:])) + ((B, 1.0),)
EXTRA_STAGES = tuple(zip(A_EXTRA, C_EXTRA))  # the three stages of the dense output

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
ERROR_EXPONENT = -1.0 / 8.0  # error estimator of order 7
# After an accepted step the next step size comes from a PI controller (Gustafsson; Hairer, Norsett & Wanner I,
# II.4, and Hairer's dopri5.f): h_new = h SAFETY err^-PI_ALPHA max(err_old, PI_ERROR_FLOOR)^PI_BETA, err_old the last
# accepted step's error norm, with PI_ALPHA = 1/8 - 0.75 PI_BETA (the I controller's exponent -1/8 moved onto the last
# error), PI_BETA = 0.04 (Hairer's value). The plain I controller (SciPy's: err^(-1/8) alone) read each step's error
# as if it held for the next one; here the error of a step depends on the drive's phase over it (the drive terms
# dominate the local error of the paper scene: its norm swings tenfold between neighbouring steps of the same size),
# and the controller grew the step after every low reading into a rejection: on the paper scene over tau in
# [0, 200] without the drive's ceiling, 863 trials for 675 steps at rtol 1e-9 (271 for 213 at 1e-5). With the PI
# controller 753 for 739 (243 for 232): 11,252 RHS calls instead of 12,380 (3,614 instead of 3,893), the error of x
# against the reference 4.0e-11 instead of 2.2e-10 (4.6e-7 and 4.9e-7 at 1e-5). A rejected trial's retry and
# _shorten keep the I rule. The first step (no error before it) has the memory term 1: with Hairer's start (the
# floor 1e-4, a step cut by 0.69) the paper scene's run without the ceiling erred by 1.5e-6 at rtol 1e-4 and 3.5e-7
# at 1e-6, two decades of rtol for a factor 4 of error (tests/fmus/test_accuracy.py asks for 10); with 1, 2.9e-6 and
# 1.25e-7.
PI_BETA = 0.04
PI_ALPHA = 1.0 / 8.0 - 0.75 * PI_BETA
PI_ERROR_FLOOR = 1e-4  # Hairer's: the error of a step far below its tolerance counts as 1e-4 (no previous step: 1)
# Error norm of a trial step: Hairer's combination h e5^2 / sqrt(e5^2 + 0.01 e3^2) estimates the 8th-order error as
# the 5th-order estimate e5 times e5 / (0.1 e3) = O(h^2), which holds where the solution is smooth over a disk of
# radius ~h around the step. Near a kink of the right-hand side (a non-terminal event: the contact force's g^(3/2)
# puts a (t - t_kink)^(3/2) term in x'') all embedded solutions have errors of the same low order (h^2.5 in v), the
# factor is not small, and the combination under-reports: measured 25-34 times on the steps that start at a
# re-contact (docs/events.md).
# On a step that crosses such an event or lies within one step of it (_near_kink) e3 gets weight 0: the error is e5.
ATOL_PER_RTOL = 1e-2  # atol = 1e-2 rtol: the response is O(1e-2), so rtol alone would be too loose

# Event location (docs/events.md). The dense output of a step is a polynomial of degree 7 in the step
# fraction s; an affine event function g of it is one too, and its 8 Bernstein coefficients on an interval
# bound it there (convex hull). A step is searched by bisecting [0, 1] (left half first) until every piece
# is either proved free of the event by its coefficients or its end is found on the event's far side.
# Pieces shorter than 2^-EVENT_MAX_DEPTH of the step are not split further (a tangential touch).
EVENT_MAX_DEPTH = 40
# Nor is a piece on which g varies by no more than the rounding of its coefficients and of g's evaluation
# (max(b) - min(b) <= tol, tol = EVENT_ROUNDING * the sum of the magnitudes b is computed from): splitting it cannot
# tell a touch from rounding, and the interpolant's verdict at the piece's end decides. Without that bound a touch
# within rounding (a graze of depth ~1e-16) sent the depth-first search through every 2^-40 piece of the region
# where the hull straddles 0 (964,111 in one step), and a step whose coefficients round by more than g itself
# (x'' ~ 1e46 from rest) through up to 2^40 pieces. EVENT_ROUNDING = 2^-46 = 64 eps: b is a sum of 9 terms (each
# rounded once, <= 9 eps of the magnitudes), 40 halvings add <= 40 eps more, the evaluation of g a few eps.
EVENT_ROUNDING = 2.0 ** -46
# A search examines (evaluates g at the end of) at most EVENT_MAX_PIECES pieces, then raises RuntimeError
# (EVENT_UNSETTLED); a safety net: the random contact-loss scenes and the graze sweep examine at most 17 pieces per
# search (tests/core/test_event_search_twins.py checks a graze stays two orders below the bound), so no sound step
# reaches it.
EVENT_MAX_PIECES = 4096
EVENT_UNSETTLED = (f"event search gave up after {EVENT_MAX_PIECES} pieces of the step: the Bernstein hull of the "
                   "event function and the dense output disagree (the step's values exceed the arithmetic)")
# A step is searched only if g comes within EVENT_SCREEN * (|g(end) - g(start)| + h (|g'(start)| + |g'(end)|))
# of 0 at one of its ends (or changes side): a step's motion of g stays within half that bound for a
# parabolic arc, so the screen keeps a factor 4 on it (docs/events.md).
EVENT_SCREEN = 2.0


def _bernstein_matrix():
    """M[j][k]: Bernstein coefficient k (degree 7) of the j-th term s^a (1-s)^b of the dense output
    (scipy's Dop853DenseOutput: F0 s + F1 s(1-s) + F2 s^2(1-s) + F3 s^2(1-s)^2 + ... + F6 s^4(1-s)^3)."""
    powers = ((1, 0), (1, 1), (2, 1), (2, 2), (3, 2), (3, 3), (4, 3))
    rows = []
    for a, b in powers:
        row = [Fraction(0)] * 8
        for m in range(8 - a - b):  # s^a (1-s)^b (s + 1 - s)^(7-a-b)
            row[a + m] += Fraction(comb(7 - a - b, m), comb(7, a + m))
        rows.append(tuple(float(value) for value in row))
    return tuple(rows)


BERNSTEIN = _bernstein_matrix()


def _dot(coefficients, values):
    """sum(c * k) over the shorter of the two sequences, left to right from 0.0 (a specified order: CPython's
    sum() of floats is compensated from 3.12 on, and the C twin must give the same bits)."""
    total = 0.0
    for c, k in zip(coefficients, values):
        total += c * k
    return total


def _tableau_dot(coefficients, values):
    """_dot without the terms whose coefficient is zero (38 of DOP853's 120 stage coefficients, rows of A and B):
    the same value whenever the skipped values are finite, as the sum starts at +0.0 and so is never -0.0, and
    c * k = +-0.0 then leaves it unchanged. Used by every stage (the plant's and the closed loop's), as the C twin
    (core/dop853.c stages_of) skips the same terms; the error and dense-output sums keep _dot, every term, so that
    a stage that is not finite makes the error estimate (and the dense output) non-finite, as it must."""
    total = 0.0
    for c, k in zip(coefficients, values):
        if c != 0.0:
            total += c * k
    return total


def _norm(values):
    """math.hypot(*values): the same function as the C twin's vk_python_hypot (CPython's vector_norm)."""
    return math.hypot(*values)


def _monotone(b):
    """Whether Bernstein coefficients b rise or fall strictly (then so does their polynomial: its derivative's
    coefficients are their differences)."""
    rising = falling = True
    for k in range(len(b) - 1):
        rising = rising and b[k + 1] > b[k]
        falling = falling and b[k + 1] < b[k]
    return rising or falling


def _split(b):
    """de Casteljau at s = 1/2: the Bernstein coefficients of the left and right halves."""
    b = list(b)
    degree = len(b) - 1
    left, right = [b[0]], [b[-1]]
    for r in range(1, degree + 1):
        for k in range(degree + 1 - r):
            b[k] = 0.5 * (b[k] + b[k + 1])
        left.append(b[0])
        right.append(b[degree - r])
    right.reverse()
    return left, right


def bernstein_search(b, positive, beyond, tol):
    """The event search of both integrators (core/roots.c bernstein_search, the same operations): the first piece
    (s_a, s_b) of [0, 1], left half first, whose end s_b is beyond the event (beyond(s): g at the step fraction s
    is past it, seen from the side the step starts on) and on which g, given by its Bernstein coefficients b on
    [0, 1], is monotone (_monotone) or which is 2^-EVENT_MAX_DEPTH long or on which b spans no more than tol (the
    rounding of b and of g's evaluation: EVENT_ROUNDING); pieces whose hull is on the start side
    (positive: min(b) > 0; else not max(b) > 0) are skipped. None if there is none, else (s_a, s_b, beyond(s_a)):
    with the last True the event is at s_a (a rounding of the hull's verdict on the piece before), else one zero
    lies in the piece. RuntimeError (EVENT_UNSETTLED) once EVENT_MAX_PIECES pieces were examined in vain."""
    stack = [(0.0, 1.0, 0, b)]
    examined = 0
    while stack:
        s_a, s_b, depth, b = stack.pop()
        if (min(b) > 0.0) if positive else not (max(b) > 0.0):
            continue  # the hull of g on the piece is on the start side
        if examined == EVENT_MAX_PIECES:
            raise RuntimeError(EVENT_UNSETTLED)
        examined += 1
        resolved = depth >= EVENT_MAX_DEPTH or max(b) - min(b) <= tol
        if beyond(s_b) and (resolved or _monotone(b)):
            return s_a, s_b, beyond(s_a)
        if not resolved:
            left, right = _split(b)
            middle = 0.5 * (s_a + s_b)
            stack.append((middle, s_b, depth + 1, right))
            stack.append((s_a, middle, depth + 1, left))
    return None


class Integrator(abc.ABC):
    """The solvers' protocol (like SciPy's OdeSolver): what the plants, the closed loop and their snapshots use of
    an integrator of x'' = accel(t, x, v, U) (with `rates`, U carries extra first-order states). Every solver of the
    registry (solvers.SolverEntry.integrator) derives from it; a test checks that.

    State: t, x, v, U (the last step's end), nfev and n_steps (counters), max_step (the ceiling or the step).
    Stepping: advance(t_target) covers t_target; set_input(t, U) holds a new input from t on.
    Dense output: value_at(t) -> (x, v) and U_at(t) within the last step (a fixed-step solver: at its end only).
    Events (models.Event): a terminal event's zero raises terminal_event(...) (TerminalEvent, the run stops there);
    a non-terminal one's (the contact kink) ends a step there. The root search is the shared one: bernstein_search
    on the dense output (Dop853), the Hermite cubic of a step (Rk4, _hermite_event)."""

    events: tuple
    t: float
    x: float
    v: float
    nfev: int
    n_steps: int
    max_step: float

    @classmethod
    @abc.abstractmethod
    def from_settings(cls, accel, events, t0, x0, v0, U, settings, max_step, *, rates=None, phased=None,
                      step_budget=math.inf) -> "Integrator":
        """The solver of `settings` (plant.Settings) with the step ceiling or step max_step (SolverEntry.make)."""

    @abc.abstractmethod
    def set_input(self, t, U) -> None:
        """Input U holds from t on."""

    @abc.abstractmethod
    def advance(self, t_target) -> None:
        """Step until t_target is covered; TerminalEvent at a terminal event up to t_target, IntegrationError when
        the solver cannot go on."""

    @abc.abstractmethod
    def value_at(self, t) -> tuple[float, float]:
        """(x, v) at t within the last step (dense output)."""

    @abc.abstractmethod
    def U_at(self, t):
        """The input (or the extra states) at t within the last step."""

    @staticmethod
    def terminal_event(name: str, t: float, x: float, v: float) -> TerminalEvent:
        """The TerminalEvent of event `name` at (t, x, v), as every solver words it."""
        return TerminalEvent(f"{name} at tau = {t:.10g}, x = {x:.10g}", t, x, v)


class Dop853(Integrator):
    """Adaptive DOP853 with dense output and event location; restartable between doSteps.
    With `rates`, the input slot U carries extra first-order states (see the module docstring).

    Events must be affine in x (Event.affine): their zeros are located on the dense output without losing
    one (module comment at EVENT_MAX_DEPTH, docs/events.md)."""

    def __init__(self, accel, events, t0, x0, v0, U, rtol, max_step=math.inf, rates=None, step_budget=math.inf):
        for event in events:
            if event.affine is None:
                raise ValueError(f"Dop853 locates affine events only; {event.name!r} has no affine form")
        self.accel, self.events, self.rates = accel, events, rates
        self.rtol, self.atol, self.max_step = rtol, rtol * ATOL_PER_RTOL, max_step
        self.step_budget = step_budget  # most steps one advance may take
        self.nfev = 0
        self.n_steps = 0
        self._restart(t0, x0, v0, U)
        self.h = None  # chosen on the first step
        self.err_old = 0.0  # the last accepted step's error norm (the PI controller's memory; 0: none yet)

    @classmethod
    def from_settings(cls, accel, events, t0, x0, v0, U, settings, max_step, *, rates=None, phased=None,
                      step_budget=math.inf):
        """solvers.SolverEntry.make: rtol of the settings, max_step the ceiling (phased is not used)."""
        return cls(accel, events, t0, x0, v0, U, settings.rtol, max_step, rates=rates, step_budget=step_budget)

    # -- state ---------------------------------------------------------------------------------
    def _restart(self, t, x, v, U):
        """Start afresh at (t, x, v) with input U: a new derivative, no interpolant yet."""
        self.t, self.x, self.v, self.U = t, x, v, U
        self.a = self._f(t, x, v)
        self.dU = None if self.rates is None else self.rates(t, x, v, U)
        self.t_old = None
        self._dense = None
        self.stop = None  # (event name, t, x, v) once a terminal event is reached
        self.contact_side = {e.name: e.g(x) > 0.0 for e in self.events if not e.terminal}

    def _f(self, t, x, v):
        self.nfev += 1
        return self.accel(t, x, v, self.U)

    def set_input(self, t, U):
        """Input U holds from t on. If it changed, restart at t (read from the dense output if the
        integrator has stepped beyond t)."""
        if U == self.U:
            return
        x, v = self.value_at(t)
        self.U = U
        self._restart(t, x, v, U)

    # -- stepping ------------------------------------------------------------------------------
    def advance(self, t_target):
        """Step until t_target is covered (self.t >= t_target, maybe beyond it).

        Raises TerminalEvent if a terminal event lies at or before t_target, IntegrationError if the
        step size collapses, the state stops being finite or the step budget is spent.
        """
        steps = 0
        while self.t < t_target:
            if self.stop is not None:
                raise self.terminal_event(*self.stop)
            if steps >= self.step_budget:
                raise IntegrationError(f"{steps} steps reached only tau = {self.t:.10g} of {t_target:.10g}: "
                                       "make smaller communication steps", self.t, self.x, self.v)
            self._step()
            steps += 1
        if self.stop is not None and self.stop[1] <= t_target:
            raise self.terminal_event(*self.stop)

    def _step(self):
        t, x, v = self.t, self.x, self.v
        if self.h is None:
            self.h = self._initial_step()
        min_step = 10.0 * (math.nextafter(t, math.inf) - t)
        h = min(self.h, self.max_step)
        rejected = False
        while True:
            if not h >= min_step:
                raise IntegrationError(
                    f"step size collapsed to {h:.3g} at tau = {t:.10g}, x = {x:.10g} (stiff or singular)", t, x, v)
            x_new, v_new, stages, error = self._trial(t, x, v, h)
            if error < 1.0:
                factor = MAX_FACTOR if error == 0.0 else min(MAX_FACTOR, pi_factor(error, self.err_old))
                self.h = h * (min(1.0, factor) if rejected else factor)
                self.err_old = error
                break
            if not math.isfinite(error):
                h *= MIN_FACTOR
            else:
                h *= max(MIN_FACTOR, SAFETY * error**ERROR_EXPONENT)
            rejected = True
        self._accept(t, x, v, h, x_new, v_new, stages)
        self._handle_events(t, x, v)

    def _trial(self, t, x, v, h):
        """One DOP853 step of size h: new state, stages (kx, kv, kU), scaled error norm (inf on overflow).
        With extra states their new value is left in self.U_new."""
        stages = ([v], [self.a], [self.dU])
        try:
            x_new, v_new, self.U_new = self._run_stages(t, x, v, self.U, h, STAGES, stages)
        except (ArithmeticError, ValueError):  # a stage beyond a singularity: treat as a failed step
            self.nfev += len(stages[1])
            return x, v, stages, math.inf
        self.nfev += N_STAGES
        kx, kv, kU = stages
        sx = self.atol + self.rtol * max(abs(x), abs(x_new))
        sv = self.atol + self.rtol * max(abs(v), abs(v_new))
        e5 = _square(_dot(E5, kx) / sx) + _square(_dot(E5, kv) / sv)
        e3 = _square(_dot(E3, kx) / sx) + _square(_dot(E3, kv) / sv)
        n = 2
        if self.rates is not None:  # component by component, left to right (the C twin's order)
            sU = (self.atol + self.rtol * np.maximum(np.abs(self.U), np.abs(self.U_new))).tolist()
            for e, s in zip(_dot(E5, kU).tolist(), sU):
                e5 += _square(e / s)
            for e, s in zip(_dot(E3, kU).tolist(), sU):
                e3 += _square(e / s)
            n += len(sU)
        if not math.isfinite(e5 + e3):
            return x, v, stages, math.inf
        weight3 = 0.0 if self._near_kink(x, v, x_new, v_new, h) else 0.01  # the error norm's comment at ATOL_PER_RTOL
        if e5 == 0.0 and weight3 * e3 == 0.0:
            return x_new, v_new, stages, 0.0
        return x_new, v_new, stages, abs(h) * e5 / math.sqrt((e5 + weight3 * e3) * n)

    def _near_kink(self, x, v, x_new, v_new, h):
        """Whether a non-terminal event (a kink of the right-hand side) changes side over the step from (x, v) to
        (x_new, v_new), or lies within one step of its ends: |g| <= h max(|g'|) at the nearer end."""
        for event in self.events:
            if event.terminal:
                continue
            c0, cx = event.affine
            g0, g1 = c0 + cx * x, c0 + cx * x_new
            if (g0 > 0.0) != (g1 > 0.0) or min(abs(g0), abs(g1)) <= h * max(abs(cx * v), abs(cx * v_new)):
                return True
        return False

    def _run_stages(self, t, x, v, U0, h, nodes, stages):
        """Append the stages of `nodes` ((row of A, c) pairs) from (t, x, v, U0) with step h to
        stages = (kx, kv, kU); return the last stage's (x, v, U). kU is used only with extra states.
        A stage is appended once all its derivatives are evaluated."""
        accel, rates = self.accel, self.rates
        kx, kv, kU = stages
        U = U0
        dot = _tableau_dot  # the C twin's (core/dop853.c stages_of)
        for row, c in nodes:
            ts = t + c * h
            xs = x + h * dot(row, kx)
            vs = v + h * dot(row, kv)
            if rates is not None:
                U = U0 + h * dot(row, kU)
                dU = rates(ts, xs, vs, U)
            a = accel(ts, xs, vs, U)
            if rates is not None:
                kU.append(dU)
            kx.append(vs)
            kv.append(a)
        return xs, vs, U

    def _accept(self, t, x, v, h, x_new, v_new, stages):
        self.t_old, self.x_old, self.v_old, self.a_old = t, x, v, self.a
        self.U_old, self.dU_old = self.U, self.dU
        self._stages = stages
        self._dense = None
        self.t, self.x, self.v, self.a = t + h, x_new, v_new, stages[1][-1]
        if self.rates is not None:
            self.U, self.dU = self.U_new, stages[2][-1]
        self.n_steps += 1

    def _initial_step(self):
        """Hairer's starting step (scipy's select_initial_step), over all components (x, v, extra states)."""
        t, x, v, a = self.t, self.x, self.v, self.a
        y0, f0 = [x, v], [v, a]
        if self.rates is not None:
            y0 += self.U.tolist()
            f0 += self.dU.tolist()
        n = len(y0)
        scale = [self.atol + abs(y) * self.rtol for y in y0]
        d0 = _norm([y / s for y, s in zip(y0, scale)]) / math.sqrt(n)
        d1 = _norm([f / s for f, s in zip(f0, scale)]) / math.sqrt(n)
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, self.max_step)
        y1 = [y + h0 * f for y, f in zip(y0, f0)]
        if self.rates is None:
            f1 = [y1[1], self._f(t + h0, y1[0], y1[1])]
        else:
            U1 = np.array(y1[2:])
            dU1 = self.rates(t + h0, y1[0], y1[1], U1)
            self.nfev += 1
            f1 = [y1[1], self.accel(t + h0, y1[0], y1[1], U1)] + dU1.tolist()
        d2 = _norm([(g - f) / s for g, f, s in zip(f1, f0, scale)]) / math.sqrt(n) / h0
        h1 = max(1e-6, h0 * 1e-3) if max(d1, d2) <= 1e-15 else (0.01 / max(d1, d2)) ** (1.0 / 9.0)
        return min(100.0 * h0, h1, self.max_step)

    # -- events --------------------------------------------------------------------------------
    def _handle_events(self, t0, x0, v0):
        """Find the earliest zero of an event in the last step (zeros of excursions that begin and end inside
        the step included); cut the step there (redo it with the exact length, so no step straddles the
        event). A contact event's state then lies on its new side (moved there if the redone step ends a
        rounding short), and the side flips; a terminal event stops the run. A redone step that fails the error
        test is replaced by a shorter one (_shorten) and the event is left to the next step."""
        earliest = None
        for event in self.events:
            t_event = self._first_zero(event)
            if t_event is not None and (earliest is None or t_event < earliest[0]):
                earliest = (t_event, event)
        if earliest is None:
            return
        t_event, event = earliest
        h = t_event - t0
        self.t, self.x, self.v, self.a = t0, x0, v0, self.a_old
        self.U, self.dU = self.U_old, self.dU_old
        if h > 0.0:
            x_new, v_new, stages, error = self._trial(t0, x0, v0, h)
            if not error < 1.0:
                self._shorten(t0, x0, v0, h, error)
                return
            self._accept(t0, x0, v0, h, x_new, v_new, stages)
        else:  # the event is at the step's start: the step is undone
            self.t_old = None
            self._dense = None
        if event.terminal:
            self.stop = (event.name, self.t, self.x, self.v)
            return
        side = not self.contact_side[event.name]
        if (event.g(self.x) > 0.0) != side:
            self._move_to_side(event, side)
        self.contact_side[event.name] = side

    def _shorten(self, t0, x0, v0, h, error):
        """The step cut at an event fails its error test (the contact force's higher derivatives are singular at
        the event): an error-controlled shorter step is taken instead, which ends before the event; the next step
        meets the event again."""
        min_step = 10.0 * (math.nextafter(t0, math.inf) - t0)
        while True:
            h *= MIN_FACTOR if not math.isfinite(error) else max(MIN_FACTOR, SAFETY * error**ERROR_EXPONENT)
            if not h >= min_step:
                raise IntegrationError(
                    f"step size collapsed to {h:.3g} at tau = {t0:.10g}, x = {x0:.10g} (stiff or singular)", t0, x0, v0)
            x_new, v_new, stages, error = self._trial(t0, x0, v0, h)
            if error < 1.0:
                break
        self._accept(t0, x0, v0, h, x_new, v_new, stages)
        self.h = min(self.h, h)

    def _move_to_side(self, event, side):
        """Put x on the event's zero and then, ulp by ulp, on its side `side` (g > 0 or not); a new derivative.
        The move is within the redone step's error (it ended within it of the located zero)."""
        c0, cx = event.affine
        x = -c0 / cx
        direction = math.inf if (cx > 0.0) == side else -math.inf
        for _ in range(8):
            if (c0 + cx * x > 0.0) == side:
                break
            x = math.nextafter(x, direction)
        self.x = x
        if self.rates is not None:  # rates before accel (closedloop reuses the stage's control)
            self.dU = self.rates(self.t, self.x, self.v, self.U)
        self.a = self._f(self.t, self.x, self.v)
        self._dense = None

    def _first_zero(self, event):
        """The earliest time in the last step where the event is reached on the dense output (terminal: g <= 0;
        contact: g on the other side than contact_side), or None."""
        c0, cx = event.affine
        positive = True if event.terminal else self.contact_side[event.name]  # the side the step starts on

        def beyond(g):
            return (not g > 0.0) if positive else g > 0.0

        g0, g1 = c0 + cx * self.x_old, c0 + cx * self.x
        if beyond(g0):
            return self.t_old
        h = self.t - self.t_old
        if not beyond(g1):
            reach = EVENT_SCREEN * (abs(g1 - g0) + h * (abs(cx * self.v_old) + abs(cx * self.v)))
            if abs(g0) > reach and abs(g1) > reach:
                return None
        _, (fx, _, _) = self._interpolant(self.t_old)
        G = [0.0 + cx * f for f in fx]  # the dense output's coefficients of g - g0
        b = [g0 + _dot(G, [row[k] for row in BERNSTEIN]) for k in range(8)]
        scale = abs(c0) + abs(cx * self.x_old)  # the magnitudes b and g's evaluation round against
        for term in G:
            scale += abs(term)

        def time(s):  # the step's ends exactly
            return self.t if s == 1.0 else self.t_old if s == 0.0 else self.t_old + s * h

        piece = bernstein_search(b, positive, lambda s: beyond(c0 + cx * self.value_at(time(s))[0]),
                                  EVENT_ROUNDING * scale)
        if piece is None:
            return None
        s_a, s_b, at_start = piece
        return time(s_a) if at_start else self._locate(event, time(s_a), time(s_b))  # one zero: g monotone there

    def _locate(self, event, t_a, t_b):
        """Zero of g(x(t)) on the dense output in [t_a, t_b], where g changes side."""
        from scipy.optimize import brentq  # lazily: only the pure-Python path needs it, and only at an event

        g = event.g
        return brentq(lambda tt: g(self.value_at(tt)[0]), t_a, t_b, xtol=1e-15, rtol=1e-15)

    # -- dense output --------------------------------------------------------------------------
    def value_at(self, t):
        """(x, v) at t in [t_old, t] of the last step (7th-order interpolant)."""
        if t == self.t:
            return self.x, self.v
        s, (fx, fv, _) = self._interpolant(t)
        return self.x_old + _evaluate(fx, s), self.v_old + _evaluate(fv, s)

    def U_at(self, t):
        """The extra states (or the held input) at t in [t_old, t] of the last step."""
        if t == self.t or self.rates is None:
            return self.U
        s, (_, _, fU) = self._interpolant(t)
        return self.U_old + _evaluate(fU, s)

    def _interpolant(self, t):
        """(fraction of the last step at t, dense-output coefficients of x, v and the extra states)."""
        if self.t_old is None or not (self.t_old <= t <= self.t):
            raise ValueError(f"tau = {t} is outside the last step [{self.t_old}, {self.t}]")
        if self._dense is None:
            self._dense = self._build_dense()
        return (t - self.t_old) / (self.t - self.t_old), self._dense

    def _build_dense(self):
        """Coefficients F of scipy's Dop853DenseOutput, from three extra stages."""
        stages = tuple(list(k) for k in self._stages)
        t, x, v, h = self.t_old, self.x_old, self.v_old, self.t - self.t_old
        self._run_stages(t, x, v, self.U_old, h, EXTRA_STAGES, stages)
        self.nfev += len(EXTRA_STAGES)
        kx, kv, kU = stages
        components = [(x, self.x, v, self.v, kx), (v, self.v, self.a_old, self.a, kv)]
        if self.rates is not None:
            components.append((self.U_old, self.U, self.dU_old, self.dU, kU))
        dense = [None, None, None]
        for i, (y_old, y_new, f_old, f_new, k) in enumerate(components):
            dy = y_new - y_old
            dense[i] = [dy, h * f_old - dy, 2.0 * dy - h * (f_new + f_old)] + [h * _dot(row, k) for row in D]
        return dense


def pi_factor(error, err_old):
    """The PI controller's step factor after an accepted step of error norm `error` (> 0, finite) that followed one
    of error norm err_old (comment at PI_BETA; core/dop853.c pi_factor); err_old <= 0: none (the first step, or one
    after an error of 0), whose memory term is 1."""
    memory = max(err_old, PI_ERROR_FLOOR)**PI_BETA if err_old > 0.0 else 1.0
    return SAFETY * error**-PI_ALPHA * memory


def _evaluate(coefficients, s):
    """Dense output increment y(s) - y_old at the fraction s of the step (scipy's Dop853DenseOutput)."""
    y = 0.0
    n = len(coefficients)
    for i in range(n - 1, -1, -1):
        y += coefficients[i]
        y *= s if (n - 1 - i) % 2 == 0 else 1.0 - s
    return y


def rk4_drive_gains(theta: float) -> tuple[float, float]:
    """(G_x, G_v): RK4's response to a fast drive f(t) = e^(i nu t) over the true response; theta = nu h.

    For a drive that does not depend on the state, one RK4 step adds h (f_0 + 4 f_1/2 + f_1)/6 to v (Simpson's
    rule) and h v + h^2 (f_0 + 2 f_1/2)/6 to x. Well above the oscillator's own frequency the drive's ripple is
    x_p = -f/nu^2, v_p = f/(i nu); RK4's discrete particular solution x_n = X e^(i theta n), v_n = V e^(i theta n)
    of those updates, over the exact one, is (phi = theta/2)
        G_x = theta^2 (1 + 2 cos phi) / (12 sin^2 phi) = 1 - theta^4/960 + ...
        G_v = theta (2 + cos phi) / (6 sin phi)       = 1 + theta^4/2880 + ...
    Both are real: RK4 keeps the ripple's phase and gets its amplitude wrong. G_x vanishes at theta = 4 pi/3
    (RK4 sees no ripple at all) and both diverge at theta = 2 pi, where every stage samples the drive at the
    same phase (a resonance of the discrete scheme): inf there.
    """
    phi = 0.5 * theta
    s = math.sin(phi)
    if theta == 0.0:
        return 1.0, 1.0
    if abs(s) < 1e-300:
        return math.inf, math.inf
    return theta * theta * (1.0 + 2.0 * math.cos(phi)) / (12.0 * s * s), theta * (2.0 + math.cos(phi)) / (6.0 * s)


# A drive term of angular frequency nu is resolved by RK4 steps h with nu h <= RK4_DRIVE_THETA: there RK4's
# ripple of x (the worse of the two, G_x) is within RK4_DRIVE_ERROR = 1 % of the true one, i.e. at least
# 2 pi/1.696 = 3.7 steps per period of the drive. Beyond it the error grows as theta^4/960 and faster: 6 % at
# theta = 2.5, 73 % at theta = 4 (the gamma cos(2 Omega t) term at Omega = 200 under the default step 0.01).
# The ripple itself is small (beta/Omega^2), but RK4's error at such a step is then dominated by it, far above
# RK4's error on the slow motion (extremes.py measures 230 times at Omega = 200, h = 0.01, tau <= 10).
RK4_DRIVE_ERROR = 0.01


def _rk4_drive_theta() -> float:
    """theta in [0.5, 3] where G_x = 1 - RK4_DRIVE_ERROR (G_x falls monotonically there), by bisection to round-off
    (no scipy at import, see _dop853_coefficients)."""
    low, high = 0.5, 3.0
    while True:
        middle = 0.5 * (low + high)
        if middle in (low, high):
            return low
        low, high = (middle, high) if 1.0 - rk4_drive_gains(middle)[0] < RK4_DRIVE_ERROR else (low, middle)


RK4_DRIVE_THETA = _rk4_drive_theta()  # 1.696...


def _hermite_event(event, t, x, v, h, x_new, v_new):
    """(t, x, v) of the first point where a terminal event is reached (g <= 0) on the cubic Hermite interpolant of a
    fixed step from (x, v) to (x_new, v_new), or None. For an affine event (all the models' events) excursions that
    begin and end inside the step are found as in Dop853._first_zero: the cubic's Bernstein coefficients (its
    control points) bound g on a piece; for another one only a sign change at the step's end is seen.

    RK4 has no dense output; this cubic is accurate to O(h^4) on a resolved step. Without it a terminal event
    would be reported at the step's end, which near pull-in can lie beyond the electrode (x > 3R/2)."""
    def state(s):
        s2, s3 = s * s, s * s * s
        xs = (2 * s3 - 3 * s2 + 1) * x + (s3 - 2 * s2 + s) * h * v + (3 * s2 - 2 * s3) * x_new + (s3 - s2) * h * v_new
        vs = ((6 * s2 - 6 * s) * (x - x_new) / h + (3 * s2 - 4 * s + 1) * v + (3 * s2 - 2 * s) * v_new)
        return xs, vs

    g = event.g
    if not g(x) > 0.0:  # already on the event at the step's start
        return t, x, v
    from scipy.optimize import brentq  # lazily, as in Dop853._locate

    if event.affine is None:  # no bound on g: only a sign change at the step's end is seen
        if g(x_new) > 0.0:
            return None
        s = brentq(lambda s: g(state(s)[0]), 0.0, 1.0, xtol=1e-15, rtol=1e-15)
        return (t + s * h, *state(s))
    c0, cx = event.affine
    b = [c0 + cx * x, c0 + cx * (x + h * v / 3.0), c0 + cx * (x_new - h * v_new / 3.0), c0 + cx * x_new]
    if min(b) > 0.0:  # the search's first verdict, without it (the C twin's fast exit of most steps)
        return None
    scale = abs(c0) + abs(cx) * (abs(x) + abs(x_new) + abs(h * v) + abs(h * v_new))  # what b and g round against
    piece = bernstein_search(b, True, lambda s: not g(state(s)[0]) > 0.0, EVENT_ROUNDING * scale)
    if piece is None:
        return None
    s_a, s_b, at_start = piece
    s = s_a if at_start else brentq(lambda s: g(state(s)[0]), s_a, s_b, xtol=1e-15, rtol=1e-15)
    return (t + s * h, *state(s))


def _rk4_growth(zr, zi):
    """|R(z)| of RK4's amplification R(z) = 1 + z (1 + z (1/2 + z (1/6 + z/24))), z = zr + i zi, in real
    arithmetic (the C twin's order)."""
    pr, pi = 1.0 / 6.0 + zr / 24.0, zi / 24.0
    pr, pi = 0.5 + (zr * pr - zi * pi), zr * pi + zi * pr
    pr, pi = 1.0 + (zr * pr - zi * pi), zr * pi + zi * pr
    pr, pi = 1.0 + (zr * pr - zi * pi), zr * pi + zi * pr
    return math.hypot(pr, pi)


def _square(q):
    """q * q, raising OverflowError where it overflows from a finite q, as q ** 2 does (core/pyfloat.h py_square;
    one product instead of pow, which libm need not round as the product)."""
    square = q * q
    if square == math.inf and abs(q) != math.inf:
        raise OverflowError(errno.ERANGE, os.strerror(errno.ERANGE))
    return square


PHASE_RESYNC = 16  # RK4 steps between two direct evaluations of the drive's phasors (core/rk4.h)


def _phases_at(frequencies, t):
    """[cos f0 t, sin f0 t, cos f1 t, sin f1 t, ...] directly."""
    phases = []
    for f in frequencies:
        angle = f * t
        phases += (math.cos(angle), math.sin(angle))
    return phases


def _rotate(phases, rotation):
    """Each phasor (c, s) turned by the angle whose (cos, sin) is in `rotation`: angle addition."""
    out = []
    for k in range(0, len(phases), 2):
        c, s, rc, rs = phases[k], phases[k + 1], rotation[k], rotation[k + 1]
        out += (c * rc - s * rs, s * rc + c * rs)
    return out


class Rk4(Integrator):
    """Fixed-step classic Runge-Kutta 4; steps end exactly on the communication points.
    With `rates`, the input slot U carries extra first-order states (see the module docstring).

    With `phased = (frequencies, accel_phased)`, accel's time dependence is cos and sin of f t for f in
    frequencies, and the steps call accel_phased(t, phases, x, v, U) with phases = [cos f0 t, sin f0 t, ...]:
    evaluated directly at an advance's start and every PHASE_RESYNC steps, in between each stage's from the
    previous one's by a rotation through f h/2 (stages 2 and 3 share t + h/2). Three trigonometric calls per
    stage become a few multiplications; the phasors differ from direct evaluation by rounding only (a few ulps
    per rotation; the direct evaluation's own argument f t carries an error of ulp(f t), which is larger for
    t >= 1)."""

    def __init__(self, accel, events, t0, x0, v0, U, max_step, rates=None, phased=None):
        self.accel, self.events, self.max_step, self.rates = accel, events, max_step, rates
        self.t, self.x, self.v, self.U = t0, x0, v0, U
        self.nfev = 0
        self.n_steps = 0
        self.phased = phased
        self._phases = self._rotation = None
        self._since_anchor = -1

    @classmethod
    def from_settings(cls, accel, events, t0, x0, v0, U, settings, max_step, *, rates=None, phased=None,
                      step_budget=math.inf):
        """solvers.SolverEntry.make: steps of max_step (the step budget is not used: the step count is set)."""
        return cls(accel, events, t0, x0, v0, U, max_step, rates=rates, phased=phased)

    def set_input(self, t, U):
        self.U = U

    def advance(self, t_target):
        """Integrate to exactly t_target in equal steps <= max_step."""
        span = t_target - self.t
        if span <= 0.0:
            return
        n = max(1, math.ceil(span / self.max_step * (1.0 - 1e-12)))
        h = span / n
        self._check_stability(h)
        t0 = self.t
        self._since_anchor = -1  # the phasors and rotations are evaluated directly at the first step
        for i in range(1, n + 1):
            self._step(h)
            self.t = t_target if i == n else t0 + i * h

    def _check_stability(self, h):
        """Refuse a step for which RK4 is unstable on the local linearisation x'' = -k x - c x'.

        Eigenvalues lambda of [[0, 1], [-k, -c]] with Re(lambda) <= 0 (physically stable) must give
        |R(h lambda)| <= 1, R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24, or RK4 would blow up (a NaN or a
        spurious pull-in instead of an honest error).
        """
        f, U, t, x, v = self.accel, self.U, self.t, self.x, self.v
        dx, dv = 1e-6 * max(1.0, abs(x)), 1e-6 * max(1.0, abs(v))
        try:
            k = -(f(t, x + dx, v, U) - f(t, x - dx, v, U)) / (2.0 * dx)
            c = -(f(t, x, v + dv, U) - f(t, x, v - dv, U)) / (2.0 * dv)
        except (ArithmeticError, ValueError):
            return
        self.nfev += 4
        disc, half = c * c / 4.0 - k, -c / 2.0
        if disc >= 0.0:
            root = math.sqrt(disc)
            eigenvalues = ((half + root, 0.0), (half - root, 0.0))
        else:  # a complex pair: the conjugate has the same |R|
            eigenvalues = ((half, math.sqrt(-disc)),)
        for re, im in eigenvalues:
            zr, zi = h * re, h * im
            if re <= 0.0 and _rk4_growth(zr, zi) > 1.0 + 1e-12:
                size = math.hypot(re, im)
                raise IntegrationError(
                    f"RK4 unstable: step h = {h:.3g} at tau = {t:.10g} gives h*lambda = {zr:.3g}{zi:+.3g}j outside the "
                    f"stability region (|lambda| = {size:.3g}); reduce max_step below {2.5 / size:.3g}", t, x, v)

    def _step(self, h):
        if self.phased is not None:
            return self._step_phased(h)
        f, rates, U, t, x, v = self.accel, self.rates, self.U, self.t, self.x, self.v
        half = 0.5 * h
        try:
            # each stage: the extra states' rates (if any) before accel, which may reuse what rates computed
            U2 = U if rates is None else U + half * (d1 := rates(t, x, v, U))
            a1 = f(t, x, v, U)
            x2, v2 = x + half * v, v + half * a1
            U3 = U if rates is None else U + half * (d2 := rates(t + half, x2, v2, U2))
            a2 = f(t + half, x2, v2, U2)
            x3, v3 = x + half * v2, v + half * a2
            U4 = U if rates is None else U + h * (d3 := rates(t + half, x3, v3, U3))
            a3 = f(t + half, x3, v3, U3)
            x4, v4 = x + h * v3, v + h * a3
            if rates is not None:
                U_new = U + h / 6.0 * (d1 + 2.0 * d2 + 2.0 * d3 + rates(t + h, x4, v4, U4))
            a4 = f(t + h, x4, v4, U4)
        except (ArithmeticError, ValueError):
            raise IntegrationError(
                f"RK4 step h = {h:.3g} from tau = {t:.10g} left the model's domain (x = {x:.10g}); "
                f"reduce max_step", t, x, v) from None
        self._finish(h, t, x, v, x + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4),
                     v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4), U_new if rates is not None else None)

    def _step_phased(self, h):
        """_step without rates, accel_phased with each stage's phasors (see the class docstring)."""
        frequencies, f = self.phased
        U, t, x, v = self.U, self.t, self.x, self.v
        half = 0.5 * h
        try:
            if self._since_anchor < 0 or self._since_anchor >= PHASE_RESYNC:
                if self._since_anchor < 0:
                    self._rotation = _phases_at(frequencies, half)
                self._phases = _phases_at(frequencies, t)
                self._since_anchor = 0
            p1 = self._phases
            p2 = _rotate(p1, self._rotation)
            p4 = _rotate(p2, self._rotation)
            a1 = f(t, p1, x, v, U)
            x2, v2 = x + half * v, v + half * a1
            a2 = f(t + half, p2, x2, v2, U)
            x3, v3 = x + half * v2, v + half * a2
            a3 = f(t + half, p2, x3, v3, U)
            x4, v4 = x + h * v3, v + h * a3
            a4 = f(t + h, p4, x4, v4, U)
        except (ArithmeticError, ValueError):
            raise IntegrationError(
                f"RK4 step h = {h:.3g} from tau = {t:.10g} left the model's domain (x = {x:.10g}); "
                f"reduce max_step", t, x, v) from None
        self._finish(h, t, x, v, x + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4),
                     v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4), None)
        self._phases = p4  # the next step starts from this one's end
        self._since_anchor += 1

    def _finish(self, h, t, x, v, x_new, v_new, U_new):
        """The end of a step: finiteness, terminal events on the step's cubic, the new state."""
        self.nfev += 4
        if not (math.isfinite(x_new) and math.isfinite(v_new)):
            raise IntegrationError(
                f"RK4 unstable: the state became non-finite after tau = {t:.10g} with h = {h:.3g}; "
                f"reduce max_step", t, x, v)
        for event in self.events:
            if event.terminal:
                hit = _hermite_event(event, t, x, v, h, x_new, v_new)
                if hit is not None:
                    raise self.terminal_event(event.name, *hit)
        self.x, self.v = x_new, v_new
        if U_new is not None:
            self.U = U_new
        self.n_steps += 1

    def value_at(self, t):
        self._require_current(t)
        return self.x, self.v

    def U_at(self, t):
        self._require_current(t)
        return self.U

    def _require_current(self, t):
        if t != self.t:
            raise ValueError(f"RK4 holds only tau = {self.t}, not {t}")
