"""Series (5) and coefficients (8) against SymPy Taylor expansions and the corrected explicit formulas."""
import math

import pytest
import sympy as sp

from vibromodel import forces
from vibromodel.fidelities import make_model
from vibromodel.parameters import Scene

x = sp.Symbol("x")
R_VALUES = [1.0, 0.7, 2.5]


def taylor(expr, order=6):
    series = sp.series(expr, x, 0, order).removeO()
    return [float(series.coeff(x, k)) for k in range(order)]


def test_g1_is_the_taylor_series_of_the_hertz_force():
    # the coefficients are rationals (1, 1, 1/6, -1/54, ...) that each side rounds to double once or after a few
    # operations (2^-53 = 1.1e-16 relative each): rel 1e-15 allows ~9 roundings; a wrong term is off by O(1)
    assert forces.series_g1() == pytest.approx(taylor((1 + 2 * x / 3) ** sp.Rational(3, 2)), rel=1e-15)


@pytest.mark.parametrize("R", R_VALUES)
def test_g2_g3_are_taylor_series_of_the_electrostatic_terms(R):
    u = 2 * x / (3 * sp.nsimplify(R))
    # powers of 2/(3R) up to the 5th and a factor: < 20 roundings of 1.1e-16 relative each, <= 2.2e-15: rel 1e-14
    # keeps a margin of 4; abs 1e-15 for the even terms of G2, exactly 0 in SymPy and 0 or a rounding here
    assert forces.series_g2(R) == pytest.approx(taylor(1 / (1 - u) ** 2 - 1 / (1 + u) ** 2), rel=1e-14, abs=1e-15)
    assert forces.series_g3(R) == pytest.approx(taylor(1 / (1 - u) ** 2), rel=1e-14)


@pytest.mark.parametrize("R", R_VALUES)
def test_coefficients_match_errata_formulas(R):
    alpha, gamma = 0.003, 0.0007
    expected = (  # docs/model.md, Series and polynomial model, Eq. 8 corrected
        -gamma,
        1 - 8 * alpha / (3 * R) - 4 * gamma / (3 * R),
        1 / 6 - 4 * gamma / (3 * R**2),
        -1 / 54 - 64 * alpha / (27 * R**3) - 32 * gamma / (27 * R**3),
        1 / 216 - 80 * gamma / (81 * R**4),
        -1 / 648 - 128 * alpha / (81 * R**5) - 64 * gamma / (81 * R**5),
    )
    # each coefficient is a few products and a sum of O(1) and O(alpha, gamma) terms on both sides, < 20 roundings
    # of 1.1e-16 relative: rel 1e-14 has a margin of 4, and a wrong term (size >= gamma/R^5 ~ 1e-5) shows
    assert forces.coefficients(alpha, gamma, R) == pytest.approx(expected, rel=1e-14)


def test_example_coefficient_values_of_errata_table():
    correct = forces.coefficients(0.001, 0.0002, 1.0)
    printed = forces.coefficients_printed(0.001, 0.0002, 1.0)
    # the errata table prints 8 significant digits: its rounding is <= 5e-8 relative, inside rel 1e-7
    assert correct[1:] == pytest.approx([0.99706667, 0.1664, -0.021125926, 0.0044320988, -0.0032814815], rel=1e-7)
    assert printed[3:] == pytest.approx([-0.020888889, 0.0021172840, -0.00096666667], rel=1e-7)


def test_polynomial_model_is_the_taylor_expansion_of_the_exact_model():
    """exact - polynomial right-hand side = c6 x^6 + c7 x^7 + O(x^8) at fixed t (AC terms included)."""
    scene = Scene(alpha=0.004, beta=0.002, gamma=0.001, R=0.8)
    exact, poly = make_model(scene, 0), make_model(scene, 1)
    R = sp.nsimplify(scene.R)
    u = 2 * x / (3 * R)
    for t in (0.3, 1.7):
        drive = scene.beta * math.sin(scene.Omega * t) + scene.gamma * (1 - math.cos(2 * scene.Omega * t))
        rhs = -(1 + 2 * x / 3) ** sp.Rational(3, 2) + scene.alpha * (1 / (1 - u) ** 2 - 1 / (1 + u) ** 2) \
            + drive / (1 - u) ** 2
        c = taylor(rhs, order=8)
        h = 0.01
        difference = exact.accel(t, h, 0.0, 0.0) - poly.accel(t, h, 0.0, 0.0)
        # remainder O(h^8): relative size ~ h^2 = 1e-4; rounding of O(1) values 2e-16/h^6 = 2e-4
        assert difference == pytest.approx(c[6] * h**6 + c[7] * h**7, rel=2e-3)


def test_hertz_force_is_zero_without_contact_and_never_complex():
    assert forces.hertz(-1.5) == 0.0 and forces.hertz(-3.0) == 0.0
    assert forces.hertz(0.0) == 1.0
    # default rel 1e-6: 1 + 2x/3 = 0.067 is computed two ways, differing by the cancellation's rounding
    # (~ulp(1)/0.067 = 3e-15 relative); the check is that this branch gives the Hertz force, not 0 or a complex
    assert forces.hertz(-1.4) == pytest.approx((1 - 2.8 / 3) ** 1.5)


def test_the_contact_flag_on_the_surface_follows_the_motion():
    """forces.in_contact (the twin of core/model.c's vm_in_contact): the indentation's sign off the surface;
    exactly on it (x = -3/2) moving in, or at rest and pushed in."""
    in_contact = forces.in_contact
    assert in_contact(-1.4, -5.0, -5.0) and not in_contact(-1.6, 5.0, 5.0)  # off the surface: the side decides
    assert in_contact(-1.5, 1e-300, -1.0) and not in_contact(-1.5, -1e-300, 1.0)  # on it, moving: the direction
    assert in_contact(-1.5, 0.0, 1.0) and not in_contact(-1.5, 0.0, -1.0)  # at rest: the acceleration
    assert not in_contact(-1.5, 0.0, 0.0) and not in_contact(-1.5, 0.0, float("nan"))  # in equilibrium: not


def test_cos_double_angle_is_within_eleven_units_of_the_true_cosine():
    """The model's cos 2 Omega t from sin Omega t (forces.cos_double_angle: 1 - 2 s^2, one sine per time) against
    cos(2 theta) at 40 digits (mpmath) for the double theta, over the paper scene's angles Omega t (Omega = 2,
    t in [0, 200]), angles up to 1e5 and the points where cos 2 theta is 0 or +-1. The bound, u = 2^-53: s is within
    2u of sin theta (glibc's sin, under an ulp), s*s rounds by u, so 2 s^2 carries at most 2 (2*2u + u) = 10u and
    the subtraction from 1 rounds by at most u: 11u absolute (libm's cos(2 theta) itself is within an ulp, u of an
    O(1) value). A wrong formula (1 - s^2, 2 s^2 - 1) is off by O(1)."""
    import random

    import mpmath

    u = 2.0 ** -53
    rng = random.Random(35)
    angles = [2.0 * t for t in (rng.uniform(0.0, 200.0) for _ in range(600))]
    angles += [rng.uniform(-1e5, 1e5) for _ in range(300)]
    angles += [k * math.pi / 4 for k in range(-8, 9)] + [0.0, 1e-300, 5e-324]
    with mpmath.workdps(40):
        worst = max(abs(forces.cos_double_angle(math.sin(theta)) - mpmath.cos(2 * mpmath.mpf(theta)))
                    for theta in angles)
    assert worst <= 11 * u
