"""The paper's OAFM formulas exactly as printed, with its printed constants: only to reproduce the paper.

Eq. 30 with M1..M4 of Eq. 25 as printed (wrong signs in M2, M3; misplaced e^(-mu tau) in the M3 term),
C1..C4 of Eq. 37 on [0, tau*]; Eq. 33 (without 1/p*) + Eq. 35 (without 1/(8 p*^2) ...) with C5..C7 and
p* = 0.988 of Eq. 38 beyond. docs/model.md, OAFM analytic solution; The paper's example reproduced list what is wrong; `oafm_bases.paper_*` is the corrected
form of the same ansatz.
"""
from __future__ import annotations

import math

from .closedform import Terms
from .oafm import AnalyticSolution, Piece, continue_from
from .oafm_bases import eq11_operator
from .parameters import Scene

C1_C4 = (0.030429, 0.00073852, -0.000338155, 0.000342986)  # Eq. 37
C5_C7 = (-0.000003211, 0.000016621, 0.0000563803)  # Eq. 38
TAU_STAR, P_STAR = 50.0, 0.988  # Eq. 37, 38


def printed_m(scene: Scene, C) -> tuple[float, float, float, float]:
    """M1..M4 of Eq. 25 as printed (corrected: M2 and M3 have the wrong sign of the mu p term)."""
    L = eq11_operator(scene)
    a1, mu, p = L.k, scene.mu, L.q
    C1, C2, C3, C4 = C
    D1 = mu**2 * p**2 + (a1 - p**2) ** 2
    D3 = 9 * mu**2 * p**2 + (a1 - 9 * p**2) ** 2
    return ((-mu * p * C1 + (a1 - p**2) * C2) / D1, ((a1 - p**2) * C1 - mu * p * C2) / D1,
            ((a1 - 9 * p**2) * C3 - 3 * mu * p * C4) / D3, (-3 * mu * p * C3 + (a1 - 9 * p**2) * C4) / D3)


def printed_eq30(scene: Scene, C=C1_C4) -> Terms:
    """x~(tau) of Eq. 30 term by term, as printed."""
    L = eq11_operator(scene)
    mu, p, A = scene.mu, L.q, scene.x_start
    g = scene.gamma / L.k
    M1, M2, M3, M4 = printed_m(scene, C)
    return Terms.of([
        (0, 0.0, 0.0, g, 0.0), (0, mu / 2, p, A - g, (A - g) * mu / (2 * p)),  # Eq. 15
        (0, -mu / 35, p, 0.0, M1), (0, -mu / 30, p, 0.0, -M1),  # M1 (e^(mu tau/35) - e^(mu tau/30)) sin p tau
        (0, mu, p, M2, 0.0), (0, mu / 2, p, -M2, M2 * mu / (2 * p)),  # M2 [...]
        (0, mu, 3 * p, M3, 0.0), (0, 3 * mu / 2, p, -M3, M3 * mu / (2 * p)),  # M3 e^(-mu tau)[cos 3p tau - e^(-mu tau/2)(...)]
        (0, mu, 3 * p, 0.0, M4), (0, mu / 2, p, 0.0, -3 * M4),  # M4 (e^(-mu tau) sin 3p tau - 3 e^(-mu tau/2) sin p tau)
    ]).merged()


def printed_steady(x_star: float, v_star: float, C=C5_C7, p_star: float = P_STAR) -> Terms:
    """Eq. 33 + Eq. 35 as printed, in s = tau - tau*: x~(tau*) cos p*s + x~'(tau*) sin p*s + C5[3 sin - sin 3] + ..."""
    rows = [(0, 0.0, p_star, x_star, v_star)]
    for c, n in zip(C, (3, 5, 7)):
        rows += [(0, 0.0, p_star, 0.0, n * c), (0, 0.0, n * p_star, 0.0, -c)]
    return Terms.of(rows).merged()


def printed_solution(scene: Scene) -> AnalyticSolution:
    """The paper's analytic solution on [0, 50] and beyond, all as printed."""
    first = Piece(start=0.0, end=TAU_STAR, basis_name="Eq. 30 as printed", C=C1_C4, x=printed_eq30(scene))
    second = Piece(start=TAU_STAR, end=math.inf, basis_name="Eq. 33 + 35 as printed", C=C5_C7,
                   x=printed_steady(*continue_from(first, TAU_STAR)))
    return AnalyticSolution([first, second])
