"""Averaged slow flow (docs/model.md, Averaging and slow flow): moments, coefficients, backbone, steady states, stability, paper mode."""
import math

import numpy as np
import pytest
from numpy.polynomial import polynomial as P
from scipy.integrate import solve_ivp

from vibromodel import averaging as av
from vibromodel import averaging_printed as printed
from vibromodel import forces
from vibromodel.parameters import Scene

STRONG = Scene(mu=0.002)  # docs/model.md, Averaging and slow flow: mu = 0.002, Delta = 0.0007, the rest as the paper example
EPS = np.finfo(float).eps


def period_average(f, Omega, n=64):
    """Mean over one period 2 pi/Omega by the trapezoid rule: exact for trigonometric polynomials of
    degree < n, and psi^5 (beta sin - gamma cos 2) has degree 11."""
    t = 2 * math.pi / Omega * np.arange(n) / n
    return np.mean(f(t), axis=-1)


def psi(t, beta, gamma, Omega):
    return -beta * np.sin(Omega * t) / Omega**2 + gamma * np.cos(2 * Omega * t) / (4 * Omega**2)  # Eq. 46


def test_fast_moments_match_period_averages():
    beta, gamma, Omega = 0.3, 0.2, 1.7  # large, so that every moment matters
    m, q = av.fast_moments(beta, gamma, Omega)
    for j in range(6):
        m_j = period_average(lambda t: psi(t, beta, gamma, Omega) ** j, Omega)
        q_j = period_average(lambda t: (beta * np.sin(Omega * t) - gamma * np.cos(2 * Omega * t))
                             * psi(t, beta, gamma, Omega) ** j, Omega)
        scale = max(abs(m_j), (beta / Omega**2) ** j)  # size of the terms being averaged
        # the trapezoid rule is exact here (period_average), so only rounding remains: 64 samples of terms of size
        # <= scale, one rounding per addition: <= 64 EPS scale; q's terms carry the drive, of size ~beta
        assert m[j] == pytest.approx(m_j, abs=64 * EPS * scale)
        assert q[j] == pytest.approx(q_j, abs=64 * EPS * scale * beta)


def test_averaged_coefficients_equal_the_period_average_of_the_polynomial_model():
    """Independent of the binomial formula: average a(X + psi) - (beta sin - gamma cos 2) G3(X + psi) over
    a period, as a polynomial in X, by composing polynomials numerically."""
    scene = Scene(alpha=0.01, beta=0.2, gamma=0.1, Omega=1.3, R=1.2)
    a = np.array(forces.coefficients(scene.alpha, scene.gamma, scene.R))
    f = np.array(forces.series_g3(scene.R))
    t = 2 * math.pi / scene.Omega * np.arange(64) / 64
    total = np.zeros(6)
    for tk in t:
        shift = np.array([psi(tk, scene.beta, scene.gamma, scene.Omega), 1.0])  # X + psi as a polynomial in X
        drive = scene.beta * math.sin(scene.Omega * tk) - scene.gamma * math.cos(2 * scene.Omega * tk)
        for n, c in enumerate(a - drive * f):
            total += np.pad(c * P.polypow(shift, n), (0, 5 - n))
    # 64 samples x 6 polynomial terms of size <= ~1 (|X + psi| coefficients, a_k <= 1): random rounding
    # ~sqrt(384) x 1.1e-16 = 2e-15; atol 1e-14 is 5x that, and far below a wrong coefficient (O(alpha) = 1e-2)
    np.testing.assert_allclose(av.averaged_coefficients(scene), total / len(t), rtol=0, atol=1e-14)


def test_paper_example_numbers_of_errata():
    model = av.averaged(Scene())
    A, eq = model.eq.A, model.eq
    assert A[0] == pytest.approx(-1.99997e-4, abs=5e-10)  # corrected table row (50): Gamma = -1.99997e-4
    assert A[1] == pytest.approx(0.99706667, abs=5e-9)  # A1 = 0.99706667
    # row (58): k1 - A1 = 6.68e-5 and sqrt(k1) - sqrt(A1) = 3.34e-5, 3 digits; ours, 6.6750e-5, sits on the
    # rounding edge of the first, so one unit of the last digit is allowed there
    assert eq.k[1] - A[1] == pytest.approx(6.68e-5, abs=1e-7)
    assert math.sqrt(eq.k[1]) - math.sqrt(A[1]) == pytest.approx(3.34e-5, abs=5e-8)
    assert sum(A[k] * eq.x_e**k for k in range(6)) == pytest.approx(0.0, abs=8 * EPS)  # x_e is the root


def test_shifted_coefficients_are_the_taylor_coefficients_at_the_equilibrium():
    eq = av.equilibrium(STRONG)
    y = 0.013
    # two degree-5 Horner evaluations (about 10 roundings each) of coefficients <= 1 at arguments < 0.1, plus the
    # rounding of the shifted coefficients k: a few EPS each; 16 EPS with margin
    assert P.polyval(eq.x_e + y, eq.A) == pytest.approx(P.polyval(y, eq.k), abs=16 * EPS)


def free_oscillation(k, amplitude):
    """Exact frequency and first-harmonic amplitude of y'' + sum k_j y^j = 0 from y(0) = amplitude, y' = 0."""
    def rhs(_t, z):
        return [z[1], -P.polyval(z[0], k)]

    turn = lambda _t, z: z[1]  # noqa: E731 - y' = 0 again at half a period
    turn.direction = 1.0
    sol = solve_ivp(rhs, (0, 20), [amplitude, 0.0], method="DOP853", rtol=1e-13, atol=1e-15, events=turn,
                    dense_output=True)
    T = 2 * sol.t_events[0][0]
    t = T * np.arange(512) / 512  # trapezoid rule, periodic: converges geometrically
    y = np.concatenate([sol.sol(t[t <= T / 2])[0], sol.sol(T - t[t > T / 2])[0]])  # y(T - t) = y(t)
    a1 = 2 * np.mean(y * np.cos(2 * math.pi * t / T))
    return 2 * math.pi / T, a1


def test_lindstedt_backbone_matches_the_exact_free_oscillation_frequency():
    eq = av.equilibrium(STRONG)
    omega, a = free_oscillation(eq.k, 0.305)
    shift = omega - math.sqrt(eq.k[1])  # the backbone: omega = omega_e + kappa(a)
    lindstedt, first_order = (av.backbone(eq, kind).kappa(a) for kind in av.BACKBONES)
    # docs/model.md, Averaging and slow flow: 1.9e-7 with the Lindstedt kappa (the next term, O(r^6), is not modelled),
    # 1.1e-3 with the strict first-order kappa
    assert abs(lindstedt - shift) < 5e-7
    assert abs(first_order - shift) > 1e-3


def errata_branches():
    model = av.averaged(STRONG)
    flow = model.flow(model.omega_e - 0.0024)
    return flow, av.steady_states(flow, model.r_max)


def test_three_branches_at_sigma_minus_0_0024_as_in_errata():
    flow, states = errata_branches()
    assert [round(s.r, 5) for s in states] == [0.16628, 0.30374, 0.35107]  # docs/model.md, Averaging and slow flow table
    assert [s.kind for s in states] == ["stable focus", "saddle", "stable focus"]
    rho = sorted(m.real for m in states[1].multipliers(flow.omega))
    assert rho == pytest.approx([0.98533, 1.00217], abs=5e-6)  # exp(lambda T) column, 5 digits


@pytest.mark.parametrize("index", [0, 1, 2])
def test_steady_states_are_equilibria_and_the_jacobian_is_right(index):
    flow, states = errata_branches()
    s = states[index]
    assert np.abs(flow.rhs(s.A, s.B)).max() < 1e-14  # drive ~ 3.5e-4: residual at round-off
    J = flow.jacobian(s.A, s.B)
    h = 1e-7 * s.r  # central differences, error ~ h^2 |f'''| << 1e-9
    fd = np.column_stack([(np.array(flow.rhs(s.A + h * e[0], s.B + h * e[1]))
                           - np.array(flow.rhs(s.A - h * e[0], s.B - h * e[1]))) / (2 * h)
                          for e in ((1, 0), (0, 1))])
    np.testing.assert_allclose(J, fd, atol=1e-9)
    assert np.trace(J) == pytest.approx(-flow.mu, abs=8 * EPS)  # docs/model.md, Averaging and slow flow: tr J = -mu
    assert np.linalg.det(J) == pytest.approx(s.det, rel=1e-9)
    # |J| <= 5e-3 and the eigenvalues are ~1e-3 apart: LAPACK and the closed form (trace, det, a square root)
    # each round at ~EPS |J| = 1e-18; atol 1e-12 is 1e-9 of the eigenvalues and catches any wrong formula
    np.testing.assert_allclose(sorted(np.linalg.eigvals(J), key=lambda z: (z.real, z.imag)),
                               sorted(s.eigenvalues, key=lambda z: (z.real, z.imag)), atol=1e-12)


def test_folds_bound_the_three_branch_interval():
    model = av.averaged(STRONG)
    folds = av.folds(model)
    assert len(folds) == 2
    for fold in folds:
        # a fold is a zero of det, located to round-off (measured |det| ~ 5e-21); det is ~1e-6 on the branches
        # (|J| ~ 1e-3), so abs 1e-14 is 1e-8 of that: far above round-off, far below a point off the fold
        assert av.steady_state(model.flow(fold.omega), fold.r).det == pytest.approx(0.0, abs=1e-14)
    (lo, hi), d = (f.omega for f in folds), 1e-7
    count = [len(av.steady_states(model.flow(w), model.r_max)) for w in (lo - d, lo + d, hi - d, hi + d)]
    assert count == [1, 3, 3, 1]


def test_peak_amplitude_by_backbone_as_in_errata():
    """docs/model.md, Averaging and slow flow table: 0.3389 (correct kappa), 0.1733 (strict first order), 0.2884 (paper's coefficients)."""
    eq = av.equilibrium(STRONG)
    paper = printed.printed_backbone(eq.A[3], eq.A[5], eq.A[1])  # Eqs 59-60 with the correct A_k
    peaks = []
    for bb in (av.backbone(eq, "lindstedt"), av.backbone(eq, "first-order"), paper):
        model = av.Averaged(STRONG, eq, bb)
        peaks.append(round(max(s.r for s in av.steady_states(model.flow(model.omega_e - 0.002))), 4))
    assert peaks == [0.3389, 0.1733, 0.2884]


def test_paper_subcase_1a_lambdas_contradict_its_D():
    check = printed.subcase_1a_check()
    # Eq. 71 with the printed mu and D gives -4.7808e-4 and -5.2192e-4 (the corrected table, §5.2 1.a) ...
    assert check["lambda_from_eq71"] == pytest.approx([-4.7808e-4, -5.2192e-4], abs=5e-9)
    # ... while the printed pair has neither the sum -mu nor the product (mu^2 - D)/4 that Eq. 67 demands
    assert abs(check["sum_printed"] - check["sum_required"]) > 0.1 * check["mu"]
    assert abs(check["product_printed"] / check["product_required"] - 1) > 0.2


def test_paper_classification_has_no_saddle_and_the_wrong_trace():
    flow, states = errata_branches()
    kinds = [printed.printed_classification(flow.mu, s.det) for s in states]
    assert "saddle" not in " ".join(kinds) and kinds[1].startswith("not covered")
    # tr J = +mu in Eq. 68: negative damping would be called stable
    assert printed.printed_classification(-0.001, 1e-7) == "unstable node"
    assert av.classify(-0.001, 1e-7, 1.0, 1.0) == "unstable node"
    assert printed.printed_classification(0.001, 1e-8).startswith("stable")


def test_undamped_unforced_steady_state_is_the_rest_point():
    model = av.averaged(Scene(Delta=0.0))
    (state,) = av.steady_states(model.flow())
    assert state.r == 0.0 and state.kind.startswith("stable")
