"""The integrated rungs' error estimates (vibromodel.error_estimates) against independent evidence: DOP853's error
constants from its own tableau, RK4's order from step halving, the solver's and the polynomial's estimates against
the exact model run by the compiled kernel; and a reduced calibration campaign (slow)."""
import math

import numpy as np
import pytest

from vibrofmu.analyses.domains import run_steps
from vibrofmu.fmus import kernel
from vibromodel import error_estimates, integrate
from vibromodel.fidelities import REGISTRY
from vibromodel.parameters import Scene
from vibromodel.plant import Settings, make_plant

STOP, H = 50.0, 0.1


@pytest.fixture(scope="module")
def library():
    return kernel.kernel_library(), "the test's kernel"


def dop853_on_oscillation(z: complex) -> tuple[float, float]:
    """(|local error|, |embedded estimate|) of one DOP853 step of y' = lambda y, y(0) = 1, h lambda = z, from
    integrate.py's tableau (the stages K_i = z y_i; the estimate as integrate.Dop853 forms it from E5 and E3)."""
    k = []
    for i in range(integrate.N_STAGES):
        k.append(z * (1.0 + sum(integrate.A[i][j] * k[j] for j in range(i))))
    y1 = 1.0 + sum(b * ki for b, ki in zip(integrate.B, k))
    k.append(z * y1)
    e5 = abs(sum(e * ki for e, ki in zip(integrate.E5, k)))
    e3 = abs(sum(e * ki for e, ki in zip(integrate.E3, k)))
    return abs(y1 - np.exp(z)), e5 * e5 / math.sqrt(e5 * e5 + 0.01 * e3 * e3)


@pytest.mark.parametrize("sh", [0.3, 0.5, 1.0, 1.5, 2.0, 2.25])
def test_dop853_error_constants_follow_from_its_tableau(sh):
    """DOP853_LOCAL (s h)^9 and DOP853_ESTIMATOR (s h)^8, the estimate's model of one step on an oscillation, within
    the 20 % that the constants' own variation over s h in [0.3, 2.25] allows (measured: the local error's constant
    6.4e-8 ... 7.6e-8, the estimator's 4.35e-7 ... 5.7e-7); beyond, up to the drive's ceiling of 4 rad, the local
    error's growth is local_growth's (next test)."""
    local, estimate = dop853_on_oscillation(1j * sh)
    assert local / sh**9 == pytest.approx(error_estimates.DOP853_LOCAL, rel=0.2)
    assert estimate / sh**8 == pytest.approx(error_estimates.DOP853_ESTIMATOR, rel=0.35)


@pytest.mark.parametrize("sh", [0.5, 1.0, 2.0, 3.0, 4.0])
def test_the_local_errors_growth_is_the_tableaus(sh):
    """local_growth (the series of R(z) - e^z over its leading term, to z^16) against one DOP853 step of y' = i s y
    from the tableau: within 0.2 % up to the drive's ceiling s h = 4 (measured 0.1 % there, where the series' first
    neglected term, 1/17! 4^17 / 6.4e-8 / 4^9 ~ 3e-4 of the leading one, is the difference), and 1.39 at 4 where
    the leading term alone was 1.37 times too small (the previous step model's)."""
    local, _ = dop853_on_oscillation(1j * sh)
    d9 = local / sh**9 / error_estimates.local_growth(sh)  # the leading coefficient |d9| the series divides out
    assert d9 == pytest.approx(6.404e-8, rel=2e-3)
    if sh == 4.0:
        assert error_estimates.local_growth(sh) > 1.35


def dop853_on_forcing(h: float, phase: float) -> tuple[float, float]:
    """(|error of x| over x's amplitude, the embedded estimate as integrate.Dop853 forms it) of one DOP853 step of
    x'' = cos(t + phase) (s = 1, no stiffness: the drive integrated by the tableau's quadrature), from the exact
    solution x = -cos(t + phase), v = sin(t + phase), amplitudes 1."""
    def f(t, y):
        return np.array([y[1], math.cos(t + phase)])

    y0 = np.array([-math.cos(phase), math.sin(phase)])
    k = [f(0.0, y0)]
    for i in range(1, integrate.N_STAGES):
        k.append(f(integrate.C[i] * h, y0 + h * sum(integrate.A[i][j] * k[j] for j in range(i))))
    y1 = y0 + h * sum(b * ki for b, ki in zip(integrate.B, k))
    k.append(f(h, y1))
    e5 = h * sum(e * ki for e, ki in zip(integrate.E5, k))
    e3 = h * sum(e * ki for e, ki in zip(integrate.E3, k))
    err5, err3 = float(np.sum(e5 * e5)), float(np.sum(e3 * e3))
    return abs(y1[0] + math.cos(h + phase)), err5 / math.sqrt(err5 + 0.01 * err3)  # dop853_on_oscillation's form


@pytest.mark.parametrize("sh", [0.3, 0.5])
def test_dop853_forced_constants_follow_from_its_quadrature(sh):
    """DOP853_FORCED_LOCAL and DOP853_FORCED_ESTIMATOR (the step model's forced parts, derived from the tableau's
    quadrature moments) against steps of x'' = cos(t + phase) over 32 phases: x's error at its worst phase within
    5 % of DOP853_FORCED_LOCAL (s h)^9 (the moments' leading term: the phase that takes the whole complex error;
    the next term adds 0.4 (s h) of it), the estimator's mean over the phases (in DOP853_ESTIMATOR's form, x and v
    each relative to its amplitude) within 10 % of DOP853_FORCED_ESTIMATOR (s h)^8 (measured 3.57e-8 at 0.3 and
    0.5). Both an order of magnitude below the free vibration's constants, which the forced parts had before."""
    phases = np.linspace(0.0, 2.0 * math.pi, 32, endpoint=False)
    steps = [dop853_on_forcing(sh, phase) for phase in phases]
    assert max(x for x, _ in steps) / sh**9 == pytest.approx(error_estimates.DOP853_FORCED_LOCAL, rel=0.05 + 0.4 * sh)
    assert np.mean([e for _, e in steps]) / sh**8 == pytest.approx(error_estimates.DOP853_FORCED_ESTIMATOR, rel=0.1)
    assert error_estimates.DOP853_FORCED_ESTIMATOR < error_estimates.DOP853_ESTIMATOR / 10


def test_the_step_models_target_is_the_pi_controllers_fixed_point():
    """CONTROLLER_TARGET: DOP853's own PI step factor (integrate.pi_factor) run on steps whose error norm is (h /
    h1)^8 settles where the factor is 1, err = SAFETY^(1/(PI_ALPHA - PI_BETA)) (the step model's comment): found by
    iterating the controller, not by the formula, and within 0.1 % of the constant (it holds 4 digits)."""
    h, err_old = 1.0, 0.0
    for _ in range(400):
        error = h**8
        h *= integrate.pi_factor(error, err_old)
        err_old = error
    assert h**8 == pytest.approx(error_estimates.CONTROLLER_TARGET, rel=1e-3)
    assert integrate.SAFETY ** (1.0 / (integrate.PI_ALPHA - integrate.PI_BETA)) == pytest.approx(h**8, rel=1e-9)


def measured(scene, settings, library, reference=None):
    plant = make_plant(scene, settings, 0.0, STOP, library=library)
    x, _ = run_steps(plant, STOP, H)
    if reference is None:
        reference, _ = run_steps(make_plant(scene, Settings(rtol=1e-12), 0.0, STOP, library=library), STOP, H)
    return float(np.max(np.abs(x - reference))), plant.error_estimate["estimate"], reference


def test_rk4_estimate_has_the_order_step_halving_measures(library):
    """Halving RK4's step divides its measured error by ~16 (order 4); the estimate (C h^4) by exactly 16. Both
    errors are bounded by their estimates, within 100x (the campaign's acceptance per scene). The steps divide the
    communication step 0.1: a step that does not (0.08) is cut at each output, and the leftover steps blur the order
    (measured 2.3 and 2.9 for h = 0.08, 0.04, 0.02)."""
    scene = Scene(mu=0.02)
    errors, estimates, reference = [], [], None
    for h in (0.1, 0.05, 0.025):
        error, estimate, reference = measured(scene, Settings(solver=1, max_step=h), library, reference)
        errors.append(error)
        estimates.append(estimate)
        assert error <= estimate <= 100.0 * error, (h, error, estimate)
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    assert all(3.5 <= order <= 4.5 for order in orders), orders  # RK4's global order, measured
    assert all(math.log2(a / b) == pytest.approx(4.0, abs=0.01) for a, b in zip(estimates, estimates[1:]))


@pytest.mark.parametrize("rtol", [1e-3, 1e-6, 1e-10])
def test_dop853_estimate_bounds_its_error_within_100x(rtol, library):
    """At rtol 1e-3 the drive's step ceiling, not rtol, sets the steps: the estimate before the step model was
    rtol-proportional and 1e4-1e6 times the measured error there. Paper scene and a lightly damped one."""
    for scene in (Scene(), Scene(mu=0.005)):
        error, estimate, _ = measured(scene, Settings(rtol=rtol), library)
        assert error <= estimate <= 100.0 * error, (scene.mu, rtol, error, estimate)


@pytest.mark.parametrize("fidelity", [1, 2])
def test_polynomial_estimate_bounds_its_error_within_100x(fidelity, library):
    """A lightly damped scene (mu = 0.002): the printed coefficients' stiffness error turns the free vibration's phase
    over the whole run; the estimate before the harmonic balance was the static force error over a1 alone, 20 times
    below the measured error on such scenes."""
    scene = Scene(mu=0.002, x_start=0.05)
    error, estimate, _ = measured(scene, Settings(fidelity=fidelity), library)
    assert error <= estimate <= 100.0 * error, (error, estimate)


def test_estimates_cost_little_beside_the_plant_set_up(monkeypatch):
    """The estimates are formulas (no integration): each is at most a few force evaluations per cycle sample. Counted,
    not timed: fidelity 0's evaluates no force; fidelities 1 and 2 evaluate the force error at most
    TRUNCATION_ANGLES times (half its samples over the cycle, the other half the same x, at two amplitudes; the drive's
    phases reuse them)."""
    calls = 0
    wrapped = error_estimates.force_error_samples

    def counting(model, scene):
        inner = wrapped(model, scene)

        def samples(xs, cycle=None):
            nonlocal calls
            calls += len(xs)
            return inner(xs, cycle)
        return samples

    monkeypatch.setattr(error_estimates, "force_error_samples", counting)
    error_estimates.exact_estimate(Scene(), Settings(), None, None, STOP)
    assert calls == 0
    # in Python (the kernel's twin, core/estimate.c, evaluates the same samples: test_the_kernel_s_polynomial_estimate...)
    error_estimates.polynomial_estimate(Scene(), Settings(fidelity=1), REGISTRY[1].model(Scene()), None, STOP,
                                        kernel=False)
    assert 0 < calls <= error_estimates.TRUNCATION_ANGLES  # theta and 2 pi - theta share their x


# corner scenes: no AC drive, no load, neither and a start at rest, undamped, a start in motion, beyond the contact
# and beyond an electrode (the samples clipped), a narrow gap, no electrostatics, heavy damping, signed zeros
CORNER_SCENES = [Scene(beta=0.0, gamma=0.0), Scene(Delta=0.0), Scene(Delta=0.0, beta=0.0, gamma=0.0, x_start=0.0),
                 Scene(mu=0.0), Scene(v_start=0.3), Scene(x_start=-1.4), Scene(x_start=1.2, R=0.9),
                 Scene(R=0.3, alpha=0.05, x_start=0.4), Scene(alpha=0.0, gamma=0.0), Scene(mu=1.9),
                 Scene(x_start=-0.0, v_start=-0.0, gamma=0.0, Delta=0.0, beta=0.0)]


def test_the_kernel_s_polynomial_estimate_gives_the_bits_of_python_s(library):
    """Fidelities 1 and 2's estimate on the compiled kernel (core/estimate.c, registered by compiled.load_library)
    against polynomial_estimate in Python: the same operations in the same order with Python's float semantics
    (complex division, math.hypot, sum() as this Python adds floats), so the same bits (repr of every term), over 24
    random scenes (the calibration campaign's ranges) and the corner scenes, adaptive DOP853 at the default and a
    random rtol and max_step, RK4 at its default and a random step, spans from 0 (Python raises: the kernel hands the
    call back to it, and the error is the same) to 10^6. (Checked once over 3,000 random scene and settings pairs and
    336 corner cases: no difference.)"""
    assert error_estimates.kernel_loaded()  # the library fixture loaded the kernel
    rng = np.random.default_rng(8)
    scenes = [(Scene(mu=10 ** rng.uniform(-3, -0.3), Delta=10 ** rng.uniform(-4, -1.5), omega=rng.uniform(0.85, 1.15),
                     Omega=rng.uniform(0.2, 10.0), alpha=10 ** rng.uniform(-4, -1.5), beta=10 ** rng.uniform(-4, -1.2),
                     gamma=10 ** rng.uniform(-4, -2), R=rng.uniform(0.3, 1.0), x_start=rng.uniform(-0.6, 0.6)),
               (rng.uniform(20.0, 600.0),)) for _ in range(24)] + [(scene, (0.0, 50.0, 1e6)) for scene in CORNER_SCENES]

    def estimate(scene, settings, model, span, kernel):
        try:
            return repr(error_estimates.polynomial_estimate(scene, settings, model, None, span, kernel=kernel))
        except (ArithmeticError, ValueError) as error:  # as error_estimates.attach catches them
            return repr(error)

    compared = on_kernel = 0
    for scene, spans in scenes:
        for fidelity, span in ((fidelity, span) for fidelity in (1, 2) for span in spans):
            model = REGISTRY[fidelity].model(scene)
            for settings in (Settings(fidelity=fidelity), Settings(fidelity=fidelity, rtol=10 ** rng.uniform(-10, -3),
                                                                  max_step=rng.uniform(0.01, 1.0)),
                             Settings(fidelity=fidelity, solver=1), Settings(fidelity=fidelity, solver=1,
                                                                            max_step=10 ** rng.uniform(-2.5, -0.7))):
                python = estimate(scene, settings, model, span, False)
                assert estimate(scene, settings, model, span, True) == python, (scene, span, settings)
                compared += 1
                on_kernel += error_estimates.kernel_polynomial_terms(scene, settings, model, span) is not None
    assert on_kernel >= 0.7 * compared  # the kernel computed most of them (not handed back)


def _sum_from_python_3_12(values, start=0):
    """sum() of floats as CPython adds them from 3.12 on (builtin_sum_impl: start + the first, then Neumaier's
    compensated addition, the compensation added at the end where it is finite and not 0)."""
    values = iter(values)
    first = next(values, None)
    if first is None:
        return start
    total, compensation = start + first, 0.0
    for x in values:
        t = total + x
        compensation += (total - t) + x if abs(total) >= abs(x) else (x - t) + total
        total = t
    return total + compensation if compensation and math.isfinite(compensation) else total


def test_the_kernel_s_estimate_adds_as_python_3_12_does_when_told(library, monkeypatch):
    """The kernel's compensated sums (what it does under Python 3.12 and later, whose sum() of floats is Neumaier's)
    against polynomial_estimate in Python with that sum() (_sum_from_python_3_12, in place of this Python's): the
    same bits over 12 random scenes, both solvers (the plain and the compensated sums differ in the last bits of
    about half of such estimates, so this tests the flag's path, which CI's Python 3.11 does not take)."""
    try:
        error_estimates.use_kernel(library[0], compensated=True)
        monkeypatch.setattr(error_estimates, "sum", _sum_from_python_3_12, raising=False)
        rng = np.random.default_rng(4)
        for _ in range(12):
            scene = Scene(mu=10 ** rng.uniform(-3, -0.3), Delta=10 ** rng.uniform(-4, -1.5),
                          omega=rng.uniform(0.85, 1.15), Omega=rng.uniform(0.2, 10.0),
                          alpha=10 ** rng.uniform(-4, -1.5), beta=10 ** rng.uniform(-4, -1.2),
                          gamma=10 ** rng.uniform(-4, -2), R=rng.uniform(0.3, 1.0), x_start=rng.uniform(-0.6, 0.6))
            span = rng.uniform(20.0, 600.0)
            for fidelity in (1, 2):
                model = REGISTRY[fidelity].model(scene)
                for settings in (Settings(fidelity=fidelity), Settings(fidelity=fidelity, solver=1)):
                    assert error_estimates.kernel_polynomial_terms(scene, settings, model, span) is not None
                    assert repr(error_estimates.polynomial_estimate(scene, settings, model, None, span)) == repr(
                        error_estimates.polynomial_estimate(scene, settings, model, None, span, kernel=False))
    finally:
        error_estimates.use_kernel(library[0])


def _plain_harmonics(model, scene, x_s, amplitude):
    """The force error's harmonics written plainly (one force_error_parts call per x, min/max to clip it to the gap,
    sums over generators, the drive's phases from their times): the reference of force_error_harmonics, which reuses
    one sampler, the drive's two extreme values and a single loop for speed."""
    lo, hi = -1.5 + 1e-9, 1.5 * scene.R * (1.0 - 1e-3)
    n, cosines, error = error_estimates.TRUNCATION_ANGLES // 2, error_estimates.TRUNCATION_COSINES, \
        error_estimates.force_error_parts(model, scene)
    parts = [error(min(max(x_s + amplitude * c, lo), hi)) for c in cosines]
    ac = (scene.beta != 0.0 or scene.gamma != 0.0) and scene.Omega > 0.0
    times = [math.pi / scene.Omega * j / error_estimates.TRUNCATION_TIMES
             for j in range(error_estimates.TRUNCATION_TIMES)] if ac else [0.0]
    ends = [min(ws := [scene.beta * math.sin(scene.Omega * t) - scene.gamma * math.cos(2.0 * scene.Omega * t)
                       for t in times]), max(ws)]
    mean_a, mean_b = sum(a for a, _ in parts) / n, sum(b for _, b in parts) / n
    scale = 2.0 / n / amplitude if amplitude > 0.0 else 0.0
    k_a = scale * sum(a * c for (a, _), c in zip(parts, cosines))
    k_b = scale * sum(b * c for (_, b), c in zip(parts, cosines))
    rest = 0.0
    for (a, b), c in zip(parts, cosines):
        ra, rb = a - mean_a - k_a * amplitude * c, b - mean_b - k_b * amplitude * c
        rest = max(rest, abs(ra + ends[0] * rb), abs(ra + ends[1] * rb))
    return (max(abs(mean_a + w * mean_b) for w in ends), max(abs(k_a + w * k_b) for w in ends), rest)


def test_the_harmonic_balance_gives_the_bits_of_its_plain_form():
    """force_error_harmonics (the polynomial's estimate's most frequent work, made faster) against _plain_harmonics:
    the same operations in the same order, so the same bits, over 60 random scenes (the calibration campaign's
    ranges; both polynomial models, the response's amplitude and half of it, and an amplitude that reaches beyond the
    gap, where the clipping decides); the stiffness alone where the rest is not asked."""
    rng = np.random.default_rng(5)
    for _ in range(60):  # each scene's two polynomial models cost ~2 ms to build
        scene = Scene(mu=10 ** rng.uniform(-3, -0.3), Delta=10 ** rng.uniform(-4, -1.5), omega=rng.uniform(0.85, 1.15),
                      Omega=rng.uniform(0.2, 10.0), alpha=10 ** rng.uniform(-4, -1.5), beta=10 ** rng.uniform(-4, -1.2),
                      gamma=10 ** rng.uniform(-4, -2), R=rng.uniform(0.3, 1.0), x_start=rng.uniform(-0.2, 0.2))
        span = rng.uniform(20.0, 600.0)
        parts = error_estimates.response_parts(scene, span)
        amplitude = parts["free"] + sum(a for a, _ in parts["forced"])
        for fidelity in (1, 2):
            model = REGISTRY[fidelity].model(scene)
            for a in (amplitude, 0.5 * amplitude, 2.0 * scene.R):
                fast = error_estimates.force_error_harmonics(model, scene, parts["x_s"], a)
                assert [v.hex() for v in fast] == [v.hex() for v in _plain_harmonics(model, scene, parts["x_s"], a)]
                stiffness = error_estimates.force_error_harmonics(model, scene, parts["x_s"], a, with_rest=False)[1]
                assert stiffness.hex() == fast[1].hex()


# the paper's; strong electrostatics, a narrow gap; no AC drive and a gap wider than the contact (x < -1.5: lost)
SCENES = [Scene(), Scene(Delta=0.05, beta=0.02, gamma=0.005, alpha=0.03, R=0.6), Scene(beta=0.0, gamma=0.0, R=1.3)]


@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("fidelity", [1, 2])
def test_the_force_error_is_the_models_accel_difference(scene, fidelity):
    """force_error_parts' A + w B, w = beta sin(Omega t) - gamma cos(2 Omega t), against exact.accel - poly.accel of
    the models themselves (models.py) over x across 95 % of the gap (contact lost below -1.5) and the drive's phases.
    Both are sums of a few terms, each rounded: 1e-13 of the largest acceleration's size bounds the difference."""
    exact, poly = REGISTRY[0].model(scene), REGISTRY[fidelity].model(scene)
    parts = error_estimates.force_error_parts(poly, scene)
    for t in np.linspace(0.0, 7.0, 9):
        w = scene.beta * math.sin(scene.Omega * t) - scene.gamma * math.cos(2.0 * scene.Omega * t)
        for x in np.linspace(-0.95, 0.95, 23) * 1.5 * scene.R:
            a, b = parts(float(x))
            e, q = exact.accel(t, x, 0.0, 0.0), poly.accel(t, x, 0.0, 0.0)
            assert abs(a + w * b - (e - q)) <= 1e-13 * max(1.0, abs(e), abs(q)), (t, x)


@pytest.mark.parametrize("scene", SCENES)
def test_the_arrays_exact_accel_is_the_model_s(scene):
    """exact_accel (fidelity 4's residual on its samples at once) against ExactModel.accel point by point, x across
    the contact edge and v of both signs: the same operations (numpy's cos and sqrt may differ from math's by an
    ulp), so 1e-14 of the acceleration's size."""
    model = REGISTRY[0].model(scene)
    rng = np.random.default_rng(3)
    t, v = rng.uniform(0.0, 50.0, 200), rng.uniform(-1.0, 1.0, 200)
    x = rng.uniform(-0.95, 0.95, 200) * 1.5 * scene.R
    expected = np.array([model.accel(*point, 0.0) for point in zip(t, x, v)])
    assert np.all(np.abs(error_estimates.exact_accel(scene, t, x, v) - expected) <= 1e-14 * np.maximum(1.0, abs(expected)))


@pytest.mark.parametrize("scene", SCENES[:2])
def test_the_grid_evaluation_is_the_piece_s_to_rounding(scene):
    """Piece.evaluate_grid (fidelity 4's estimate samples the solution by a running product of e^(rate dt)) against
    Piece.evaluate (one exp per term and time) on Eq. 11's linear prediction x0 (a piece of the same form as the fitted
    ones, without a fit): 4000 samples, k roundings at the k-th, so 1e-11 of max|x| bounds the difference."""
    from vibromodel.oafm import Piece
    from vibromodel.oafm_bases import eq11_operator, forced_x0

    x0 = forced_x0(eq11_operator(scene), scene, 0.0, scene.x_start, scene.v_start)[0].merged()
    piece = Piece(start=0.0, end=200.0, basis_name="x0", C=(), x=x0)
    s = 0.05 * np.arange(4000)
    expected = piece.evaluate(s)
    assert np.max(np.abs(piece.evaluate_grid(0.0, 0.05, 4000) - expected)) <= 1e-11 * np.max(np.abs(expected))


def test_the_cheaper_a1_is_the_coefficients_one_to_the_bit():
    from vibromodel import forces

    for alpha, gamma, R in ((0.001, 0.0002, 1.0), (0.03, 0.005, 0.6), (0.0, 0.0, 0.3)):
        assert forces.linear_stiffness(alpha, gamma, R) == forces.coefficients(alpha, gamma, R)[1]


def test_linear_response_matches_solve_ivp():
    """Fidelity 4's propagation of its residual: the exact recurrence against scipy's DOP853 at rtol 1e-11 on
    e'' + mu e' + a1 e = f for a forcing of three frequencies (one near resonance). The forcing is sampled at 0.01 and
    taken piecewise linear, which errs by ~(s dt)^2/8 of it: 5e-4 of |f| at s = 3, so 1e-3 of max|e| bounds the
    difference."""
    from scipy.integrate import solve_ivp

    mu, a1, dt, span = 0.05, 1.1, 0.01, 60.0
    t = np.arange(0.0, span + dt / 2, dt)

    def force(t):
        return np.sin(0.7 * t) + 0.3 * np.cos(1.04 * t) - 0.2 * np.sin(3.0 * t)

    e = error_estimates.linear_response(force(t), dt, mu, a1)
    reference = solve_ivp(lambda t, y: [y[1], force(t) - mu * y[1] - a1 * y[0]], (0.0, span), [0.0, 0.0],
                          method="DOP853", rtol=1e-11, atol=1e-13, t_eval=t).y[0]
    assert np.max(np.abs(e - reference)) <= 1e-3 * np.max(np.abs(reference))


@pytest.mark.parametrize("scene", [Scene(), Scene(Delta=0.003, beta=0.005, Omega=3.0, mu=0.03)])
def test_the_slow_flow_s_arrays_are_its_lookups_to_rounding(scene):
    """SlowFlowSolution.states (fidelity 3's estimate samples its table at once) against state() point by point over
    the table, the cells' ends included: the same operations (numpy's sin and cos may differ from math's by an ulp,
    and x'' sums terms of size omega^2 r), so 1e-14 of the largest of |x|, |x'|, |x''| and 1."""
    solution = make_plant(scene, Settings(fidelity=3), 0.0, STOP).solution
    t = np.concatenate([np.linspace(0.0, STOP, 377), solution.spacing * np.arange(int(STOP / solution.spacing))])
    arrays = solution.states(t)
    expected = np.array([solution.state(float(u)) for u in t]).T
    scale = max(1.0, float(np.max(np.abs(expected))))
    assert np.max(np.abs(np.array(arrays) - expected)) <= 1e-14 * scale
    with pytest.raises(ValueError):  # beyond the table
        solution.states(np.array([solution.t_end + 1.0]))


@pytest.mark.parametrize("values", [{}, {"Delta": 0.003, "beta": 0.005, "Omega": 3.0, "mu": 0.03}])
def test_averaged_estimate_is_its_propagated_residual_and_bounds_the_error(values, library):
    """Fidelity 3: the residual of Eq. 3 on the reconstructed x~ propagated through the linear operator at x_e is the
    linearized error itself, so it is close to the measured error (paper scene over [0, 50]: 3.7e-4 against 3.7e-4;
    the other: 1.3e-3 against 1.3e-3): within 2x here (the calibration campaign's measured error over it is 0.44-2.2);
    the estimate, CALIBRATION["averaged"] times it, bounds the measured error within 100x. The former sum of the
    neglected terms' amplitudes was 11 times the measured error on the paper scene."""
    error, estimate, _ = measured(Scene(**values), Settings(fidelity=3), library)
    propagated = estimate / error_estimates.CALIBRATION["averaged"]
    assert error / 2.0 <= propagated <= 2.0 * error, (error, propagated)
    assert error <= estimate <= 100.0 * error


@pytest.mark.long  # two OAFM fits: seconds
@pytest.mark.parametrize("values", [{}, {"Delta": 0.05}])
def test_analytic_estimate_is_its_propagated_residual_and_bounds_the_error(values, library):
    """Fidelity 4: the residual propagated through Eq. 11's operator is the linearized error itself, so it is close
    to the measured error (paper scene: 3.2e-9 against 3.1e-9; Delta = 0.05: 3.2e-6 against 3.1e-6); the estimate,
    CALIBRATION["analytic"] times it, bounds the measured error within 100x. The former estimate max|R|/a1 was 23
    times the measured error on the paper scene."""
    error, estimate, _ = measured(Scene(**values), Settings(fidelity=4), library)
    propagated = estimate / error_estimates.CALIBRATION["analytic"]
    assert error / 2.0 <= propagated <= 2.0 * error, (error, propagated)  # the linearization: within 2x here
    assert error <= estimate <= 100.0 * error


@pytest.mark.slow
@pytest.mark.parametrize("rung", ["exact", "rk4", "polynomial", "polynomial-paper", "averaged", "analytic"])
def test_reduced_calibration_campaign(rung):
    """The calibration campaign (vibrofmu.analyses.error_calibration) reduced to the first 200 scenes of the documented
    one (seed 7; docs/rungs.md, the calibration block): deterministic on one machine, so the acceptance's shares must
    hold for them: the estimate bounds the measured error in >= 99 % and is within 100x of it in >= 90 %. (At 100
    scenes one miss in 99 estimated is already below 99 %.)"""
    from vibrofmu.analyses.error_calibration import campaign

    summary = campaign(rung, 200, 7)["summary"]
    assert summary["estimated"] >= 100  # the analytic rung refuses about half of the random scenes
    assert summary["bounded_share"] >= 0.99 and summary["within_100x_share"] >= 0.9, summary


@pytest.mark.slow
def test_reduced_auto_campaign():
    """Fidelity auto over the first 30 (scene, tolerance) pairs of the documented auto campaign (seed 7): its choice
    meets the tolerance in >= 99 % of them, i.e. in all (its cost against the oracle is a timing: vibrofmu bench
    prints it, and docs/rungs.md's auto block)."""
    from vibrofmu.analyses.error_calibration import auto_campaign

    summary = auto_campaign(30, 7)["summary"]
    assert summary["pairs"] == 30 and summary["met_share"] >= 0.99, summary


@pytest.mark.parametrize("estimate, outcome", [(1e-7, "quiet"), (1e-4, "warned"), (0.05, "refused"),
                                               (float("nan"), "refused")])
def test_fidelity_4_warns_and_refuses_by_its_estimate(estimate, outcome):
    """Fidelity 4's registry entry warns above FIT_WARN of the amplitude and refuses above FIT_REFUSE (or when it
    cannot estimate) by its error estimate (error_estimates.attach), whatever its residual's max|R|/a1: a stand-in
    estimator gives the estimate, on an amplitude of 0.1 (FIT_WARN: 1e-5, FIT_REFUSE: 0.01)."""
    from dataclasses import replace
    from types import SimpleNamespace

    from vibromodel.analytic import FIT_REFUSE, FIT_WARN
    from vibromodel.parameters import ParameterError

    level = REGISTRY[4]
    assert (level.warn_share, level.refuse_share) == (FIT_WARN, FIT_REFUSE)
    stand_in = replace(level, error_estimate=lambda *args: {"estimate": estimate, "amplitude": 0.1, "terms": {}})
    plant = SimpleNamespace(scene=Scene(), settings=Settings(fidelity=4), model=None, solution=None, notes=[],
                            warnings=[])
    if outcome == "refused":
        with pytest.raises(ParameterError) as refusal:
            error_estimates.attach(plant, stand_in, 0.0, STOP)
        assert refusal.value.name == "fidelity" and "use fidelity 0" in refusal.value.reason
        return
    error_estimates.attach(plant, stand_in, 0.0, STOP)
    assert plant.error_estimate["estimate"] == estimate
    if outcome == "warned":
        assert len(plant.warnings) == 1 and f"error estimate max|x - x_exact| ~ {estimate:.3g}" in plant.warnings[0]
        assert "use fidelity 0" in plant.warnings[0]
    else:
        assert plant.warnings == []
