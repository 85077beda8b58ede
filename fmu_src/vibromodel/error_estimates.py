"""Error estimates of the rungs: an estimate of max|x - x_exact| over a run, from each rung's own theory, with a
constant calibrated against the exact model (`vibrofmu.analyses.error_calibration`, docs/rungs.md, Error estimates).

Fidelity 3 (the averaged slow flow, docs/model.md, Averaging and slow flow) errs through what first-order averaging
leaves out; each term below is the amplitude of one neglected part of the solution (x units):

- ac: the fast AC response psi = -beta sin(Omega t)/Omega^2 + gamma cos(2 Omega t)/(4 Omega^2) assumes Omega >>
  sqrt(k1). The linear response of the exact model to the AC force F3(x_e) beta sin(Omega t) is
  F3(x_e) beta H(Omega), H(s) = 1/(k1 - s^2 + i mu s); psi's phasor is -beta/Omega^2. Their difference
  |F3(x_e) H(Omega) + 1/Omega^2| beta (gamma: at 2 Omega, psi's 1/(4 Omega^2)) is the steady error; the start
  absorbs the same mismatch (and its derivative, Omega times it) into the free vibration, which turns at omega_e:
  the term is that amplitude times (1 + Omega/omega_e). At Omega = 0.3, beta = 0.01 it is 0.14 (psi = 0.11 where the
  quasi-static response is 0.011): the table of the averaging's slow-AC failure.
- drift: the slow flow turns the free vibration at (omega^2 + k1)/(2 omega), the exact one at sqrt(k1 - mu^2/4): the
  phase error grows at their difference d_omega, on a free vibration of amplitude r_free (start minus steady
  slow state) decaying at mu/2: max over the run of r_free e^(-mu t/2) min(2, d_omega t).
- rate: the oscillating terms averaging drops from the slow equations have the amplitude of the slow rate over the
  fast frequency, max|(A', B')| / omega (the near-identity transformation's size).
- harmonics: the third harmonic of the cubic stiffness and the k2^2 terms of the second-order reconstruction,
  (|k3|/(32 k1) + k2^2/(3 k1^2)) r^3.
- pumping: the parametric pumping of the AC terms (averaging.parametric_growth) eats a share of the damping; the
  error is that share of the amplitude.

Fidelity 4 (OAFM): the residual R of Eq. 3 on the fitted x~. Linearized, an error e obeys L[e] = -R with
L = d^2/dt^2 + mu d/dt + a1; off resonance |e| ~ |R|/a1 (analytic.check_fit's estimate). The resonant gain
1/(mu p) overestimated the measured error 100-10,000 times (the residual's largest part is not at resonance), so the
estimate is max|R|/a1 with a calibrated factor.

Each level's estimator is its registry entry's `error_estimate` (fidelities.py); make_plant attaches the result to
the plant (`attach`). A rung whose estimate exceeds its entry's `warn_share` of the amplitude adds an fmi2Warning
naming the estimate and the rung to use; a rung that cannot estimate (non-finite) warns likewise.
"""
from __future__ import annotations

import math

import numpy as np

from . import forces

# Calibrated constants (vibrofmu.analyses.error_calibration; docs/rungs.md, Error estimates): each rung's estimate
# is CALIBRATION[level] times its theoretical sum of terms, chosen so that the estimate bounds the measured error in
# >= 99 % of the campaign's random scenes.
CALIBRATION = {"averaged": 3.0, "analytic": 1.0, "adaptive": 1.0, "fixed": 1.0, "truncation": 1.0}
# An approximate rung warns when its estimate exceeds its share of the run's amplitude max|x| (the registry's
# FidelityEntry.warn_share): fidelity 3 AVERAGED_WARN_SHARE (its calibrated estimate is ~10 times its measured error
# of ~1 % on the paper scene, which is not warned; every cell of the slow-AC grid that is not warned is within 5 %:
# tests/fmus/test_error_estimates.py), fidelity 4 analytic.FIT_WARN.
AVERAGED_WARN_SHARE = 0.15


def linear_gain(k1: float, mu: float, s: float) -> complex:
    """H(s) = 1/(k1 - s^2 + i mu s): the steady phasor of y'' + mu y' + k1 y = e^(i s t)."""
    return 1.0 / complex(k1 - s * s, mu * s)


def _drift(r_free: float, d_omega: float, mu: float, span: float) -> float:
    """max over t in [0, span] of r_free e^(-mu t/2) min(2, d_omega t) (its maximum without the cap is at 2/mu)."""
    t = span if mu <= 0.0 else min(span, 2.0 / mu)
    return r_free * min(2.0, d_omega * t * math.exp(-0.5 * mu * t))


def averaged_terms(model, solution, span: float) -> dict:
    """The terms of fidelity 3's estimate (module docstring), x units, for an averaged model (averaging.Averaged)
    and its slow-flow solution (slowflow.SlowFlowSolution) over a run of `span` from its start."""
    from .averaging import parametric_growth  # fidelity 3's module (loaded by it)

    s, k = model.scene, model.eq.k
    k1, k2, k3 = k[1], k[2], k[3]
    w_e, mu = model.omega_e, s.mu
    cells = np.asarray(solution.cells)
    horizon = max(1, min(len(cells), math.ceil(span / solution.spacing))) if len(cells) else 0
    cells = cells[:horizon]
    if len(cells):
        r = np.hypot(cells[:, 0], cells[:, 4])
        rate = np.hypot(cells[:, 1], cells[:, 5]) / solution.spacing
        r_max, rate_max = float(np.max(r)), float(np.max(rate))
        r_free = float(math.hypot(cells[0, 0] - cells[-1, 0], cells[0, 4] - cells[-1, 4]))
    else:
        r_max = rate_max = r_free = 0.0
    f3e = 1.0 / (1.0 - 2.0 * model.eq.x_e / (3.0 * s.R)) ** 2  # F3 at x_e
    ac = 0.0
    for amplitude, freq, psi in ((s.beta, s.Omega, 1.0 / s.Omega**2), (s.gamma, 2.0 * s.Omega, 1.0 / (4.0 * s.Omega**2))):
        if amplitude:
            mismatch = abs(amplitude) * abs(f3e * linear_gain(k1, mu, freq) + psi)
            ac += mismatch * (1.0 + freq / w_e)
    d_omega = abs((s.omega**2 + k1) / (2.0 * s.omega) - math.sqrt(max(k1 - 0.25 * mu * mu, 0.0)))
    pumping = max((share for _, _, share in parametric_growth(s, w_e)), default=0.0)
    return {"ac": ac, "drift": _drift(r_free, d_omega, mu, span), "rate": rate_max / (2.0 * s.omega),
            "harmonics": (abs(k3) / (32.0 * k1) + k2 * k2 / (3.0 * k1 * k1)) * r_max**3,
            "pumping": min(pumping, 2.0) * r_max, "amplitude": abs(model.eq.x_e) + r_max}


def averaged_estimate(model, solution, span: float) -> tuple[float, dict]:
    """(fidelity 3's estimate of max|x - x_exact| over the run, its terms)."""
    terms = averaged_terms(model, solution, span)
    return CALIBRATION["averaged"] * sum(v for key, v in terms.items() if key != "amplitude"), terms


def analytic_terms(scene, solution, span: float) -> dict:
    """The terms of fidelity 4's estimate (module docstring): max|R| and the off-resonance gain 1/a1."""
    from .oafm_bases import eq11_operator  # fidelity 4's module (loaded by it)

    residual = max(piece.residual_max for piece in solution.pieces)
    return {"residual": residual, "gain": 1.0 / eq11_operator(scene).k}


def analytic_estimate(scene, solution, span: float) -> tuple[float, dict]:
    """(fidelity 4's estimate of max|x - x_exact| over the run, its terms)."""
    terms = analytic_terms(scene, solution, span)
    return CALIBRATION["analytic"] * terms["residual"] * terms["gain"], terms


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

def linear_amplitude(scene) -> tuple[float, float, float]:
    """(x_s, the linear prediction's bound of max|x - x_s|, a1): Eq. 11's static offset x_s = gamma/a1 (a0 = -gamma)
    and the sum of the moduli of its free and forced parts (start, Delta at omega, beta at Omega, gamma at 2 Omega)."""
    a1 = forces.coefficients(scene.alpha, scene.gamma, scene.R)[1]
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


def solver_terms(scene, settings, span: float) -> dict:
    """The exact model's solver error over a run of `span`:
    - adaptive DOP853: its per-step error control at rtol accumulates over the response's memory min(span, 2/mu) in
      periods 2 pi/p: rtol * amplitude * (1 + memory p / (2 pi)) (models.tolerance_factor keeps rtol per that memory);
    - RK4, step h: the phase error of an oscillation of frequency s and amplitude a grows at a s^5 h^4 / 120 per unit
      time (RK4's error constant for x'' = -s^2 x), over the memory: sum over the response's parts."""
    x_s, amplitude, a1 = linear_amplitude(scene)
    mu = scene.mu
    p = math.sqrt(max(a1 - 0.25 * mu * mu, 1e-300))
    memory = _memory(mu, span)
    size = abs(x_s) + amplitude
    if not _fixed(settings):
        rtol, _ = _solver_rtol(scene, settings, span)
        return {"solver": rtol * size * (1.0 + memory * p / (2.0 * math.pi)), "amplitude": size}
    h = settings.max_step or _fixed_default()
    parts = [(amplitude, p), (abs(scene.beta) * abs(linear_gain(a1, mu, scene.Omega)) + abs(scene.beta) / scene.Omega**2,
                              scene.Omega),
             (abs(scene.gamma) / (4.0 * scene.Omega**2), 2.0 * scene.Omega)]
    return {"solver": sum(a * min(s**5 * h**4 / 120.0 * memory, 2.0) for a, s in parts if a), "amplitude": size}


def _fixed(settings) -> bool:
    from .solvers import solver_entry
    return solver_entry(settings.solver).fixed_step


def _solver_rtol(scene, settings, span):
    from .models import solver_tolerance
    return solver_tolerance(scene, settings, 0.0, span)


def _fixed_default():
    from .solvers import FIXED_DEFAULT_STEP
    return FIXED_DEFAULT_STEP


def truncation_terms(scene, model, span: float) -> dict:
    """Fidelities 1 and 2: the polynomial's force error max|F_exact - F_poly| over x in x_s +- the linear amplitude
    (and the AC phases), answered by the linear response: over a1 off resonance (analytic's argument), at most the
    impulse response's integral over the run."""
    from .models import ExactModel

    x_s, amplitude, a1 = linear_amplitude(scene)
    exact = ExactModel(scene)
    lo, hi = max(x_s - amplitude, -1.5 + 1e-9), min(x_s + amplitude, 1.5 * scene.R * (1.0 - 1e-3))
    xs = np.linspace(lo, hi, 41) if hi > lo else np.array([x_s])
    period = 2.0 * math.pi / (2.0 * scene.Omega) if scene.Omega > 0.0 else 1.0
    difference = 0.0
    for t in np.linspace(0.0, 2.0 * period, 9):
        for x in xs:
            difference = max(difference, abs(exact.accel(float(t), float(x), 0.0, 0.0)
                                             - model.accel(float(t), float(x), 0.0, 0.0)))
    return {"truncation": difference / a1, "amplitude": abs(x_s) + amplitude}


def _result(value: float, amplitude: float, terms: dict) -> dict:
    return {"estimate": float(value), "amplitude": float(amplitude), "terms": {k: float(v) for k, v in terms.items()}}


def exact_estimate(scene, settings, model, solution, span: float) -> dict:
    """Fidelity 0: the solver's error (solver_terms), calibrated per kind of solver."""
    terms = solver_terms(scene, settings, span)
    kind = "fixed" if _fixed(settings) else "adaptive"
    return _result(CALIBRATION[kind] * terms["solver"], terms["amplitude"], terms)


def polynomial_estimate(scene, settings, model, solution, span: float) -> dict:
    """Fidelities 1 and 2: the solver's error and the polynomial's truncation (truncation_terms)."""
    terms = {**solver_terms(scene, settings, span), **truncation_terms(scene, model, span)}
    kind = "fixed" if _fixed(settings) else "adaptive"
    value = CALIBRATION[kind] * terms["solver"] + CALIBRATION["truncation"] * terms["truncation"]
    return _result(value, terms["amplitude"], terms)


def averaged_plant_estimate(scene, settings, model, solution, span: float) -> dict:
    """Fidelity 3: averaged_estimate of the plant's slow-flow solution."""
    from .averaging import averaged as averaged_model  # fidelity 3's module (loaded by it)
    value, terms = averaged_estimate(averaged_model(scene), solution, span)
    return _result(value, terms["amplitude"], terms)


def analytic_plant_estimate(scene, settings, model, solution, span: float) -> dict:
    """Fidelity 4: analytic_estimate of the plant's OAFM solution; the amplitude is the linear prediction's."""
    value, terms = analytic_estimate(scene, solution, span)
    return _result(value, abs(scene.gamma) + linear_amplitude(scene)[1], terms)


DEFAULT_SPAN = 1000.0  # the run estimated without a stop time (fidelity 3's set-up window, slowflow.WINDOW)


def round_estimate(value: float) -> float:
    """An estimate to 3 significant digits (more would be noise), as both plant FMUs publish it (the native one's C
    computes the same terms in another order: native/plant_setup.c native_error_estimate)."""
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
    plant.warnings += warning(int(level.level), level.warn_share, result["estimate"], result["amplitude"])
