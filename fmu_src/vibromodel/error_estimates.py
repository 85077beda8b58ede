"""Error estimates of the rungs: an estimate of max|x - x_exact| over a run, from each rung's own theory, with a
constant calibrated against the exact model (`vibrofmu.analyses.error_calibration`, docs/rungs.md, Error estimates).

Fidelity 3 (the averaged slow flow, docs/model.md, Averaging and slow flow): whatever first-order averaging leaves
out (the fast AC response psi's assumption Omega >> sqrt(k1), the free vibration's phase drift, the terms averaging
drops from the slow equations, the higher harmonics, the parametric pumping) shows in the residual R = x~'' -
accel(x~, x~') of Eq. 3 on the reconstructed x~. The start state matches (x_start, v_start) exactly, so the error
e obeys, linearized about x_e, e'' + mu e' + k1 e = -R with e(0) = e'(0) = 0: the estimate is max|e| (R sampled
over the run from the slow flow's table, as fidelity 4's below) times a calibrated factor. (Its former sum of the
neglected terms' amplitudes was 0.11-31 times the measured error, ~11 on the paper scene; the propagated residual
is 0.45-2.2 times it, 1.00 on the paper scene.)

Fidelity 4 (OAFM): the residual R of Eq. 3 on the fitted x~. Linearized, an error e obeys L[e] = -R with
L = d^2/dt^2 + mu d/dt + a1 and e(0) = e'(0) = 0 (x~ starts at the scene's start): the estimate is max|e| of that
equation driven by R sampled over the run (propagated_residual), times a calibrated factor. (max|R|/a1, the off-
resonance gain alone, was 1-1000 times the measured error; the resonant gain 1/(mu p) 100-10,000 times.)

The integrated rungs (solver_terms, truncation_terms) sum over the linear response's parts (response_parts): each
error injected at a frequency s adds up over the time the response remembers it at that frequency.

Each level's estimator is its registry entry's `error_estimate` (fidelities.py); make_plant attaches the result to
the plant (`attach`). A rung whose estimate exceeds its entry's `warn_share` of the amplitude adds an fmi2Warning
naming the estimate and the rung to use; a rung that cannot estimate (non-finite) warns likewise.
"""
from __future__ import annotations

import math
import operator

import numpy as np

from . import forces
from .models import MIN_RTOL, drive_step_ceiling, tolerance_factor
from .solvers import FIXED_DEFAULT_STEP, solver_entry

# Calibrated constants (vibrofmu.analyses.error_calibration; docs/rungs.md, Error estimates): each rung's estimate
# is CALIBRATION[kind] times its theoretical terms, chosen on campaigns of 300-400 scenes (seed 11) so that the
# estimate bounds the measured error in >= 99 % of them with the least over-estimate, then checked on 1,000 others
# (seed 7): averaged 2 (its propagated residual, the linearized error: the measured error over it was 0.44-2.24 on
# 398 scenes of seed 11, median 1.00, 99th percentile 1.13; the scenes above 1.5, four, erred by 3-50 % of their
# amplitude, where the linearization about x_e is weakest), analytic 3 (the propagated residual is the linearized
# error: 0.9-1.1 times the measured one on four test scenes, and the non-linear terms add to it); fixed 2 (RK4:
# 0.44-186 times); truncation 1. DOP853 (solver_terms, its step model above DOP853_ESTIMATOR): adaptive 5 on the
# accumulated local errors, the I controller's 2 carried to the controller's explicit target (its model asked the
# estimator for rtol where that controller kept 0.43 rtol, and the accumulated term grows as the target^(9/8):
# 2 / 0.43^(9/8) = 5.2), and local 130 on the estimator's size per step, calibrated on 400 scenes of each of the
# exact model (rtol 1e-10 ... 1e-3) and fidelities 1 and 2 (seed 11): 116 is the least that bounds 99.0 % of the
# exact model's, 130 bounds 99.2 % (the local term is most of the estimate: the step's estimator is what the
# controller holds, whatever the part; the errors it misses are the non-linear terms' -- the contact force's
# harmonics, the drive's products with x -- which the linear response has not).
CALIBRATION = {"averaged": 2.0, "analytic": 3.0, "adaptive": 5.0, "local": 130.0, "fixed": 2.0, "truncation": 1.0}
# An approximate rung warns when its estimate exceeds its share of the run's amplitude max|x| (the registry's
# FidelityEntry.warn_share): fidelity 3 AVERAGED_WARN_SHARE, the acceptance's 5 % itself (its estimate bounds its
# measured error, about twice it: a scene it does not warn is within 5 % of the amplitude, as every cell of the
# slow-AC grid that is not warned must be: tests/fmus/test_error_estimates.py; the paper scene's 1e-3 of 0.04 is
# not warned), fidelity 4 analytic.FIT_WARN; above its refuse_share (fidelity 4:
# analytic.FIT_REFUSE) or not finite, the rung refuses the scene (ParameterError naming `fidelity`).
AVERAGED_WARN_SHARE = 0.05


def linear_gain(k1: float, mu: float, s: float) -> complex:
    """H(s) = 1/(k1 - s^2 + i mu s): the steady phasor of y'' + mu y' + k1 y = e^(i s t)."""
    return 1.0 / complex(k1 - s * s, mu * s)


def averaged_terms(model, solution, span: float) -> dict:
    """The terms of fidelity 3's estimate (module docstring), x units, for an averaged model (averaging.Averaged)
    and its slow-flow solution (slowflow.SlowFlowSolution) over a run of `span` from its start (at most the table's
    end): the residual R of Eq. 3 on the reconstructed x~ propagated through the linear operator at x_e
    (propagated_residual's equation with a1 = k1), max|R| and the amplitude |x_e| + max r of the slow flow."""
    s = model.scene
    mu, k1 = s.mu, model.eq.k[1]
    cells = solution.cell_array()
    horizon = max(1, min(len(cells), math.ceil(span / solution.spacing))) if len(cells) else 0
    r_max = float(np.max(np.hypot(cells[:horizon, 0], cells[:horizon, 4]))) if horizon else 0.0
    span = min(span, solution.t_end - solution.t0)
    p = math.sqrt(k1 - 0.25 * mu * mu)  # ValueError (no estimate) for an overdamped k1 <= mu^2/4
    fastest = max(2.0 * solution.omega, 2.0 * s.Omega if solution.ac else 0.0, p)  # x~'s second harmonics, psi's
    n = int(min(RESIDUAL_SAMPLES, max(2, math.ceil(span * fastest / RESIDUAL_STEP_TURN) + 1)))
    on_kernel = solution.residual_terms(s, span, n, mu, k1) if getattr(solution, "kernel", False) else None
    if on_kernel is not None:  # the same samples in C (core/slowflow_table.c: vk_slowflow_residual)
        propagated, largest = on_kernel
    else:
        tau = solution.t0 + np.linspace(0.0, span, n)
        x, v, a = solution.states(tau, cells)
        residual = exact_accel(s, tau, x, v) - a
        propagated = float(np.max(np.abs(linear_response(residual, span / (n - 1), mu, k1))))
        largest = float(np.max(np.abs(residual)))
    return {"propagated": propagated, "residual": largest, "amplitude": abs(model.eq.x_e) + r_max}


def averaged_estimate(model, solution, span: float) -> tuple[float, dict]:
    """(fidelity 3's estimate of max|x - x_exact| over the run, its terms)."""
    terms = averaged_terms(model, solution, span)
    return CALIBRATION["averaged"] * terms["propagated"], terms


# Fidelity 3's pre-check (averaged_floor; fidelity auto asks it before building the rung, auto.choose): the share of
# its leading term that the estimate is taken to exceed. Measured over 3,000 scenes of the auto campaign's generator
# (vibrofmu.analyses.error_calibration.random_scene, seed 1): estimate / (CALIBRATION["averaged"] x the term) was
# 0.58-5 (1st percentile 0.85, median 1.03): the term is most of the estimate; the least (0.58) where the other
# parts of the residual (the amplitude's own frequency shift at r ~ 0.5, the AC drive's products) partly cancel it
# at its peak. A tenth keeps a factor >= 5 below every scene measured (tests/model/test_auto.py checks 2,000 others).
AVERAGED_FLOOR_SHARE = 0.1


def averaged_floor(model, t0: float, span: float) -> float:
    """A floor of fidelity 3's estimate (averaged_estimate) over a run of `span` from t0, from its averaged model
    alone (averaging.Averaged: no slow-flow solution, no table): AVERAGED_FLOOR_SHARE of its leading term, so that
    the estimate is above it (checked over random scenes: tests/model/test_auto.py); inf where the estimate cannot
    be made (k1 <= mu^2/4: averaged_terms' ValueError, a nan estimate). Fidelity auto passes the rung over unbuilt
    when the floor exceeds the tolerance.

    The leading term is the slow flow's frequency error. Linear in (A, B), the slow flow's free part (the start's
    slow state minus the drive's steady point) turns as e^((-mu/2 + i nu) t) with nu = (omega^2 - k1)/(2 omega), so
    in x it is a free vibration at Omega_f = omega - nu = (omega^2 + k1)/(2 omega), decaying at mu/2. The linear
    operator the estimate propagates through, L = d^2 + mu d + k1 (averaged_terms), turns its free vibration at
    p = sqrt(k1 - mu^2/4); so that part leaves the residual R = (p^2 - Omega_f^2) y_f, and the error e it drives
    (L e = -R, e(0) = e'(0) = 0) is the difference of the two free vibrations from the same start, exactly:
    |e| = 2 r_f e^(-mu t/2) |sin(d t/2)| at the peaks of its fast factor, d = |Omega_f - p| >= (omega - omega_e)^2/
    (2 omega) (it turns wrong even at resonance once mu is not small: p < omega_e). Its largest value over the first
    lobe, at t* = (2/d) atan(d/mu), clipped to the run, is the term (the backbone's shift kappa(r) turns both alike to
    this order: the residual's first harmonic of the nonlinear force cancels it). The run is taken at most
    slowflow.CHUNK long: the estimate covers the set-up's table, at least that long (a bounded table may hold less
    than the run). The start's slow state is van der Pol's first-order one (slowflow's start iteration begins
    there; its second-order terms, ~k2 r/(6 k1) of r, are within the share)."""
    from .slowflow import CHUNK

    s = model.scene
    mu, k1, w = s.mu, model.eq.k[1], s.omega
    if not k1 > 0.25 * mu * mu:
        return math.inf
    p = math.sqrt(k1 - 0.25 * mu * mu)
    nu, drive = (w * w - k1) / (2.0 * w), s.Delta / (2.0 * w)
    psi = dpsi = 0.0
    if s.beta != 0.0 or s.gamma != 0.0:  # psi = P sin(Omega t) + Q cos(2 Omega t), Eq. 46 (slowflow)
        P, Q, W = -s.beta / s.Omega ** 2, s.gamma / (4.0 * s.Omega ** 2), s.Omega
        psi = P * math.sin(W * t0) + Q * math.cos(2.0 * W * t0)
        dpsi = W * (P * math.cos(W * t0) - 2.0 * Q * math.sin(2.0 * W * t0))
    y, u = s.x_start - model.eq.x_e - psi, (s.v_start - dpsi) / w  # y = A cos + B sin, y'/w = -A sin + B cos
    c, sn = math.cos(w * t0), math.sin(w * t0)
    A, B = y * c - u * sn, y * sn + u * c
    rate = nu * nu + 0.25 * mu * mu  # the steady point: A' = B' = 0 of the linear slow flow
    if not rate > 0.0:
        return 0.0  # undamped at resonance: no steady point (no floor claimed)
    r_free = math.hypot(A + nu * drive / rate, B - 0.5 * mu * drive / rate)
    d = abs(w - nu - p)
    horizon = min(span, CHUNK)
    if not (d > 0.0 and horizon > 0.0 and r_free > 0.0):
        return 0.0
    t = min(2.0 / d * math.atan2(d, mu), horizon)
    term = 2.0 * r_free * math.exp(-0.5 * mu * t) * abs(math.sin(0.5 * d * t))
    return AVERAGED_FLOOR_SHARE * CALIBRATION["averaged"] * term


# The residual's samples for fidelity 4's propagation: a step turns the fastest term of x~ (or the free vibration) by
# at most RESIDUAL_STEP_TURN radians (the piecewise-linear R then errs by ~1 % of its size); at most RESIDUAL_SAMPLES
# samples (a run of 2000 at frequency 4: 16,000).
RESIDUAL_STEP_TURN = 0.5
RESIDUAL_SAMPLES = 20000


def propagated_residual(scene, solution, span: float) -> float:
    """max|e| over the run of e'' + mu e' + a1 e = -R, e(0) = e'(0) = 0: the error the residual R of Eq. 3 on x~
    drives through Eq. 11's linear operator (module docstring). R is sampled on the run and taken piecewise linear;
    e = Im(z)/p with z' = lambda z - R, lambda = -mu/2 + i p, advanced exactly between samples (one linear
    recurrence, scipy.signal.lfilter)."""
    from .oafm_bases import eq11_operator

    mu, a1 = scene.mu, eq11_operator(scene).k
    p = math.sqrt(a1 - 0.25 * mu * mu)  # eq11_operator refuses a1 <= mu^2/4
    fastest = max(solution.fastest_frequency(), p)
    n = int(min(RESIDUAL_SAMPLES, max(2, math.ceil(span * fastest / RESIDUAL_STEP_TURN) + 1)))
    dt = span / (n - 1)
    tau, (x, v, a) = solution.sample_grid(solution.pieces[0].start, dt, n)
    return float(np.max(np.abs(linear_response(exact_accel(scene, tau, x, v) - a, dt, mu, a1))))


def exact_accel(scene, t, x, v) -> np.ndarray:
    """Eq. 3's acceleration (models.ExactModel.accel at U = 0) on arrays: the residual R = x'' - accel of the
    estimate's samples at once (tests/model/test_error_estimate_theory.py checks it against ExactModel.accel)."""
    s = 1.0 + 2.0 * x / 3.0
    positive = np.maximum(s, 0.0)
    a = 1.0 - scene.mu * v - positive * np.sqrt(positive)
    if scene.Delta != 0.0:
        a = a + scene.Delta * np.cos(scene.omega * t)
    if scene.alpha != 0.0 or scene.beta != 0.0 or scene.gamma != 0.0:
        u = 2.0 * x / (3.0 * scene.R)
        f3 = 1.0 / ((1.0 - u) * (1.0 - u))
        force = scene.alpha * (f3 - 1.0 / ((1.0 + u) * (1.0 + u)))
        if scene.beta != 0.0 or scene.gamma != 0.0:
            force = force + (scene.beta * np.sin(scene.Omega * t)
                             + scene.gamma * (1.0 - np.cos(2.0 * scene.Omega * t))) * f3
        a = a + force
    return a


def linear_response(f, dt: float, mu: float, a1: float) -> np.ndarray:
    """e at the samples of f (spacing dt, f piecewise linear between them) of e'' + mu e' + a1 e = f, e(0) = e'(0) =
    0, a1 > mu^2/4: e = Im(z)/p, z' = lambda z + f, lambda = -mu/2 + i p, p = sqrt(a1 - mu^2/4), advanced exactly
    from sample to sample (one linear recurrence, scipy.signal.lfilter)."""
    from scipy.signal import lfilter

    f = np.asarray(f, dtype=float)
    p = math.sqrt(a1 - 0.25 * mu * mu)
    lam = complex(-0.5 * mu, p)
    step = np.exp(lam * dt)
    phi1 = (step - 1.0) / lam  # int_0^dt e^(lambda (dt - u)) du
    phi2 = (step - 1.0 - lam * dt) / (lam * lam * dt)  # int_0^dt e^(lambda (dt - u)) u/dt du
    z = lfilter([1.0], [1.0, -step], f[:-1] * phi1 + (f[1:] - f[:-1]) * phi2)
    return np.concatenate(([0.0], z.imag / p))


def analytic_terms(scene, solution, span: float) -> dict:
    """The terms of fidelity 4's estimate (module docstring): the residual propagated through Eq. 11's operator; also
    max|R|, its rms and the off-resonance gain 1/a1 of analytic.check_fit's rule."""
    from .oafm_bases import eq11_operator  # fidelity 4's module (loaded by it)

    residual = max(piece.residual_max for piece in solution.pieces)
    rms = max(piece.residual_rms for piece in solution.pieces)
    return {"propagated": propagated_residual(scene, solution, span), "residual": residual, "residual_rms": rms,
            "gain": 1.0 / eq11_operator(scene).k}


def analytic_estimate(scene, solution, span: float) -> tuple[float, dict]:
    """(fidelity 4's estimate of max|x - x_exact| over the run, its terms)."""
    terms = analytic_terms(scene, solution, span)
    return CALIBRATION["analytic"] * terms["propagated"], terms


def warning(level: int, share: float | None, estimate: float, amplitude: float) -> list[str]:
    """The fmi2Warning of a rung whose estimate exceeds `share` (fidelities.FidelityEntry.warn_share) of the
    amplitude, or that cannot estimate (non-finite); else [] (and [] for a rung without a share: the integrated
    ones, whose solver settings the user chose)."""
    if share is None:
        return []
    if not math.isfinite(estimate):
        return [f"fidelity {level} cannot estimate its error here (estimate {estimate!r}); use fidelity 0"]
    if estimate > share * amplitude:
        return [f"fidelity {level}'s error estimate max|x - x_exact| ~ {estimate:.3g} exceeds {share:g} of the "
                f"amplitude max|x| ~ {amplitude:.4g} (docs/rungs.md, Error estimates); use fidelity 0"]
    return []



# -- the integrated rungs: the exact model's solver settings and the polynomial truncation ------------------------

# DOP853's step model (solver_terms), derived from integrate.py's tableau and step controller (tests/model/
# test_error_estimate_theory.py recomputes every constant here from them):
# - The free vibration is the test equation y' = i s y: one step of h reads DOP853_ESTIMATOR (s h)^8 on its embedded
#   error estimator (Hairer's e5^2 / sqrt(e5^2 + 0.01 e3^2), e5 ~ 1.35e-5 (s h)^6, e3 ~ 4.2e-3 (s h)^4) and errs by
#   DOP853_LOCAL (s h)^9 local_growth(s h) (the stability function's R(z) - e^z = d9 z^9 + d10 z^10 + ..., d9 =
#   -6.4e-8; local_growth is |1 + (d10/d9) z + ...| at z = i s h, DOP853_LOCAL_SERIES: 1.16 at s h = 2, 1.39 at the
#   drive's ceiling of 4 rad per step, where the leading term alone was 1.37 times too small).
# - A forced part at a drive's frequency s (Delta, beta, gamma) is no free motion: its phase is the drive's, fixed by
#   t, and a step integrates the drive term (x'' = F e^(i s t)) by the tableau's quadrature, whose errors are its
#   moments' (sum b_j c_j^k - 1/(k+1) for v, sum_j (sum_i b_i a_ij) c_j^k / k! - 1/(k+2)! for x): x errs by
#   DOP853_FORCED_LOCAL (s h)^9 of its amplitude (v by 6.6e-10), and the estimator reads DOP853_FORCED_ESTIMATOR
#   (s h)^8 on the mean over the drive's phases (e5 ~ 3.78e-6 (s h)^6 on x and on v, e3 ~ 4.2e-3 (s h)^4 in
#   modulus; x and v each relative to its amplitude, in DOP853_ESTIMATOR's form): 12 and 13 times less than the
#   free vibration's. That holds where the inertia carries the drive (s^2 >> a1); where the stiffness carries it
#   (s^2 <= a1) the part moves with the oscillator's own dynamics. The constants of a forced part are the forced
#   ones plus the free ones' excess in the share a1/s^2 (at most 1) of the stiffness in its acceleration (on the
#   forced equation with a1 = 1 the share gives the estimator within 25 % at s = 1.2 and 3).
#   Before, every part had the free constants: the drive's parts at 2 Omega, with tiny amplitudes, then set the
#   modelled step (h s ~ 2.25 of 2 Omega, the old ceiling) where the solver took longer steps once the ceiling rose
#   to 4 rad (the exact model's campaign, Omega 9.5-9.7 and light damping: modelled h 0.118-0.131, the solver's
#   mean step 0.133-0.149) and erred up to 2.3 times the estimate.
# - The controller: DOP853's PI controller (integrate.PI_ALPHA, PI_BETA) sets h_new = h SAFETY err^-PI_ALPHA
#   err_old^PI_BETA, so over a run in which the step neither grows nor shrinks the mean of log err is log SAFETY /
#   (PI_ALPHA - PI_BETA): it keeps the error norm at CONTROLLER_TARGET = SAFETY^(1/(PI_ALPHA - PI_BETA)) = 0.147
#   of rtol, where the I controller (err^(-1/8) alone) kept SAFETY^8 = 0.43 -- the step model's h is the largest
#   at which each part's estimator reads CONTROLLER_TARGET rtol. (The I controller's model asked the estimator for
#   rtol itself, and its calibration absorbed the 0.43; the PI controller's errors are about 3 times smaller, which
#   that model over-estimated: fidelity 1 was within 100x of its error in 88.8 % of 1,000 scenes, the exact model
#   bounded it in 99.4 %, where the acceptance asks 90 % and 99 %.)
# - The estimator's own growth with s h (2.3 times its leading term at 4 rad) is left out of the step: the real
#   step is then at most 2.3^(1/8) = 1.11 times shorter than the modelled one, on the safe side (measured on the
#   seed-7 and seed-11 campaigns: the same shares bounded, within 100x lower by 0-0.8 points with it).
DOP853_ESTIMATOR = 4.4e-7
DOP853_LOCAL = 6.5e-8
DOP853_LOCAL_SERIES = (1.0, 0.647078, 0.157789, 0.0269574, 0.00250767, 0.000179119, 1.19413e-05, 7.4633e-07)
DOP853_FORCED_ESTIMATOR = 3.4e-8
DOP853_FORCED_LOCAL = 5.3e-9
CONTROLLER_TARGET = 0.1472


def local_growth(theta: float) -> float:
    """|sum_j DOP853_LOCAL_SERIES[j] (i theta)^j|: the test equation's local error over its leading term
    DOP853_LOCAL theta^9 at theta = s h (core/estimate.c local_growth: the same operations)."""
    c0, c1, c2, c3, c4, c5, c6, c7 = DOP853_LOCAL_SERIES
    t2 = theta * theta
    real = c0 - t2 * (c2 - t2 * (c4 - t2 * c6))
    imaginary = theta * (c1 - t2 * (c3 - t2 * (c5 - t2 * c7)))
    return math.hypot(real, imaginary)


def stiffness_share(a1: float, s: float) -> float:
    """The share a1/s^2 (within [0, 1]) of the stiffness in the acceleration of a forced part at s (the step
    model's comment): 1 for s^2 <= a1 (s = 0 included), 0 without a positive stiffness."""
    stiffness = max(a1, 0.0)
    return 1.0 if s * s <= stiffness else stiffness / (s * s)


def linear_amplitude(scene) -> tuple[float, float, float]:
    """(x_s, the linear prediction's bound of max|x - x_s|, a1): Eq. 11's static offset x_s = gamma/a1 (a0 = -gamma)
    and the sum of the moduli of its free and forced parts (start, Delta at omega, beta at Omega, gamma at 2 Omega)."""
    a1 = forces.linear_stiffness(scene.alpha, scene.gamma, scene.R)
    mu = scene.mu
    p = math.sqrt(max(a1 - 0.25 * mu * mu, 1e-300))
    x_s = scene.gamma / a1
    free = abs(scene.x_start - x_s) + abs(scene.v_start) / p
    forced = (abs(scene.Delta) * abs(linear_gain(a1, mu, scene.omega))
              + abs(scene.beta) * abs(linear_gain(a1, mu, scene.Omega))
              + abs(scene.gamma) * abs(linear_gain(a1, mu, 2.0 * scene.Omega)))
    return x_s, free + 2.0 * forced, a1  # the forced parts also start a free vibration of their size


def _memory(mu: float, span: float) -> float:
    """How long the linear response remembers an error: min(span, 2/mu)."""
    return span if mu <= 0.0 else min(span, 2.0 / mu)


def response_parts(scene, span: float) -> dict:
    """The linear response of Eq. 11 over a run of `span`, in parts of one frequency each (C twin, for the kernel
    and the native FMU: core/estimate.c response_parts):
    - forced: (|phasor|, s) of Delta cos(omega t), beta sin(Omega t) and -gamma cos(2 Omega t) (the electrostatic
      drive's linear forcing), each through H(s) = 1/(a1 - s^2 + i mu_eff s) with mu_eff = 2/memory: at resonance
      the response grows as t/(2 s) for the run's memory min(span, 2/mu), not to the steady 1/(mu s);
    - free: the modulus of the free vibration the start leaves, (x_start, v_start) minus the forced parts at t = 0,
      turning at p = sqrt(a1 - mu^2/4)."""
    a1 = forces.linear_stiffness(scene.alpha, scene.gamma, scene.R)
    mu = scene.mu
    memory = _memory(mu, span)
    mu_eff = 2.0 / memory
    p = math.sqrt(max(a1 - 0.25 * mu * mu, 1e-300))
    x_s = scene.gamma / a1
    dx, dv, forced = scene.x_start - x_s, scene.v_start, []
    for drive, s in ((complex(scene.Delta, 0.0), scene.omega), (complex(0.0, -scene.beta), scene.Omega),
                     (complex(-scene.gamma, 0.0), 2.0 * scene.Omega)):
        z = drive * linear_gain(a1, mu_eff, s)
        if z != 0.0:
            forced.append((abs(z), s))
            dx -= z.real
            dv += s * z.imag  # -(i s z).real
    free = math.hypot(dx, (dv + 0.5 * mu * dx) / p)
    return {"x_s": x_s, "a1": a1, "p": p, "mu": mu, "mu_eff": mu_eff, "memory": memory, "free": free,
            "forced": forced}


def _components(parts: dict) -> list[tuple[float, float]]:
    """(amplitude, frequency) of every part: the free one at most free + the forced ones (their phases may add)."""
    forced = parts["forced"]
    return [(parts["free"] + sum(a for a, _ in forced), parts["p"])] + forced


def _remembered(s: float, parts: dict) -> float:
    """How long an error injected at frequency s adds up in the response: the memory at resonance (s = p), else the
    time 1/|i s - lambda| (lambda = -mu/2 + i p) over which its phase against the free vibration turns by a radian."""
    distance = math.hypot(s - parts["p"], 0.5 * parts["mu"])
    return parts["memory"] if distance * parts["memory"] <= 1.0 else 1.0 / distance


def solver_terms(scene, settings, span: float, parts: dict | None = None) -> dict:
    """The exact model's solver error over a run of `span`, summed over the response's parts (amplitude a, frequency
    s; response_parts):
    - adaptive DOP853 at the solver's rtol (after models.tolerance_factor): its PI controller keeps the estimator's
      error norm at CONTROLLER_TARGET rtol times the norm's scale (atol + rtol |x|, atol + rtol |v|); a part's
      estimator reads its constant (the free vibration's DOP853_ESTIMATOR, a forced part's by stiffness_share) times
      (s h)^8 a, and the step h is the largest that keeps every part there, at most max_step or the drive's step
      ceiling (the step model's comment above DOP853_ESTIMATOR). Each step errs by its local constant (s h)^9 a,
      which adds up over _remembered(s) / h steps ("accumulated", at most 2 a: a phase), and the output within a
      step errs like the step's estimator, its largest part ("local": dense output, the last steps);
    - RK4, step h: a part errs by (s h)^5 / 120 a per step (RK4's error constant for y' = i s y), adding up likewise:
      a s^5 h^4 / 120 _remembered(s) (at most 2 a). parts: response_parts(scene, span) when already computed."""
    parts = parts or response_parts(scene, span)
    if not _fixed(settings):
        return AdaptiveEstimator(scene, span, settings.max_step, parts).terms(settings.rtol)
    components = _components(parts)
    size = abs(parts["x_s"]) + sum(a for a, _ in components)
    h = settings.max_step or _fixed_default()
    accumulated = 0.0
    for a, s in components:
        accumulated += a * min(2.0, s**5 * h**4 / 120.0 * _remembered(s, parts))
    return {"solver": CALIBRATION["fixed"] * accumulated, "accumulated": accumulated, "amplitude": size}


class AdaptiveEstimator:
    """solver_terms of adaptive DOP853 on one scene, span and max_step, for any rtol (terms(rtol)): what does not
    depend on rtol (the response's parts, the norm's scales, each part's weight, the step ceiling, the tolerance
    factor) computed once, so that fidelity auto asks every rtol for the price of a few operations each."""

    def __init__(self, scene, span: float, max_step: float, parts: dict):
        self.parts = parts
        self.components = _components(parts)
        self.size = abs(parts["x_s"]) + sum(a for a, _ in self.components)
        scale_x = 0.01 + self.size  # integrate.ATOL_PER_RTOL = 0.01
        scale_v = 0.01 + sum(a * s for a, s in self.components)
        self.ceiling = max_step if max_step > 0.0 else drive_step_ceiling(scene)
        a1 = parts["a1"]  # the free part (the first) is the test equation's, each forced one by its stiffness share
        self.shares = [1.0] + [stiffness_share(a1, s) for _, s in self.components[1:]]
        self.estimators = [DOP853_FORCED_ESTIMATOR + (DOP853_ESTIMATOR - DOP853_FORCED_ESTIMATOR) * share
                           for share in self.shares]
        self.weights = [(s, estimator * a * math.hypot(1.0 / scale_x, s / scale_v) / math.sqrt(2.0))
                        for (a, s), estimator in zip(self.components, self.estimators) if a > 0.0 and s > 0.0]
        self.remembered = [_remembered(s, parts) for _, s in self.components]
        self.factor = tolerance_factor(scene, span)

    def terms(self, rtol: float) -> dict:
        """solver_terms's dict at the requested rtol (the solver's: rtol times the tolerance factor, models.
        solver_tolerance's value)."""
        rtol = rtol if self.factor == 1.0 else max(MIN_RTOL, rtol * self.factor)
        h = self.ceiling
        for s, weight in self.weights:
            h = min(h, (CONTROLLER_TARGET * rtol / weight) ** 0.125 / s)
        accumulated = local = 0.0
        for (a, s), remembered, share, estimator in zip(self.components, self.remembered, self.shares,
                                                          self.estimators):
            theta = s * h
            constant = DOP853_FORCED_LOCAL + (DOP853_LOCAL * local_growth(theta) - DOP853_FORCED_LOCAL) * share
            accumulated += a * min(2.0, constant * theta**9 / h * remembered)
            local = max(local, a * estimator * theta**8)
        value = CALIBRATION["adaptive"] * accumulated + CALIBRATION["local"] * local
        return {"solver": value, "accumulated": accumulated, "local": local, "step": h, "amplitude": self.size}


def _fixed(settings) -> bool:
    return solver_entry(settings.solver).fixed_step


def _fixed_default():
    return FIXED_DEFAULT_STEP


TRUNCATION_ANGLES = 16  # the cycle's samples of the force error's harmonic balance
TRUNCATION_TIMES = 5  # the AC drive's phases sampled over its period pi/Omega (the electrostatic force's)


def force_error_samples(model, scene):
    """F_exact - F_poly of Eq. 3 against Eq. 7 (`model`: models.PolynomialModel, its a0..a5 and G3), the difference
    of their accelerations at v = 0, U = 0, at a list of x: xs -> ([A], [B]), the difference at each x being A + w B
    at the AC drive's value w = beta sin(Omega t) - gamma cos(2 Omega t). Both share Delta cos(omega t); A = 1 - H(x)
    + alpha (F3 - F2) + gamma F3 + sum a_k x^k, B = F3 - G3(x) (tests/model/test_error_estimate_theory.py checks
    A + w B against the models' accel). One loop over the samples: the estimate's most frequent work. With
    (center, amplitude, lo, hi), the samples are at x = center + amplitude c for c in xs, clipped to [lo, hi] as
    min(max(x, lo), hi) does it (a NaN stays NaN)."""
    a0, a1, a2, a3, a4, a5 = model.a
    g0, g1, g2, g3, g4, g5 = model.g3
    alpha, gamma, three_r = scene.alpha, scene.gamma, 3.0 * scene.R
    sqrt = math.sqrt

    def samples(xs, cycle=None) -> tuple[list, list]:
        statics, electrostatics = [], []
        if cycle is not None:
            center, amplitude, lo, hi = cycle
        for x in xs:
            if cycle is not None:
                x = center + amplitude * x
                x = lo if lo > x else x
                x = hi if hi < x else x
            s = 1.0 + 2.0 * x / 3.0
            u = 2.0 * x / three_r
            f3 = 1.0 / ((1.0 - u) * (1.0 - u))
            statics.append(1.0 - (s * sqrt(s) if s > 0.0 else 0.0) + alpha * (f3 - 1.0 / ((1.0 + u) * (1.0 + u)))
                           + gamma * f3 + (a0 + x * (a1 + x * (a2 + x * (a3 + x * (a4 + x * a5))))))
            electrostatics.append(f3 - (g0 + x * (g1 + x * (g2 + x * (g3 + x * (g4 + x * g5))))))
        return statics, electrostatics

    return samples


def force_error_parts(model, scene):
    """force_error_samples at one x: x -> (A, B)."""
    samples = force_error_samples(model, scene)

    def parts(x: float) -> tuple[float, float]:
        (a,), (b,) = samples((x,))
        return a, b

    return parts


# cos(theta) at the first half of the TRUNCATION_ANGLES midpoints of the cycle: the other half (2 pi - theta) repeats
# them, so the sums over the cycle are twice the sums over these, and its largest values are among these
TRUNCATION_COSINES = tuple(math.cos(2.0 * math.pi * (i + 0.5) / TRUNCATION_ANGLES)
                           for i in range(TRUNCATION_ANGLES // 2))


def drive_ends(scene) -> tuple[float, float]:
    """The least and the greatest AC drive w = beta sin(Omega t) - gamma cos(2 Omega t) over TRUNCATION_TIMES phases
    of its period pi/Omega (0 without an AC drive): |a + w b| is convex in w, so its largest over the drive's phases
    is at one of these."""
    beta, gamma, omega, sin, cos = scene.beta, scene.gamma, scene.Omega, math.sin, math.cos
    ac = (beta != 0.0 or gamma != 0.0) and omega > 0.0
    times = [math.pi / omega * j / TRUNCATION_TIMES for j in range(TRUNCATION_TIMES)] if ac else [0.0]
    ws = [beta * sin(omega * t) - gamma * cos(2.0 * omega * t) for t in times]
    return min(ws), max(ws)


def force_error_harmonics(model, scene, x_s: float, amplitude: float, with_rest: bool = True, ends=None,
                           samples=None) -> tuple[float, float, float]:
    """Over x = x_s + amplitude cos(theta), theta at TRUNCATION_ANGLES midpoints, and the AC drive's phases: the
    force error d = F_exact - F_poly's largest |mean|, |stiffness| 2 mean(d cos theta)/amplitude (its first harmonic,
    the describing function) and |rest| max|d - mean - stiffness amplitude cos theta| (the higher harmonics). d is
    A(x) + w B(x) (force_error_samples), so each harmonic is its A part plus w times its B part: the x samples are
    evaluated once for every phase of the drive, and once for theta and 2 pi - theta (the same x). with_rest False:
    the stiffness alone (mean and rest nan, not computed). ends: drive_ends(scene), samples: force_error_samples(model, scene), when already at
    hand (truncation_terms asks two amplitudes of one scene)."""
    lo, hi = -1.5 + 1e-9, 1.5 * scene.R * (1.0 - 1e-3)
    n, cosines = TRUNCATION_ANGLES // 2, TRUNCATION_COSINES
    samples = samples or force_error_samples(model, scene)
    a_parts, b_parts = samples(cosines, (x_s, amplitude, lo, hi))  # the cycle's distinct x, clipped to the gap
    low, high = ends or drive_ends(scene)
    scale = 2.0 / n / amplitude if amplitude > 0.0 else 0.0
    k_a = scale * sum(map(operator.mul, a_parts, cosines))
    k_b = scale * sum(map(operator.mul, b_parts, cosines))
    stiffness = max(abs(k_a + low * k_b), abs(k_a + high * k_b))
    if not with_rest:
        return math.nan, stiffness, math.nan
    mean_a = sum(a_parts) / n
    mean_b = sum(b_parts) / n
    mean = max(abs(mean_a + low * mean_b), abs(mean_a + high * mean_b))
    rest = 0.0
    for a, b, c in zip(a_parts, b_parts, cosines):  # rest = max(rest, |ra + low rb|, |ra + high rb|), as max does it
        ra, rb = a - mean_a - k_a * amplitude * c, b - mean_b - k_b * amplitude * c
        value = abs(ra + low * rb)
        if value > rest:
            rest = value
        value = abs(ra + high * rb)
        if value > rest:
            rest = value
    return mean, stiffness, rest


def truncation_terms(scene, model, span: float, parts: dict | None = None) -> dict:
    """Fidelities 1 and 2: the polynomial's force error d = F_exact - F_poly on the response's cycle (amplitude A =
    the free part + the forced ones, response_parts), by harmonic balance: its mean moves x by mean/a1 ("mean"); its
    first harmonic is a stiffness error dk, which turns the free vibration at dk/(2p) more, a phase that grows over the
    memory (at most 2 radians), and changes each forced part's gain by dk |H(s)| ("stiffness"); the higher harmonics
    answer at 2p, 3p, ... with the gain 1/|a1 - (2p)^2| ~ 1/(3 a1) at most, rest/(3 a1) ("harmonics"). The free vibration decays as e^(-mu t/2) and dk with it as
    e^(-k mu t/2), k the exponent of dk's growth with the amplitude (dk at A and at the forced parts + half the free
    one): its phase stops growing after 2/(max(k, 1) mu). parts: response_parts(scene, span) when already computed."""
    parts = parts or response_parts(scene, span)
    forced = parts["forced"]
    a1, p, mu = parts["a1"], parts["p"], parts["mu"]
    f = sum(a for a, _ in forced)
    free = parts["free"]
    amplitude = f + free
    ends, samples = drive_ends(scene), force_error_samples(model, scene)
    mean, stiffness, rest = force_error_harmonics(model, scene, parts["x_s"], amplitude, ends=ends, samples=samples)
    memory = parts["memory"]
    if free > 0.0 and mu > 0.0 and stiffness > 0.0:
        half = f + 0.5 * free
        smaller = force_error_harmonics(model, scene, parts["x_s"], half, with_rest=False, ends=ends,
                                         samples=samples)[1]
        k = math.log(stiffness / smaller) / math.log(amplitude / half) if smaller > 0.0 else 0.0
        memory = min(memory, 2.0 / (max(k, 1.0) * mu))
    drift = free * min(2.0, stiffness / (2.0 * p) * memory)
    for a, s in forced:
        drift += a * min(2.0, stiffness * abs(linear_gain(a1, parts["mu_eff"], s)))
    harmonics = rest / (3.0 * a1)  # the second harmonic's gain 1/|a1 - (2 p)^2| ~ 1/(3 a1), the higher ones' less
    return {"truncation": mean / a1 + drift + harmonics, "mean": mean / a1, "stiffness": drift,
            "harmonics": harmonics, "amplitude": abs(parts["x_s"]) + amplitude}


def _result(value: float, amplitude: float, terms: dict) -> dict:
    return {"estimate": float(value), "amplitude": float(amplitude), "terms": {k: float(v) for k, v in terms.items()}}


def exact_estimate(scene, settings, model, solution, span: float) -> dict:
    """Fidelity 0: the solver's error (solver_terms), calibrated per kind of solver."""
    terms = solver_terms(scene, settings, span)
    return _result(terms["solver"], terms["amplitude"], terms)


# The compiled kernel's twin of polynomial_estimate and solver_terms (core/estimate.c, also the native FMU's estimate):
# compiled.load_library registers the kernel it loads (use_kernel), and fidelities 1 and 2's estimate then runs in C,
# with the same bits (tests/model/test_error_estimate_theory.py compares them over random scenes); without a kernel,
# or where the Python code would raise, it runs in Python.
_KERNEL = None
# core/estimate.h's layouts: in[] (PE_INPUTS doubles), constants[] (PC_CONSTANTS), out[] (PO_OUTPUTS)
_PE_INPUTS, _PC_CONSTANTS, _PO_OUTPUTS, _PC_MAX_COSINES = 29, 36, 10, 16
_SOLVER_KEYS = {False: ("solver", "accumulated", "local", "step", "amplitude"),
                True: ("solver", "accumulated", None, None, "amplitude")}
_TRUNCATION_KEYS = ("truncation", "mean", "stiffness", "harmonics", "amplitude")


def kernel_constants() -> list[float]:
    """core/estimate.h's constants[] (PC_CONSTANTS doubles): this module's constants and the cycle's cosines, as the
    kernel (use_kernel) and the native FMU (its generated rules.h, RULE_ESTIMATE_CONSTANTS) hand them to the C."""
    return [DOP853_ESTIMATOR, DOP853_LOCAL, CALIBRATION["adaptive"], CALIBRATION["local"], CALIBRATION["fixed"],
            CALIBRATION["truncation"], MIN_RTOL, TRUNCATION_TIMES, len(TRUNCATION_COSINES), DOP853_FORCED_ESTIMATOR,
            DOP853_FORCED_LOCAL, CONTROLLER_TARGET, *DOP853_LOCAL_SERIES, *TRUNCATION_COSINES,
            *[0.0] * (_PC_MAX_COSINES - len(TRUNCATION_COSINES))]


# Python's sum() of floats is compensated (Neumaier) from 3.12 on, and core/estimate.c adds alike when asked. The
# native FMU has no Python to follow: it adds compensated (NATIVE_COMPENSATED, its rules.h), the sum of the Python
# this project is developed and tested on, and the more accurate one (the sums here add at most 16 terms of one
# sign or mixed signs, where an uncompensated sum can lose the last bits). Both FMUs publish the estimate to 3
# digits (round_estimate), so a Python before 3.12 differs from the native FMU only where the sums' last bits move
# the third digit.
NATIVE_COMPENSATED = True


def use_kernel(library, compensated: bool | None = None) -> None:
    """Run fidelities 1 and 2's estimate on this kernel library (compiled.load_library's; None: in Python).
    compensated: whether the C adds as sum() does from Python 3.12 on (default: as this Python's sum() does)."""
    global _KERNEL
    if library is None:
        _KERNEL = None
        return
    import ctypes
    import sys

    doubles = ctypes.c_double * _PE_INPUTS
    function = library.vk_polynomial_estimate
    function.restype = ctypes.c_int
    function.argtypes = [doubles, ctypes.c_double * _PC_CONSTANTS, ctypes.c_int, ctypes.c_double * _PO_OUTPUTS]
    constants = (ctypes.c_double * _PC_CONSTANTS)(*kernel_constants())
    # Python's sum() of floats is compensated (Neumaier) from 3.12 on; the C adds alike
    compensated = sys.version_info >= (3, 12) if compensated is None else compensated
    _KERNEL = (function, doubles, constants, int(compensated), ctypes.c_double * _PO_OUTPUTS)


def kernel_loaded() -> bool:
    """Whether a kernel is registered (use_kernel): polynomial_estimate then runs on it."""
    return _KERNEL is not None


def kernel_polynomial_terms(scene, settings, model, span: float) -> dict | None:
    """polynomial_estimate's terms from the registered kernel, or None without one or where the Python code raises
    (it runs then)."""
    if _KERNEL is None:
        return None
    function, doubles, constants, compensated, outputs = _KERNEL
    fixed = _fixed(settings)
    step = (settings.max_step or _fixed_default()) if fixed else 0.0
    ceiling = 0.0 if fixed else settings.max_step if settings.max_step > 0.0 else drive_step_ceiling(scene)
    factor = 1.0 if fixed else tolerance_factor(scene, span)
    values = doubles(scene.alpha, scene.gamma, scene.R, scene.mu, scene.Delta, scene.omega, scene.beta, scene.Omega,
                     scene.x_start, scene.v_start, span, settings.rtol, float(fixed), step, ceiling, factor,
                     forces.linear_stiffness(scene.alpha, scene.gamma, scene.R), *model.a, *model.g3)
    out = outputs()
    if function(values, constants, compensated, out):
        return None
    terms = {key: value for key, value in zip(_SOLVER_KEYS[fixed], out[:5]) if key is not None}
    terms.update(zip(_TRUNCATION_KEYS, out[5:]))
    return terms


def polynomial_estimate(scene, settings, model, solution, span: float, kernel: bool = True) -> dict:
    """Fidelities 1 and 2: the solver's error and the polynomial's truncation (truncation_terms); on the compiled
    kernel where one is registered (use_kernel) and kernel is True."""
    terms = kernel_polynomial_terms(scene, settings, model, span) if kernel else None
    if terms is not None:
        return _result(terms["solver"] + CALIBRATION["truncation"] * terms["truncation"], terms["amplitude"], terms)
    parts = response_parts(scene, span)
    terms = {**solver_terms(scene, settings, span, parts), **truncation_terms(scene, model, span, parts)}
    value = terms["solver"] + CALIBRATION["truncation"] * terms["truncation"]
    return _result(value, terms["amplitude"], terms)


def averaged_plant_estimate(scene, settings, model, solution, span: float) -> dict:
    """Fidelity 3: averaged_estimate of the plant's slow-flow solution."""
    from .averaging import averaged as averaged_model  # fidelity 3's module (loaded by it)
    model = getattr(solution, "averaged", None) or averaged_model(scene)  # the solution's own, else made anew
    value, terms = averaged_estimate(model, solution, span)
    return _result(value, terms["amplitude"], terms)


def analytic_plant_estimate(scene, settings, model, solution, span: float) -> dict:
    """Fidelity 4: analytic_estimate of the plant's OAFM solution; the amplitude is the linear prediction's."""
    value, terms = analytic_estimate(scene, solution, span)
    return _result(value, abs(scene.gamma) + linear_amplitude(scene)[1], terms)


DEFAULT_SPAN = 1000.0  # the run estimated without a stop time (fidelity 3's set-up window, slowflow.WINDOW)


def round_estimate(value: float) -> float:
    """An estimate to 3 significant digits (more would be noise), as both plant FMUs publish it (the native one by
    core/estimate.c, the kernel path's C: native/plant_setup.c native_error_estimate)."""
    return float(f"{value:.3g}")


def attach(plant, level, t0: float, stop_time: float | None) -> None:
    """Give a plant (plant.Plant, compiled.CompiledPlant, compiled_open_loop.CompiledOpenLoopPlant) its
    `error_estimate` (its level's estimator's dict; level: the registry's entry, fidelities.FidelityEntry) and add
    the rung's warning to its warnings."""
    if level.error_estimate is None:
        plant.error_estimate = None
        return
    inner = getattr(plant, "python", plant)  # the compiled open-loop plant wraps the Python one
    span = DEFAULT_SPAN if stop_time is None or not math.isfinite(stop_time - t0) else stop_time - t0
    try:
        result = level.error_estimate(plant.scene, plant.settings,
                                      getattr(inner, "model", None) or level.model(plant.scene),
                                      getattr(inner, "solution", None), span)
    except (ArithmeticError, ValueError) as error:  # ZeroDivisionError and OverflowError are ArithmeticErrors
        result = {"estimate": math.nan, "amplitude": math.nan, "terms": {}, "error": str(error)}
    result["estimate"] = round_estimate(result["estimate"])
    plant.error_estimate = result
    terms = ", ".join(f"{k} {v:.3g}" for k, v in result["terms"].items())
    plant.notes.append(f"error estimate: max|x - x_exact| ~ {result['estimate']:.3g} over the run ({terms})")
    refusal = refused(int(level.level), level.refuse_share, result["estimate"], result["amplitude"])
    if refusal is not None:
        from .parameters import ParameterError
        raise ParameterError("fidelity", int(level.level), refusal)
    plant.warnings += warning(int(level.level), level.warn_share, result["estimate"], result["amplitude"])


def refused(level: int, share: float | None, estimate: float, amplitude: float) -> str | None:
    """Why a rung refuses the scene: its estimate is above `share` (fidelities.FidelityEntry.refuse_share) of the
    amplitude or not finite (None: it does not refuse; a rung without a share never does)."""
    if share is None:
        return None
    if not math.isfinite(estimate):
        return f"fidelity {level} cannot estimate its error here (estimate {estimate!r}); use fidelity 0"
    if estimate > share * amplitude:
        return (f"fidelity {level}'s error estimate max|x - x_exact| ~ {estimate:.3g} exceeds {share:g} of the "
                f"amplitude max|x| ~ {amplitude:.4g}: outside its domain; use fidelity 0")
    return None
