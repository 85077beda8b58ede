"""Fidelity 3: the averaged slow flow integrated in time, and x reconstructed from it (docs/model.md, Averaging and slow flow).

x ~ x_e + A(t) cos(omega t) + B(t) sin(omega t) + y2 + psi(t), with (A, B) from the slow flow, y2 the
second-order harmonics of the quadratic stiffness and psi the fast AC response (Eq. 46). The slow flow is integrated with large steps (DOP853, SciPy) and tabulated as
cubic Hermite pieces on a uniform grid whose spacing is refined until the table matches the
integrator's dense output to the tolerance; one output then costs one table lookup and a few
trigonometric terms. v and a are the exact time derivatives of the reconstructed x.

scipy is imported inside the functions that use it: at module level its import would be most of the
plant FMU's first instantiation, which needs none of this module.
"""
from __future__ import annotations

import math
import time

import numpy as np

from .averaging import Averaged
from .integrate import IntegrationError
from .parameters import ParameterError

CHUNK = 200.0  # tau covered per integration when the end of the experiment is not known
# A bounded solution (the plant's) tabulates at most WINDOW ahead at set-up and later CHUNK at a time as the run
# advances, and drops the cells behind the time it was last asked for: its memory, its FMU state and its set-up
# time stay those of a run of WINDOW, whatever the stop time (stop time 1e6 used to take 12 s, 1.4 GB and 395 MB
# per serialized state).
WINDOW = 1000.0
MAX_STEPS = 10**6  # most steps of max_step one integration may take (as plant.MAX_STEPS_PER_DOSTEP)
MAX_REFINEMENTS = 24


class SlowFlowSolution:
    """(x, x', x'') of the averaged model from the initial state (x0, v0) at t0."""

    def __init__(self, model: Averaged, t0: float, x0: float, v0: float, rtol: float,
                 max_step: float = math.inf, t_end: float | None = None, bounded: bool = False):
        if bounded and t_end is not None:
            t_end = min(t_end, t0 + WINDOW)  # the rest as the run advances
        self.bounded, self.first = bounded, 0  # first: cells dropped from the front (bounded only)
        span = max(CHUNK, t_end - t0) if t_end is not None else CHUNK
        if span / max_step > MAX_STEPS:  # endless (1e-300) or a failure inside SciPy naming nothing (5e-324)
            raise ParameterError("max_step", max_step, f"the averaged slow flow over tau = {span:g} would need "
                                 f"more than {MAX_STEPS} steps of it; raise it or use 0 (automatic)")
        s = model.scene
        self.flow = model.flow()
        self.omega, self.x_e = s.omega, model.eq.x_e
        self.ac = s.beta != 0.0 or s.gamma != 0.0  # a scene without AC actuation skips psi
        if self.ac:  # psi = p sin(Omega t) + q cos(2 Omega t), Eq. 46
            self.Omega, self.psi_sin, self.psi_cos = s.Omega, -s.beta / s.Omega**2, s.gamma / (4 * s.Omega**2)
        self.rtol, self.atol, self.max_step = rtol, 1e-2 * rtol, max_step
        self.t0, self.cells, self.spacing = t0, [], 1.0
        self.integration_seconds = 0.0  # time spent integrating the slow flow itself (not tabulating)
        _, k1, k2 = model.eq.k[:3]
        self.harmonic, self.mean_shift = k2 / (6 * k1), k2 / (2 * k1)
        self._start(t0, self._initial_slow_state(t0, x0, v0))
        self.extend(t_end if t_end is not None else t0 + CHUNK)

    def _initial_slow_state(self, t0, x0, v0, iterations=50):
        """(A, B) at t0 such that the reconstructed x and its exact derivative equal (x0, v0), with (A', B')
        from the slow flow. Iterated from van der Pol's start: each step corrects (A, B) by van der Pol's
        inverse of the remaining mismatch; it contracts by ~ |d(A', B')/d(A, B)|/w + 2 |k2| r/k1 << 1."""
        w, c, s = self.omega, math.cos(self.omega * t0), math.sin(self.omega * t0)
        A = B = 0.0
        for _ in range(iterations):
            dA, dB = self.flow.rhs(A, B)
            x, v, _ = self._reconstruct(t0, A, B, dA, dB, 0.0, 0.0)
            dy, du = x0 - x, (v0 - v) / w  # mismatch; van der Pol: y = A c + B s, y'/w = -A s + B c
            A_new, B_new = A + dy * c - du * s, B + dy * s + du * c
            if A_new == A and B_new == B:
                break
            A, B = A_new, B_new
        if not (math.isfinite(A) and math.isfinite(B)):
            raise IntegrationError(f"the averaged model has no finite slow state at tau = {t0!r}: the parameters "
                                   "are beyond its numerical range", t0, x0, v0)
        return A, B

    def _start(self, t, Z):
        self.t_end, self.Z_end = t, Z

    def extend(self, t: float) -> None:
        """Integrate the slow flow from the covered end to at least t and append its table."""
        if t <= self.t_end:
            return
        span = max(t - self.t_end, CHUNK)
        if self.cells:  # later chunks keep the grid of the first, so that lookups stay uniform
            span = math.ceil(span / self.spacing) * self.spacing
        from scipy.integrate import solve_ivp  # lazily, see the module docstring

        started = time.perf_counter()
        solution = solve_ivp(lambda _t, Z: self.flow.rhs(*Z), (self.t_end, self.t_end + span), self.Z_end,
                             method="DOP853", rtol=self.rtol, atol=self.atol, max_step=self.max_step,
                             dense_output=True)
        self.integration_seconds += time.perf_counter() - started
        if not solution.success:
            raise RuntimeError(f"slow flow integration failed: {solution.message}")
        if self.cells:
            cells, _ = self._hermite_cells(solution.sol, self.t_end, self.spacing, round(span / self.spacing))
            if self.bounded:  # drop the cells before the one holding t (a run only moves forward)
                drop = max(0, min(int((t - self.t0) / self.spacing) - self.first, len(self.cells)))
                del self.cells[:drop]
                self.first += drop
        else:
            self.spacing, cells = self._refined_cells(solution.sol, self.t_end, span)
        self.cells.extend(cells)
        self._start(self.t_end + span, tuple(solution.y[:, -1]))

    def _refined_cells(self, dense, t_start, span):
        """Grid spacing span/n (n doubled from span/1) at which the Hermite table matches the dense output
        at every cell midpoint to rtol * max|Z| + atol, and that table."""
        n = math.ceil(span)
        for _ in range(MAX_REFINEMENTS):
            cells, error = self._hermite_cells(dense, t_start, span / n, n)
            if error <= self.tolerance:
                break
            n *= 2
        return span / n, cells

    def _hermite_cells(self, dense, t_start, spacing, n):
        """Cubic Hermite coefficients (A: 4, B: 4 in powers of the local time s in [0, 1]) of n cells,
        and their largest error at the cell midpoints against the dense output."""
        nodes = t_start + spacing * np.arange(n + 1)
        Z = dense(nodes)
        dZ = np.array(self.flow.rhs(*Z)) * spacing
        coefficients = np.stack([Z[:, :-1], dZ[:, :-1],
                                 3 * (Z[:, 1:] - Z[:, :-1]) - 2 * dZ[:, :-1] - dZ[:, 1:],
                                 2 * (Z[:, :-1] - Z[:, 1:]) + dZ[:, :-1] + dZ[:, 1:]])  # (power, A/B, cell)
        mid = np.einsum("pkc,p->kc", coefficients, 0.5 ** np.arange(4))
        error = float(np.max(np.abs(mid - dense(nodes[:-1] + 0.5 * spacing))))
        self.tolerance = self.rtol * float(np.max(np.abs(Z))) + self.atol
        return list(map(tuple, coefficients.transpose(2, 1, 0).reshape(n, 8).tolist())), error

    def state(self, t: float) -> tuple[float, float, float]:
        """(x, x', x'') at t, from one table lookup."""
        if t > self.t_end:
            self.extend(t)
        u = (t - self.t0) / self.spacing
        i = min(int(u), self.first + len(self.cells) - 1)
        s = u - i
        if i < self.first:
            raise ValueError(f"the slow-flow table no longer holds tau = {t!r}: a bounded table keeps the cells from "
                             f"tau = {self.t0 + self.first * self.spacing!r} on")
        a0, a1, a2, a3, b0, b1, b2, b3 = self.cells[i - self.first]
        g = 1.0 / self.spacing
        return self._reconstruct(t, a0 + s * (a1 + s * (a2 + s * a3)), b0 + s * (b1 + s * (b2 + s * b3)),
                                 g * (a1 + s * (2 * a2 + 3 * s * a3)), g * (b1 + s * (2 * b2 + 3 * s * b3)),
                                 g * g * (2 * a2 + 6 * s * a3), g * g * (2 * b2 + 6 * s * b3))

    def _reconstruct(self, t, A, B, dA, dB, ddA, ddB):
        """x = x_e + p + y2 + psi and its exact first and second derivatives, from A, B and theirs.

        p = A cos(w t) + B sin(w t) = r cos(theta) (first order); q = A sin - B cos = r sin(theta).
        y2 = k2/(6 k1) r^2 cos(2 theta) - k2/(2 k1) r^2: the second-order harmonics of the quadratic term
        (y'' + k1 y + k2 y^2, Nayfeh & Mook §4.1), the reconstruction that belongs to the Lindstedt
        backbone, which is second order in k2. psi: the fast AC response, Eq. 46.
        """
        w = self.omega
        c, sn = math.cos(w * t), math.sin(w * t)
        p, q = A * c + B * sn, A * sn - B * c
        dp, dq = dA * c + dB * sn - w * q, dA * sn - dB * c + w * p
        ddp = ddA * c + ddB * sn - 2 * w * (dA * sn - dB * c) - w * w * p
        ddq = ddA * sn - ddB * c + 2 * w * (dA * c + dB * sn) - w * w * q
        h, m = self.harmonic, self.mean_shift
        x = self.x_e + p + h * (p * p - q * q) - m * (A * A + B * B)
        v = dp + 2 * h * (p * dp - q * dq) - 2 * m * (A * dA + B * dB)
        a = ddp + 2 * h * (dp * dp + p * ddp - dq * dq - q * ddq) - 2 * m * (dA * dA + A * ddA + dB * dB + B * ddB)
        if self.ac:  # psi of Eq. 46 and its derivatives, inlined: this is the per-output hot path
            P, Q, W = self.psi_sin, self.psi_cos, self.Omega
            s1, c1 = math.sin(W * t), math.cos(W * t)
            s2, c2 = 2.0 * s1 * c1, c1 * c1 - s1 * s1
            x += P * s1 + Q * c2
            v += W * (P * c1 - 2.0 * Q * s2)
            a -= W * W * (P * s1 + 4.0 * Q * c2)
        return x, v, a
