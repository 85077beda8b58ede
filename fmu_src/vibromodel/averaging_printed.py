"""PAPER §5 exactly as printed (Eqs 50, 58, 59-60, 68, 71, §5.1, §5.2): only to reproduce the paper and
show how it differs from docs/model.md, Averaging and slow flow, which `averaging` implements.

What is wrong here (the paper's errata (docs/model.md), rows (50), (56)-(60), (67)-(71), §5.1, §5.2): Gamma has the wrong sign
and Omega^4 for Omega^8; the cubic backbone term is 4x too large, the quintic 8x, the dominant
quadratic (k2^2) contribution is missing; tr J is -mu, not mu; §5.1 has no saddle case; the printed
lambdas of Subcase 1.a contradict the printed D.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from . import forces
from .averaging import Backbone, SlowFlow
from .parameters import Scene


def printed_coefficients(scene: Scene) -> tuple[float, ...]:
    """Gamma, A1..A5 of Eq. 50 as printed, from the printed a_k of Eq. 8."""
    a = forces.coefficients_printed(scene.alpha, scene.gamma, scene.R)
    b, g, W = scene.beta, scene.gamma, scene.Omega
    m2 = (g**2 + 16 * b**2) / (32 * W**4)  # Eq. 47
    return (g + m2 * a[2] + 3 * (4 * g**4 + g**2 * b**2 + 4 * b**4) / (32 * W**4) * a[4],
            a[1] + 3 * m2 * a[3] + 15 * (4 * g**4 + g**2 * b**2 + 4 * b**2) / (32 * W**8) * a[5],
            a[2] + 6 * m2 * a[4],
            a[3] + 10 * m2 * a[5],
            a[4],
            a[5])


def printed_theta(Gamma: float, A: tuple[float, ...], a1: float) -> float:
    """theta of Eq. 58 (corrected: the odd-Gamma terms have the wrong sign)."""
    return (2 * Gamma * A[2] / a1**1.5 + 3 * Gamma**2 * A[3] / a1**2.5 + 4 * Gamma**3 * A[4] / a1**3.5
            + 5 * Gamma**4 * A[5] / a1**4.5)


@dataclass(frozen=True)
class PrintedAveraged:
    """The slow flow of Eqs 59-60 in tau-time: A' = -mu/2 A - nu_p B, B' = -mu/2 B + nu_p A + Delta/(2 sqrt a1),
    nu_p = delta - theta/2 - (3 A3/(2 sqrt a1)) r^2 - (5 A5/(2 sqrt a1)) r^4, delta = omega - sqrt(a1).

    Same interface as `averaging.Averaged` (omega_e, r_max, backbone, flow(omega)), so the same root
    finder and fold tracer apply.
    """

    scene: Scene
    a1: float
    theta: float
    backbone: Backbone
    r_max: float = 1.5

    @property
    def omega_e(self) -> float:
        """Where the printed detuning delta - theta/2 vanishes."""
        return math.sqrt(self.a1) + self.theta / 2

    def flow(self, omega: float | None = None) -> SlowFlow:
        s = self.scene
        omega = s.omega if omega is None else omega
        return SlowFlow(s.mu, omega, omega - self.omega_e, s.Delta / (2 * math.sqrt(self.a1)), self.backbone)


def printed_backbone(A3: float, A5: float, a1: float) -> Backbone:
    """kappa of Eqs 59-60: (3 A3/(2 sqrt a1)) r^2 + (5 A5/(2 sqrt a1)) r^4 (4x and 8x the first-order terms)."""
    return Backbone(3 * A3 / (2 * math.sqrt(a1)), 5 * A5 / (2 * math.sqrt(a1)), "paper")


def printed_averaged(scene: Scene) -> PrintedAveraged:
    A = printed_coefficients(scene)
    a1 = forces.coefficients_printed(scene.alpha, scene.gamma, scene.R)[1]
    return PrintedAveraged(scene, a1, printed_theta(A[0], A, a1), printed_backbone(A[3], A[5], a1))


def printed_classification(mu: float, det: float) -> str:
    """§5.1 as printed: tr J = mu (Eq. 68), D = tr^2 - 4 det (Eq. 70); Case 1 needs det > 0, and
    det < 0 (a saddle) is not among the printed cases."""
    trace = mu
    D = trace**2 - 4 * det
    if det < 0:
        return "not covered by §5.1 (det J < 0 is not among the printed cases)"
    if D > 0:
        return "stable node" if trace > 0 else "unstable node"  # Subcases 1.a, 1.b
    if D < 0:
        return "stable focus" if trace > 0 else ("center" if trace == 0 else "unstable focus")  # 2.a-2.c
    return "stable node" if trace > 0 else ("no motion" if trace == 0 else "unstable node")  # 3.a-3.c


# §5.2 Subcase 1.a as printed: mu, D, and the printed eigenvalues.
SUBCASE_1A = {"mu": 0.001, "D": 1.921258e-9, "lambda": (-0.000378, -0.000519)}


def printed_eigenvalues(mu: float, D: float) -> tuple[float, float]:
    """Eq. 71 with tr J = mu (Eq. 68): lambda = -tr/2 +- sqrt(D)/2."""
    return -mu / 2 + math.sqrt(D) / 2, -mu / 2 - math.sqrt(D) / 2


def subcase_1a_check() -> dict:
    """Subcase 1.a's arithmetic: Eq. 71 from the printed mu and D, against the printed lambdas.

    Vieta for lambda^2 + mu lambda + det = 0 (the trace slip cancels in Eq. 71): lambda1 + lambda2 = -mu
    and lambda1 lambda2 = det = (mu^2 - D)/4. The printed pair satisfies neither.
    """
    mu, D, printed = SUBCASE_1A["mu"], SUBCASE_1A["D"], SUBCASE_1A["lambda"]
    return {
        "mu": mu, "D": D,
        "lambda_printed": list(printed),
        "lambda_from_eq71": list(printed_eigenvalues(mu, D)),
        "sum_printed": printed[0] + printed[1], "sum_required": -mu,
        "product_printed": printed[0] * printed[1], "product_required": (mu * mu - D) / 4,
    }
