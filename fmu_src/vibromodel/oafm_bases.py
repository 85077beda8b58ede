"""Named OAFM basis families: each gives a transient-domain and a steady-domain `Basis`.

`paper`: the paper's ansatz with the corrections of docs/model.md, OAFM analytic solution — Eq. 15 + Eq. 29 on [0, tau*]
(C1..C4), Eq. 33 + Eq. 35 on tau > tau* (C5..C7, L = x'' + p*^2 x with p*^2 = a1).

`harmonic`: ours. L = x'' + mu x' + a1 x (Eq. 11) on both domains; x0 is the linear response of L to
the linear forcing of Eq. 7 (gamma + Delta cos w tau + beta sin W tau - gamma cos 2W tau) from the
domain's initial state, so x0 already holds the forced vibration the paper's x0 lacks (docs/model.md, The paper's example reproduced).
The y_i answer forcings e^(-m mu s/2)(cos | sin)(nu s) for every combination
nu = |i q + j omega + k Omega| with i + |j| + |k| <= order and decay index m = i, i+2, ..., <= order:
the harmonics a polynomial nonlinearity makes of a decaying free vibration (frequency q, decay
mu/2) and the forcings. (m, nu) = (1, q) is the resonant case: secular terms that absorb the
nonlinear frequency shift. Near the primary resonance many of these frequencies nearly coincide
(omega ~ q); the Tikhonov term of the fit (oafm.RIDGE) keeps their C_i from cancelling each other.
"""
from __future__ import annotations

import math

from .closedform import LinearOperator, Terms
from .forces import coefficients
from .oafm import Basis
from .parameters import ParameterError, Scene


def linear_forcing(scene: Scene, start: float) -> list[tuple[float, float, float]]:
    """(nu, C, S) with sum C cos(nu s) + S sin(nu s) = gamma + Delta cos w tau + beta sin W tau - gamma cos 2W tau,
    tau = start + s: the terms of Eq. 7 that do not depend on x."""
    rows = [(0.0, -coefficients(scene.alpha, scene.gamma, scene.R)[0], 0.0)]  # -a0 = gamma
    if scene.Delta:
        phase = scene.omega * start
        rows.append((scene.omega, scene.Delta * math.cos(phase), -scene.Delta * math.sin(phase)))
    if scene.beta:
        phase = scene.Omega * start
        rows.append((scene.Omega, scene.beta * math.sin(phase), scene.beta * math.cos(phase)))
    if scene.gamma:
        phase = 2.0 * scene.Omega * start
        rows.append((2.0 * scene.Omega, -scene.gamma * math.cos(phase), scene.gamma * math.sin(phase)))
    return rows


def eq11_operator(scene: Scene) -> LinearOperator:
    """L[x] = x'' + mu x' + a1 x (Eq. 11). Raises ParameterError unless it oscillates (a1 > mu^2/4), which
    the analytic solutions built on it (OAFM, the corrected reference) need."""
    a1 = coefficients(scene.alpha, scene.gamma, scene.R)[1]
    if not a1 > 0.25 * scene.mu**2:
        name = "gamma" if 4.0 * scene.gamma > 8.0 * scene.alpha else "alpha"  # the larger pull of a1's formula
        raise ParameterError(name, getattr(scene, name), f"a1 = 1 - 8 alpha/(3R) - 4 gamma/(3R) = {a1:.6g} must exceed "
                             f"mu^2/4 = {0.25 * scene.mu**2:.6g}: the analytic solution needs an oscillating Eq. 11")
    return LinearOperator(scene.mu, a1)


def forced_x0(L: LinearOperator, scene: Scene, start: float, x_init: float, v_init: float) -> tuple[Terms, Terms]:
    """(x0, forcing): L[x0] = linear forcing of Eq. 7, x0(0) = x_init, x0'(0) = v_init."""
    x0, forcing = L.free(x_init, v_init), Terms.of([])
    for nu, C, S in linear_forcing(scene, start):
        x0 = x0 + L.response(0.0, nu, C, S)
        forcing = forcing + Terms.of([(0, 0.0, nu, C, S)])
    return x0, forcing


# ---------------------------------------------------------------- harmonic (ours)

def harmonic_frequencies(scene: Scene, q: float, order: int) -> list[tuple[int, float]]:
    """(m, nu): decay index and frequency of each forcing pair, each pair once."""
    j_max = order if scene.Delta else 0
    k_max = min(2, order) if (scene.beta or scene.gamma) else 0
    chosen: list[tuple[int, float]] = []
    for i in range(order + 1):
        for j in range(-j_max, j_max + 1):
            for k in range(-k_max, k_max + 1):
                if i + abs(j) + abs(k) > order:
                    continue
                nu = abs(i * q + j * scene.omega + k * scene.Omega)
                for m in range(i, order + 1, 2):
                    if not any(mm == m and abs(nn - nu) <= 1e-12 * max(1.0, nu) for mm, nn in chosen):
                        chosen.append((m, nu))
    return chosen


def harmonic_basis(scene: Scene, start: float, x_init: float, v_init: float, order: int) -> Basis:
    L = eq11_operator(scene)
    functions, forcings, labels = [], [], []
    for m, nu in harmonic_frequencies(scene, L.q, order):
        sigma = 0.5 * m * scene.mu
        for C, S, trig in ((1.0, 0.0, "cos"), (0.0, 1.0, "sin")):
            if nu == 0.0 and S:
                continue
            functions.append(L.response(sigma, nu, C, S))
            forcings.append(Terms.of([(0, sigma, nu, C, S)]))
            labels.append(f"e^(-{sigma:.6g} s) {trig}({nu:.6g} s)")
    x0, x0_forcing = forced_x0(L, scene, start, x_init, v_init)
    return Basis(f"harmonic order {order}", L, x0, x0_forcing, tuple(functions), tuple(forcings), tuple(labels))


# ---------------------------------------------------------------- paper (docs/model.md, OAFM analytic solution)

def paper_transient_basis(scene: Scene, start: float, x_init: float, v_init: float, order: int = 0) -> Basis:
    """Eq. 15 for x0 (L[x0] = gamma) and Eq. 29 for x1, with M1..M4 of Eq. 25 corrected.

    x1 = x10 (Eq. 24: responses to e^(-mu s)(C1 cos ps + C2 sin ps + C3 cos 3ps + C4 sin 3ps)) with the
    M1 part exchanged for the paper's x20 choice (Eq. 26): M1 (e^(mu s/35) - e^(mu s/30)) sin ps.
    """
    L = eq11_operator(scene)
    p, mu = L.q, scene.mu
    gamma_over_a1 = scene.gamma / L.k
    x0 = Terms.of([(0, 0.0, 0.0, gamma_over_a1, 0.0)]) + L.free(x_init - gamma_over_a1, v_init)  # L[x0] = gamma
    # Eq. 26 minus the M1 part of Eq. 24: (e^(mu s/35) - e^(mu s/30) - e^(-mu s) + e^(-mu s/2)) sin ps
    x20_swap = Terms.of([(0, -mu / 35, p, 0.0, 1.0), (0, -mu / 30, p, 0.0, -1.0),
                         (0, mu, p, 0.0, -1.0), (0, mu / 2, p, 0.0, 1.0)])
    functions, forcings = [], []
    for nu, C, S in ((p, 1.0, 0.0), (p, 0.0, 1.0), (3 * p, 1.0, 0.0), (3 * p, 0.0, 1.0)):
        y = L.response(mu, nu, C, S)
        M1 = y.b[0] if nu == p else 0.0  # dM1/dC_i: the sin coefficient of the e^(-mu s) sin ps term
        functions.append(y + x20_swap.scaled(M1))
        forcings.append(Terms.of([(0, mu, nu, C, S)]) + L.apply(x20_swap).scaled(M1))
    return Basis("paper Eq. 29", L, x0, Terms.of([(0, 0.0, 0.0, scene.gamma, 0.0)]), tuple(functions),
                 tuple(forcings), ("C1", "C2", "C3", "C4"))


def paper_steady_basis(scene: Scene, start: float, x_init: float, v_init: float, order: int = 0) -> Basis:
    """Eq. 33 and Eq. 35 corrected: L = x'' + p*^2 x with p*^2 = a1, forcings C5..C7 sin(n p* s)."""
    L = LinearOperator(0.0, coefficients(scene.alpha, scene.gamma, scene.R)[1])
    functions = tuple(L.response(0.0, n * L.q, 0.0, 1.0) for n in (3, 5, 7))
    forcings = tuple(Terms.of([(0, 0.0, n * L.q, 0.0, 1.0)]) for n in (3, 5, 7))
    return Basis("paper Eq. 35", L, L.free(x_init, v_init), Terms.of([]), functions, forcings, ("C5", "C6", "C7"))


FAMILIES = {
    "harmonic": (harmonic_basis, harmonic_basis),
    "paper": (paper_transient_basis, paper_steady_basis),
}
