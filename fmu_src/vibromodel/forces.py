"""Forces of Eq. 3 and their series (5), coefficients a0..a5 of Eq. 8 (docs/model.md, Series and polynomial model).

Scalar functions on Python floats: they sit on the integrators' hot path.
"""
from __future__ import annotations

import math


def hertz(x: float) -> float:
    """Hertz contact force (1 + 2x/3)^(3/2) of Eq. 3; zero once contact is lost (no tension)."""
    s = 1.0 + 2.0 * x / 3.0
    return s * math.sqrt(s) if s > 0.0 else 0.0


def potential(x: float) -> float:
    """V(x) = -x + (3/5)(1 + 2x/3)^(5/2) in contact, -x beyond the contact edge x = -3/2: the potential of the
    unforced, undamped Eq. 3, x'' = 1 - H(x) = -V'(x) (V' = H - 1 is continuous at the edge, V(-3/2) = 3/2)."""
    s = 1.0 + 2.0 * x / 3.0
    return -x + (0.6 * s * s * math.sqrt(s) if s > 0.0 else 0.0)


def contact_indentation(x: float) -> float:
    """1 + 2x/3 = z/z_s: positive in contact, <= 0 when the mass has left the contact."""
    return 1.0 + 2.0 * x / 3.0


def in_contact(x: float, v: float, a: float) -> bool:
    """The contact flag at a state (x, v, x'' = a): in contact where the indentation is positive; exactly on the
    contact surface (x = -3/2) the motion decides: moving in (v > 0), or at rest with x'' > 0 (about to indent)."""
    indentation = contact_indentation(x)
    return indentation > 0.0 or (indentation == 0.0 and (v > 0.0 or (v == 0.0 and a > 0.0)))


def cos_double_angle(s: float) -> float:
    """cos 2 theta from s = sin theta: 1 - 2 s^2, how the model computes cos 2 Omega t (one sine per time for both AC
    terms; core twin: model.h vm_cos_double_angle). Against libm's cos(2 theta) at the same angle theta, with s within
    2u of sin theta (u = 2^-53; glibc's sin is within an ulp): s*s rounds with relative error u, so 2 s^2 carries
    at most 2 (2*2u + u) = 10u absolute, and the subtraction from 1 rounds by at most u: within 11u ~ 1.2e-15 of
    cos 2 theta, a few ulps of an O(1) value, where libm's own cos is within an ulp."""
    return 1.0 - 2.0 * (s * s)


def electrostatic(t: float, x: float, alpha: float, beta: float, gamma: float, Omega: float, R: float,
                  drive: tuple[float, float] | None = None) -> float:
    """Right-hand electrostatic terms of Eq. 3: alpha*F2(x) + (beta sin Omega t + gamma(1 - cos 2 Omega t)) F3(x).
    drive: (sin Omega t, cos 2 Omega t) given (default: computed here, cos 2 Omega t by cos_double_angle)."""
    u = 2.0 * x / (3.0 * R)
    f3 = 1.0 / ((1.0 - u) * (1.0 - u))
    force = alpha * (f3 - 1.0 / ((1.0 + u) * (1.0 + u)))
    if beta or gamma:
        if drive is None:
            s = math.sin(Omega * t)
            c = cos_double_angle(s)
        else:
            s, c = drive
        force += (beta * s + gamma * (1.0 - c)) * f3
    return force


def horner(coefficients, x: float) -> float:
    """sum c_k x^k for coefficients (c_0, c_1, ...)."""
    value = 0.0
    for c in reversed(coefficients):
        value = value * x + c
    return value


# Series (5), corrected (docs/model.md, Series and polynomial model): coefficients of x^0 .. x^5.
def series_g1() -> tuple[float, ...]:
    """G1 ~ (1 + 2x/3)^(3/2); contains no R."""
    return (1.0, 1.0, 1.0 / 6.0, -1.0 / 54.0, 1.0 / 216.0, -1.0 / 648.0)


def series_g1_printed(R: float) -> tuple[float, ...]:
    """G1 as printed in Eq. 5 (wrong x^4, x^5 terms and a spurious R)."""
    return (1.0, 1.0 / R, 1.0 / (6.0 * R**2), -1.0 / (54.0 * R**3), 1.0 / (432.0 * R**4), 1.0 / (1296.0 * R**5))


def series_g2(R: float) -> tuple[float, ...]:
    """G2 ~ (1 - 2x/3R)^-2 - (1 + 2x/3R)^-2."""
    return (0.0, 8.0 / (3.0 * R), 0.0, 64.0 / (27.0 * R**3), 0.0, 128.0 / (81.0 * R**5))


def series_g3(R: float) -> tuple[float, ...]:
    """G3 ~ (1 - 2x/3R)^-2."""
    return (1.0, 4.0 / (3.0 * R), 4.0 / (3.0 * R**2), 32.0 / (27.0 * R**3), 80.0 / (81.0 * R**4), 64.0 / (81.0 * R**5))


def linear_stiffness(alpha: float, gamma: float, R: float) -> float:
    """a1 of Eq. 7, coefficients(alpha, gamma, R)[1] to the bit (the same operations), without the others."""
    return 1.0 - alpha * (8.0 / (3.0 * R)) - gamma * (4.0 / (3.0 * R))


def coefficients(alpha: float, gamma: float, R: float) -> tuple[float, ...]:
    """a0..a5 of Eq. 7 (corrected Eq. 8): a_k = G1_k - alpha G2_k - gamma G3_k, a0 = -gamma."""
    g1, g2, g3 = series_g1(), series_g2(R), series_g3(R)
    return (-gamma,) + tuple(g1[k] - alpha * g2[k] - gamma * g3[k] for k in range(1, 6))


def coefficients_printed(alpha: float, gamma: float, R: float) -> tuple[float, ...]:
    """a0..a5 exactly as printed in Eq. 8 (to reproduce the paper)."""
    return (
        -gamma,
        1.0 - 8.0 * alpha / (3.0 * R) - 4.0 * gamma / (3.0 * R),
        1.0 / 6.0 - 4.0 * gamma / (3.0 * R**2),
        -1.0 / 54.0 - 64.0 * alpha / (27.0 * R**3),
        1.0 / 432.0 - 80.0 * gamma / (81.0 * R**5),
        1.0 / 1296.0 - 128.0 * alpha / (81.0 * R**5) - 64.0 * gamma / (81.0 * R**5),
    )


# Derivatives d/dx of the forces of Eq. 3 (variational equations of the shooting method, issue 4).
def hertz_stiffness(x: float) -> float:
    """dH/dx = (1 + 2x/3)^(1/2) in contact, 0 without: continuous at contact loss (H is C^1 there)."""
    s = 1.0 + 2.0 * x / 3.0
    return math.sqrt(s) if s > 0.0 else 0.0


def electrostatic_gradient(x: float, alpha: float, drive: float, R: float) -> float:
    """d/dx of alpha[(1-u)^-2 - (1+u)^-2] + drive (1-u)^-2, u = 2x/(3R), at a fixed drive value."""
    u = 2.0 * x / (3.0 * R)
    upper, lower = 1.0 / (1.0 - u) ** 3, 1.0 / (1.0 + u) ** 3
    return 4.0 / (3.0 * R) * (alpha * (upper + lower) + drive * upper)


def electrostatic_stiffness(t: float, x: float, alpha: float, beta: float, gamma: float, Omega: float,
                            R: float) -> float:
    """d/dx of electrostatic(t, x, ...): the drive beta sin Omega t + gamma(1 - cos 2 Omega t) at time t."""
    s = math.sin(Omega * t)
    drive = beta * s + gamma * (1.0 - cos_double_angle(s))
    return electrostatic_gradient(x, alpha, drive, R)


def electrostatic_mean(x: float, alpha: float, gamma: float, R: float) -> float:
    """Mean of electrostatic(t, x, ...) over the AC period at fixed x: alpha G2(x) + gamma G3(x) (exact forms)."""
    u = 2.0 * x / (3.0 * R)
    return (alpha + gamma) / ((1.0 - u) * (1.0 - u)) - alpha / ((1.0 + u) * (1.0 + u))


def electrostatic_mean_stiffness(x: float, alpha: float, gamma: float, R: float) -> float:
    """d/dx of electrostatic_mean: the drive at its mean value gamma."""
    return electrostatic_gradient(x, alpha, gamma, R)
