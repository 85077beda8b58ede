"""OAFM (PAPER §3, docs/model.md, OAFM analytic solution): x~ = x0 + sum C_i y_i on two domains, optimal C_i by least squares.

On each domain [start, end] the local time is s = tau - start. A `Basis` holds the initial
approximation x0 (it carries the domain's initial state) and the first-iteration functions y_i with
y_i(0) = y_i'(0) = 0 (Eq. 22), all closed forms (`Terms`). The convergence-control parameters C_i
minimise the residual functional of the full nonlinear Eq. 3,

    J(C) = (1/T) * integral over the domain of R(tau)^2  +  rho^2 * sum_i (n_i C_i)^2,
    R = x~'' - accel(tau, x~, x~', U=0),   n_i = RMS of y_i'' over the domain,

the integral by composite Gauss-Legendre quadrature (panels of length `panel`, `nodes` points each),
minimised with scipy.optimize.least_squares. The small Tikhonov term (rho = RIDGE) only breaks ties
between nearly equivalent C: without it near-collinear y_i get large cancelling C_i (up to 1e3, the
sum of |terms| 1e6 times |x~|), which costs round-off and ruins extrapolation past the domain; with it
the residual is unchanged in its first three digits (paper example). The two domains are joined with
x and x' continuous at tau*.

scipy is imported inside the functions that use it: at module level its import would be most of the
plant FMU's first instantiation, which needs none of this module.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .closedform import LinearOperator, Terms

JACOBIAN_STEP = 1e-7  # central difference of accel in x for the Gauss-Newton Jacobian only
RIDGE = 1e-5  # rho of the Tikhonov term, relative to the RMS of each y_i''


@dataclass(frozen=True)
class Basis:
    """One domain's ansatz: L, the initial approximation x0 and the functions y_i (Eq. 13, 17).

    Each closed form answers its defining problem: L[x0] = x0_forcing with the domain's initial
    state, L[y_i] = forcings[i] with y_i(0) = y_i'(0) = 0.
    """

    name: str
    operator: LinearOperator
    x0: Terms
    x0_forcing: Terms
    functions: tuple[Terms, ...]
    forcings: tuple[Terms, ...]
    labels: tuple[str, ...]

    def solution(self, C) -> Terms:
        """x~ = x0 + sum C_i y_i as one merged closed form."""
        total = self.x0
        for c, y in zip(C, self.functions):
            total = total + y.scaled(float(c))
        return total.merged()


@dataclass(frozen=True)
class Grid:
    """Composite Gauss-Legendre collocation grid: `nodes` points on each panel of length <= `panel`."""

    panel: float = 1.0
    nodes: int = 8

    def points(self, length: float, unknowns: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(s, w) on [0, length] with sum(w) = length; at least 3 points per unknown."""
        x, w = np.polynomial.legendre.leggauss(self.nodes)
        n = max(1, int(np.ceil(length / self.panel - 1e-9)), int(np.ceil(3 * unknowns / self.nodes)))
        edges = np.linspace(0.0, length, n + 1)
        half, mid = 0.5 * np.diff(edges), 0.5 * (edges[1:] + edges[:-1])
        return (mid[:, None] + half[:, None] * x).ravel(), (half[:, None] * w).ravel()

    def doubled(self) -> "Grid":
        return Grid(self.panel / 2.0, self.nodes)


@dataclass
class Piece:
    """x~ on [start, end): a merged closed form in s = tau - start, with its derivatives."""

    start: float
    end: float
    basis_name: str
    C: tuple[float, ...]
    x: Terms
    residual_rms: float = float("nan")
    residual_max: float = float("nan")
    fit: dict = field(default_factory=dict)

    def __post_init__(self):
        v = self.x.derivative().merged()
        self.v, self.a = v, v.derivative().merged()
        self._stack()

    def _stack(self) -> None:
        """x, x', x'' over one shared set of (power, sigma, nu), as Re[sum c s^m e^((-sigma + i nu) s)]:
        one complex exp per term and time."""
        keys = {}
        for row, terms in enumerate((self.x, self.v, self.a)):
            for m, sigma, nu, a, b in terms.rows():
                keys.setdefault((m, sigma, nu), np.zeros(3, dtype=complex))[row] += complex(a, -b)
        self._secular = np.array([k[0] == 1 for k in keys])
        self._rates = np.array([complex(-k[1], k[2]) for k in keys])
        self._coefficients = np.ascontiguousarray(np.array(list(keys.values())).T)  # (3, K)

    def evaluate(self, s) -> np.ndarray:
        """(x, x', x'') at local time(s) s: shape (3,) for a scalar, (len(s), 3) for an array.

        Re[(a - ib) e^((-sigma + i nu) s)] = e^(-sigma s)(a cos nu s + b sin nu s). The sum runs over the
        last axis for a scalar and an array alike, so both give the same bits: the FMU (one time per
        doStep) and the harness (arrays) agree exactly.
        """
        s_col = np.asarray(s, dtype=float)[..., None]
        z = np.exp(s_col * self._rates)
        if self._secular.any():
            z = np.where(self._secular, s_col * z, z)
        return (z[..., None, :] * self._coefficients).sum(axis=-1).real

    def evaluate_grid(self, s0: float, ds: float, n: int) -> np.ndarray:
        """(x, x', x'') at the n local times s0 + k ds, shape (n, 3): evaluate's values to rounding, not to the bit,
        at a fraction of its cost on many times (the error estimate's samples: error_estimates.propagated_residual).
        e^(rate s) steps by the factor e^(rate ds) from sample to sample (a running product: k roundings at the k-th,
        ~1e-12 relative at 10^4 samples) instead of one complex exp per term and time; Re(z c) = Re z Re c - Im z
        Im c, two real matrix products."""
        z = np.empty((n, self._rates.size), dtype=complex)
        z[0] = np.exp(s0 * self._rates)
        z[1:] = np.exp(ds * self._rates)
        z = np.cumprod(z, axis=0)
        if self._secular.any():
            s_col = (s0 + ds * np.arange(n))[:, None]
            z = np.where(self._secular, s_col * z, z)
        c = self._coefficients.T
        return z.real @ np.ascontiguousarray(c.real) - z.imag @ np.ascontiguousarray(c.imag)


class AnalyticSolution:
    """x~(tau), x~'(tau), x~''(tau) of a sequence of pieces; the last piece extends to infinity."""

    def __init__(self, pieces: list[Piece]):
        self.pieces = pieces
        self.starts = np.array([p.start for p in pieces])

    @property
    def C(self) -> list[tuple[float, ...]]:
        return [p.C for p in self.pieces]

    def fastest_frequency(self) -> float:
        """The largest angular frequency nu of any term (a step ceiling's drive, models.drive_step_ceiling)."""
        return max((float(np.max(np.abs(p._rates.imag))) for p in self.pieces if p._rates.size), default=0.0)

    @property
    def tau_end(self) -> float:
        """End of the last fitted domain: beyond it the solution extrapolates."""
        return self.pieces[-1].end

    def _index(self, tau):
        """Index of the piece holding each tau (times before the first start go to the first piece)."""
        return np.clip(np.searchsorted(self.starts, tau, side="right") - 1, 0, len(self.pieces) - 1)

    def state(self, tau: float) -> tuple[float, float, float]:
        """(x, x', x'') at one time: only closed forms are evaluated."""
        piece = self.pieces[int(self._index(tau))]
        x, v, a = piece.evaluate(tau - piece.start)
        return float(x), float(v), float(a)

    def __call__(self, tau) -> np.ndarray:
        """(x, x', x'') at the times tau; shape (3, len(tau))."""
        tau = np.atleast_1d(np.asarray(tau, dtype=float))
        index = self._index(tau)
        out = np.empty((3, tau.size))
        for i, piece in enumerate(self.pieces):
            inside = index == i
            if inside.any():
                out[:, inside] = piece.evaluate(tau[inside] - piece.start).T
        return out

    def sample_grid(self, t0: float, dt: float, n: int) -> tuple[np.ndarray, np.ndarray]:
        """(the times t0 + k dt, k < n; (x, x', x'') at them, shape (3, n)): __call__'s values to rounding
        (Piece.evaluate_grid), each piece's times being a run of the grid."""
        tau = t0 + dt * np.arange(n)
        index = self._index(tau)
        out = np.empty((3, n))
        for i, piece in enumerate(self.pieces):
            inside = np.flatnonzero(index == i)
            if inside.size:
                first = int(inside[0])
                out[:, first:first + inside.size] = piece.evaluate_grid(float(tau[first]) - piece.start, dt,
                                                                        inside.size).T
        return tau, out


# The model's accel is called point by point on Python floats (tolist): the same IEEE operations as on numpy's
# float64 scalars, so the same bits, at half the cost (numpy scalar arithmetic is the slower); the fit of a domain
# calls it ~10^5 times, most of fidelity 4's set-up.
def residual(accel, tau, x, v, a) -> np.ndarray:
    """R = x'' - accel(tau, x, x', 0): the residual of Eq. 3 (or of the model behind accel)."""
    return a - np.array([accel(t, xi, vi, 0.0) for t, xi, vi in zip(_floats(tau), _floats(x), _floats(v))])


def stiffness(accel, tau, x) -> np.ndarray:
    """d accel / dx by a central difference (used only to steer Gauss-Newton)."""
    h = JACOBIAN_STEP
    return np.array([(accel(t, xi + h, 0.0, 0.0) - accel(t, xi - h, 0.0, 0.0)) / (2 * h)
                     for t, xi in zip(_floats(tau), _floats(x))])


def _floats(values) -> list:
    """The values as Python floats (comment above residual)."""
    return np.asarray(values, dtype=float).tolist()


def fit_domain(accel, basis: Basis, start: float, end: float, grid: Grid, max_evaluations: int | None = None) -> Piece:
    """Optimal C_i of one domain: least squares of sqrt(w/T) R on the collocation grid; at most max_evaluations
    evaluations of the residual (None: scipy's default), fit["converged"] False when they ran out."""
    clock = time.perf_counter()
    length = end - start
    s, w = grid.points(length, len(basis.functions))
    tau = start + s
    X0 = [derivatives[0](s) for derivatives in _derivative_table([basis.x0])]
    Y = [np.column_stack([f(s) for f in derivatives]) if derivatives else np.zeros((s.size, 0))
         for derivatives in _derivative_table(basis.functions)]
    weight = np.sqrt(w / length)
    ridge = RIDGE * np.linalg.norm(weight[:, None] * Y[2], axis=0)

    def state(C):
        return [X0[k] + Y[k] @ C for k in range(3)]

    from scipy.optimize import least_squares  # lazily, see the module docstring

    def fun(C):
        x, v, a = state(C)
        return np.concatenate([weight * residual(accel, tau, x, v, a), ridge * C])

    def jac(C):
        x, _, _ = state(C)
        mu_v = _damping_coefficient(accel, tau, x)
        J = weight[:, None] * (Y[2] - mu_v[:, None] * Y[1] - stiffness(accel, tau, x)[:, None] * Y[0])
        return np.vstack([J, np.diag(ridge)])

    n = len(basis.functions)
    C = np.zeros(n)
    result = None
    if n:
        result = least_squares(fun, C, jac=jac, method="lm", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                               max_nfev=max_evaluations)
        C = result.x
    R = fun(C)[: s.size] / weight
    return Piece(start=start, end=end, basis_name=basis.name, C=tuple(float(c) for c in C),
                 x=basis.solution(C), residual_rms=float(np.sqrt(np.sum(w * R * R) / length)),
                 residual_max=float(np.max(np.abs(R))),
                 fit={"unknowns": n, "functions": list(basis.labels), "grid_points": int(s.size),
                      "panel": grid.panel, "nodes": grid.nodes,
                      "evaluations": int(result.nfev) if result is not None else 0,
                      "status": result.message if result is not None else "no unknowns",
                      "converged": result is None or result.status != 0,  # 0: max_nfev ran out
                      "seconds": time.perf_counter() - clock})


def _derivative_table(functions):
    """[[y_i], [y_i'], [y_i'']] for the basis functions."""
    first = [f.derivative() for f in functions]
    return [list(functions), first, [f.derivative() for f in first]]


def _damping_coefficient(accel, tau, x) -> np.ndarray:
    """d accel / dv (= -mu for Eq. 3 and Eq. 7), by a difference of the model itself."""
    return np.array([accel(t, xi, 1.0, 0.0) - accel(t, xi, 0.0, 0.0) for t, xi in zip(_floats(tau), _floats(x))])


def continue_from(piece: Piece, at: float) -> tuple[float, float]:
    """x~(tau*), x~'(tau*) of a piece: the next domain's initial state (continuity of x and x')."""
    x, v, _ = piece.evaluate(at - piece.start)
    return float(x), float(v)
