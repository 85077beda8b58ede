"""Closed forms for the OAFM: sums of damped harmonics and the responses of L (docs/model.md, OAFM analytic solution).

A `Terms` object is f(s) = sum_j s^m_j e^(-sigma_j s) (a_j cos nu_j s + b_j sin nu_j s), m_j in {0, 1}.
The set is closed under d/ds, so x, x' and x'' of an analytic solution are all exact closed forms.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# |P(s)| below this (relative to k + sigma^2 + nu^2) is treated as exact resonance with L.
RESONANCE_TOLERANCE = 1e-14


@dataclass(frozen=True)
class Terms:
    """f(s) = sum_j s^power_j e^(-sigma_j s) (a_j cos nu_j s + b_j sin nu_j s)."""

    power: np.ndarray
    sigma: np.ndarray
    nu: np.ndarray
    a: np.ndarray
    b: np.ndarray

    @staticmethod
    def of(rows) -> "Terms":
        """From rows (power, sigma, nu, a, b)."""
        rows = list(rows)
        if not rows:
            return Terms(*(np.zeros(0) for _ in range(5)))
        power, sigma, nu, a, b = (np.array(column, dtype=float) for column in zip(*rows))
        return Terms(power, sigma, nu, a, b)

    def rows(self):
        return zip(self.power, self.sigma, self.nu, self.a, self.b)

    def __len__(self) -> int:
        return len(self.a)

    def __add__(self, other: "Terms") -> "Terms":
        return Terms(*(np.concatenate([getattr(self, f), getattr(other, f)]) for f in _FIELDS))

    def scaled(self, c: float) -> "Terms":
        return Terms(self.power, self.sigma, self.nu, c * self.a, c * self.b)

    def derivative(self) -> "Terms":
        """d/ds: (e^(-sigma s)(a cos + b sin))' = e^(-sigma s)((-sigma a + nu b) cos + (-sigma b - nu a) sin)."""
        da = -self.sigma * self.a + self.nu * self.b
        db = -self.sigma * self.b - self.nu * self.a
        rotated = Terms(self.power, self.sigma, self.nu, da, db)
        secular = self.power == 1  # (s g)' = g + s g'
        return rotated + Terms(np.zeros(int(secular.sum())), self.sigma[secular], self.nu[secular],
                               self.a[secular], self.b[secular])

    def merged(self) -> "Terms":
        """Like terms (same power, sigma, nu) summed into one: fewer terms to evaluate."""
        keys = {}
        for m, sigma, nu, a, b in self.rows():
            key = (m, sigma, nu)
            a0, b0 = keys.get(key, (0.0, 0.0))
            keys[key] = (a0 + a, b0 + b)
        return Terms.of((m, sigma, nu, a, b) for (m, sigma, nu), (a, b) in keys.items())

    def __call__(self, s):
        """f(s) for a scalar or an array of s."""
        s_col = np.asarray(s, dtype=float)[..., None]
        phase = s_col * self.nu
        value = np.exp(-s_col * self.sigma) * (self.a * np.cos(phase) + self.b * np.sin(phase))
        value = np.where(self.power == 1, s_col * value, value)
        return value.sum(axis=-1)


_FIELDS = ("power", "sigma", "nu", "a", "b")


@dataclass(frozen=True)
class LinearOperator:
    """L[y] = y'' + c y' + k y: Eq. 11 with (c, k) = (mu, a1); Eq. 32 with (c, k) = (0, p*^2)."""

    c: float
    k: float

    @property
    def q(self) -> float:
        """Damped natural frequency sqrt(k - c^2/4) (p of Eq. 15)."""
        disc = self.k - 0.25 * self.c * self.c
        if not disc > 0.0:
            raise ValueError(f"L = y'' + {self.c:g} y' + {self.k:g} y is not underdamped (k - c^2/4 = {disc:g}):"
                             " the OAFM bases here need an oscillatory L")
        return math.sqrt(disc)

    def free(self, y0: float, v0: float) -> Terms:
        """L[y] = 0, y(0) = y0, y'(0) = v0: e^(-cs/2)(y0 cos qs + (v0 + c y0/2)/q sin qs) (Eq. 15, 33)."""
        q = self.q
        return Terms.of([(0, 0.5 * self.c, q, y0, (v0 + 0.5 * self.c * y0) / q)])

    def response(self, sigma: float, nu: float, C: float = 1.0, S: float = 0.0) -> Terms:
        """L[y] = e^(-sigma s)(C cos nu s + S sin nu s), y(0) = y'(0) = 0 (docs/model.md, OAFM analytic solution, sigma = k mu, nu = n p)."""
        c, k, q = self.c, self.k, self.q
        P_r = k + sigma * sigma - c * sigma - nu * nu
        P_i = nu * (c - 2.0 * sigma)
        D = P_r * P_r + P_i * P_i
        if math.sqrt(D) <= RESONANCE_TOLERANCE * (k + sigma * sigma + nu * nu):
            # resonant pair (sigma, nu) = (c/2, q): s e^(-cs/2)(C sin qs - S cos qs)/(2q) + S e^(-cs/2) sin qs/(2q^2)
            half = 0.5 * c
            return Terms.of([(1, half, q, -S / (2.0 * q), C / (2.0 * q)), (0, half, q, 0.0, S / (2.0 * q * q))])
        a = (C * P_r - S * P_i) / D
        b = (C * P_i + S * P_r) / D
        return Terms.of([(0, sigma, nu, a, b), (0, 0.5 * c, q, -a, ((sigma - 0.5 * c) * a - nu * b) / q)])

    def apply(self, y: Terms) -> Terms:
        """L[y] as Terms (unmerged)."""
        dy = y.derivative()
        return dy.derivative() + dy.scaled(self.c) + y.scaled(self.k)
