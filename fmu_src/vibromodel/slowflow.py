"""Fidelity 3: the averaged slow flow integrated in time, and x reconstructed from it (docs/model.md, Averaging and slow flow).

x ~ x_e + A(t) cos(omega t) + B(t) sin(omega t) + y2 + psi(t), with (A, B) from the slow flow, y2 the
second-order harmonics of the quadratic stiffness and psi the fast AC response (Eq. 46). The slow flow is integrated with large steps (DOP853) and tabulated as
cubic Hermite pieces on a uniform grid whose spacing is refined until the table matches the
integrator's dense output to the tolerance; one output then costs one table lookup and a few
trigonometric terms. v and a are the exact time derivatives of the reconstructed x.
The integration and the table are made in C (core/slowflow_table.c, through slowflow_kernel) when the plant asks
for the compiled kernel and one is loaded, ~10x faster than with SciPy's solve_ivp and numpy, which does it
otherwise (the same rule and tolerance, not the same bits: tests/model/test_slowflow_kernel.py).

scipy is imported inside the functions that use it: at module level its import would be most of the
plant FMU's first instantiation, which needs none of this module.
"""
from __future__ import annotations

import math
import time

import numpy as np

from . import slowflow_kernel
from .averaging import Averaged
from .parameters import PULL_IN_GAP, ParameterError

CHUNK = 200.0  # tau covered per integration when the end of the experiment is not known
# A bounded solution (the plant's) tabulates at most WINDOW ahead at set-up and later CHUNK at a time as the run
# advances, and drops the cells behind the time it was last asked for: its memory, its FMU state and its set-up
# time stay those of a run of WINDOW, whatever the stop time (stop time 1e6 used to take 12 s, 1.4 GB and 395 MB
# per serialized state).
WINDOW = 1000.0
MAX_STEPS = 10**6  # most steps of max_step one integration may take (as plant.MAX_STEPS_PER_DOSTEP)
MAX_REFINEMENTS = 24
# Set-up time is bounded by the table's size. Tabulating costs ~20 us per cell on this machine (measured: omega = 10
# at rtol 1e-8, 128,000 cells in 2.4 s; omega = 100, 2,048,000 cells in 46 s), so at most MAX_TABLE_CELLS cells are
# tabulated ahead at set-up (~0.8 s, 2 s left for a loaded machine) and per CHUNK later; a slow flow that would need
# more per CHUNK is refused before any work (predicted_spacing).
MAX_TABLE_CELLS = 40_000
# A vibration that reaches beyond this share of the way from x_e to its domain's edge is warned about (check_domain):
# measured against fidelity 0 on [0, 50], Delta = 0.1 (share 0.64) erred by 1.2 %, Delta = 0.15 (0.92) by 17 %.
AMPLITUDE_WARN = 0.8


def predicted_spacing(rate: float, rtol: float) -> float:
    """A lower bound of the table spacing _refined_cells will choose, before integrating.

    (A, B) turn at most at `rate` (|nu| + mu/2), so |d^4 Z/dt^4| <= rate^4 |Z| and the cubic Hermite cell's
    midpoint error is <= h^4 rate^4 |Z| / 384; it meets rtol |Z| for h* = (384 rtol)^(1/4) / rate. Doubling the
    cell count from span/ceil(span) stops within a factor 2 of h*: spacing >= h*/2 (checked: omega = 3, 10, 30,
    100 at rtol 1e-8 gave rate x spacing = 0.042, 0.039, 0.029, 0.024 >= 0.022). Never above 1 (the first grid)."""
    if not rate > 0.0:
        return 1.0
    return min(1.0, 0.5 * (384.0 * rtol) ** 0.25 / rate)


class SlowFlowSolution:
    """(x, x', x'') of the averaged model from the initial state (x0, v0) at t0."""

    def __init__(self, model: Averaged, t0: float, x0: float, v0: float, rtol: float,
                 max_step: float = math.inf, t_end: float | None = None, bounded: bool = False,
                 kernel: bool = False):
        self.stop = math.inf if t_end is None else t_end  # the experiment's end: check_domain looks no further
        # kernel: integrate and tabulate on the compiled kernel where one is loaded (slowflow_kernel)
        self.kernel = kernel and slowflow_kernel.kernel_loaded()
        if bounded and t_end is not None:
            t_end = min(t_end, t0 + WINDOW)  # the rest as the run advances
        self.bounded, self.first = bounded, 0  # first: cells dropped from the front (bounded only)
        span = max(CHUNK, t_end - t0) if t_end is not None else CHUNK
        if span / max_step > MAX_STEPS:  # endless (1e-300) or a failure inside SciPy naming nothing (5e-324)
            over = (f"tau = {span:g}" if t_end is not None and span == t_end - t0 else
                    f"its first table of tau = {span:g} (it is tabulated {CHUNK:g} at a time at least)")
            raise ParameterError("max_step", max_step, f"the averaged slow flow over {over} would need "
                                 f"more than {MAX_STEPS} steps of it; raise it or use 0 (automatic)")
        s = model.scene
        self.averaged = model  # the averaged model (its estimate's)
        self.x_start, self.Delta = x0, s.Delta  # named by check_domain
        self.flow = model.flow()
        self.omega, self.x_e = s.omega, model.eq.x_e
        self.ac = s.beta != 0.0 or s.gamma != 0.0  # a scene without AC actuation skips psi
        if self.ac:  # psi = p sin(Omega t) + q cos(2 Omega t), Eq. 46
            self.Omega, self.psi_sin, self.psi_cos = s.Omega, -s.beta / s.Omega**2, s.gamma / (4 * s.Omega**2)
        self.rtol, self.atol, self.max_step = rtol, 1e-2 * rtol, max_step
        self.t0, self.cells, self.spacing = t0, [], 1.0
        self.integration_seconds = 0.0  # time spent integrating the slow flow (with SciPy: not tabulating; on the
        # kernel the one call integrates and tabulates)
        _, k1, k2 = model.eq.k[:3]
        self.harmonic, self.mean_shift = k2 / (6 * k1), k2 / (2 * k1)
        self.R, self.r_edge = s.R, model.r_max  # the domain (check_domain)
        self.psi_bound = abs(s.beta) / s.Omega**2 + abs(s.gamma) / (4 * s.Omega**2) if self.ac else 0.0
        self.r_start, self.amplitude_warnings = None, []
        Z0 = self._initial_slow_state(t0, x0, v0)
        self.r_start = math.hypot(*Z0)
        t_end = t_end if t_end is not None else t0 + CHUNK
        if bounded:  # tabulate ahead only what MAX_TABLE_CELLS allows (the rest as the run advances)
            t_end = t0 + min(t_end - t0, max(CHUNK, MAX_TABLE_CELLS * self._affordable_spacing(model, rtol)))
        self._start(t0, Z0)
        self.extend(t_end)

    def _affordable_spacing(self, model: Averaged, rtol: float) -> float:
        """predicted_spacing of this slow flow; ParameterError (before any integration) when one CHUNK of table
        would exceed MAX_TABLE_CELLS: the set-up or a later doStep would take seconds to minutes (omega = 1000 took
        47 s). The rate bounds |nu(r)| + mu/2 for r up to the larger of the start's and the resonant peak's
        amplitude 2 drive/mu, capped at the domain's edge r_max (check_domain refuses beyond it)."""
        s, flow = model.scene, self.flow
        peak = 2.0 * abs(flow.drive) / s.mu if s.mu > 0.0 else math.inf
        r = min(max(self.r_start, peak), model.r_max)
        parts = {"omega": abs(flow.detuning), "mu": 0.5 * s.mu,
                 "Delta": abs(flow.backbone.kappa2) * r * r + abs(flow.backbone.kappa4) * r**4}
        rate = sum(parts.values())
        spacing = predicted_spacing(rate, rtol)
        cells = CHUNK / spacing
        if not cells <= MAX_TABLE_CELLS:
            name = max(parts, key=parts.get)
            raise ParameterError(name, getattr(s, name), f"fidelity 3's slow flow turns at up to {rate:.4g} (|nu| + "
                                 f"mu/2; detuning {flow.detuning:.4g} from omega_e = {model.omega_e:.4g}), so its "
                                 f"table at rtol {rtol:.3g} would need about {cells:.3g} cells per tau = {CHUNK:g}, "
                                 f"more than {MAX_TABLE_CELLS} (set-up time); the averaging is meant for omega near "
                                 "omega_e: use fidelity 0")
        return spacing

    def check_domain(self, cells, first_time: float) -> None:
        """ParameterError at the first cell (before the stop time) whose reconstructed x can leave the averaged
        model's domain.

        The slow flow expands the contact force in powers of x - x_e: it has no contact loss (1 + 2x/3 > 0, x > -3/2)
        and no pull-in (|x| < (1 - PULL_IN_GAP) 3R/2). x = x_e + p + h (p^2 - q^2) - m r^2 + psi with |p|, |q| <= r,
        so x lies within x_e -/+ (r + (|h| + |m|) r^2 + |psi|) (psi_bound). Δ = 0.3 used to return x(50) = -1.663
        with fmi2OK, where fidelity 0 stops at pull-in at tau = 17.08."""
        if self.stop < math.inf:  # none after the stop time
            cells = cells[:max(0, math.ceil((self.stop - first_time) / self.spacing))]
        if not len(cells):
            return
        AB = np.asarray(cells)[:, [0, 4]]
        r = np.hypot(AB[:, 0], AB[:, 1])
        spread = r + (abs(self.harmonic) + abs(self.mean_shift)) * r * r + self.psi_bound
        low, high = self.x_e - spread, self.x_e + spread
        electrode = (1.0 - PULL_IN_GAP) * 1.5 * self.R
        bad = np.flatnonzero(~((low > -1.5) & (low > -electrode) & (high < electrode)))
        if bad.size == 0:
            # how far towards the nearest edge x reaches, as a share of the way from x_e (AMPLITUDE_WARN)
            room = np.minimum(np.minimum(self.x_e + 1.5, self.x_e + electrode), electrode - self.x_e)
            share = float(np.max(spread / room))
            if share > AMPLITUDE_WARN and not self.amplitude_warnings:
                i = int(np.argmax(spread / room))
                self.amplitude_warnings.append(
                    f"Delta = {self.Delta:g}: fidelity 3's averaged vibration reaches {share:.2g} of the way from x_e "
                    f"to the edge of its domain (contact loss or pull-in) at tau = {first_time + i * self.spacing:.6g} "
                    f"(above {AMPLITUDE_WARN:g}): its series of the contact force about x_e converges slowly there "
                    "(Delta = 0.15: 17 % error); use fidelity 0 for accuracy")
            return
        i = int(bad[0])
        t = first_time + i * self.spacing
        edge = "leaves the contact (x > -3/2)" if not low[i] > -1.5 else "reaches pull-in (|x| < (1 - 0.001) 3R/2)"
        started_out = self.r_start is not None and i == 0 and t == self.t0
        name, value = ("x_start", self.x_start) if started_out else ("Delta", self.Delta)
        raise ParameterError(name, value, f"fidelity 3's averaged vibration {edge} at tau = {t:.6g}: amplitude "
                             f"r = {r[i]:.4g} about x_e = {self.x_e:.4g} gives x in [{low[i]:.4g}, {high[i]:.4g}], "
                             "outside the averaged model's domain (its contact force is a series about x_e, without "
                             "contact loss or pull-in); use fidelity 0")

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
        if not (math.isfinite(A) and math.isfinite(B)):  # the iteration diverged (its contraction needs small rates)
            name, value = ("Delta", self.Delta) if self.Delta != 0.0 else ("x_start", x0)
            raise ParameterError(name, value, f"fidelity 3's averaged model has no finite slow state at tau = {t0!r}: "
                                 "the slow state's start iteration diverges (the drive or the start is far beyond "
                                 "the averaging's small, slow range); use fidelity 0")
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
        if self.kernel and self._extend_on_kernel(t, span):
            return
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
        self.check_domain(cells, self.t_end)
        self.cells.extend(cells)
        self._start(self.t_end + span, tuple(solution.y[:, -1]))

    def cell_array(self) -> np.ndarray:
        """The table's kept cells as an (n, 8) array (a row per cell: a0..a3, b0..b3), without copying the list of
        cells when the kernel's array of the same table is at hand (kept by _extend_on_kernel)."""
        held = self.__dict__.get("_array")  # (first, cells, t_end, the array): the table it was made of
        if held is not None and held[:3] == (self.first, len(self.cells), self.t_end):
            return held[3]
        return np.asarray(self.cells, dtype=float).reshape(-1, 8)

    def residual_terms(self, scene, span: float, n: int, mu: float, k1: float) -> tuple[float, float] | None:
        """fidelity 3's estimate's (max|e|, max|R|) from n samples over the table's first `span` on the kernel
        (slowflow_kernel.residual_terms); None where it cannot (error_estimates.averaged_terms then uses numpy)."""
        return slowflow_kernel.residual_terms(self, scene, span, n, mu, k1)

    def _extend_on_kernel(self, t: float, span: float) -> bool:
        """extend() on the compiled kernel (slowflow_kernel: the integration and the table in C, the refinement of
        the first table's grid included); False, nothing done, when its grid would exceed the cells it is given room
        for (then SciPy's path refines, as without the kernel)."""
        started = time.perf_counter()
        n = 0 if not self.cells else round(span / self.spacing)
        # room for the grid: a first table's refinement rarely passes 16 cells per tau (the paper scene's: 2); a
        # finer one is asked again with room for 64 times the cells it reached (and left to SciPy beyond that)
        result = None
        for room in ((n,) if self.cells else (16 * math.ceil(span), 64 * 16 * math.ceil(span))):
            result = slowflow_kernel.tabulate(self.flow, self.t_end, self.Z_end, span, self.rtol, self.atol,
                                              self.max_step, self.spacing if self.cells else 0.0, n, MAX_REFINEMENTS,
                                              room)
            if result is not None:
                break
        self.integration_seconds += time.perf_counter() - started
        if result is None:
            return False
        spacing, table, Z_end, tolerance, _ = result
        cells = list(map(tuple, table.tolist()))
        kept, drop = (self.cell_array() if self.cells else None), 0  # the array of the table before this chunk
        if self.cells:
            if self.bounded:  # drop the cells before the one holding t (a run only moves forward)
                drop = max(0, min(int((t - self.t0) / self.spacing) - self.first, len(self.cells)))
                del self.cells[:drop]
                self.first += drop
        else:
            self.spacing, self.tolerance = spacing, tolerance
        self.check_domain(table, self.t_end)
        self.cells.extend(cells)
        self._start(self.t_end + span, Z_end)
        # the table's array, for the estimate and the compiled evaluator (cell_array): kept up to date here, so that
        # an extension costs its own chunk, not a copy of the whole list of cells
        array = table if kept is None else np.concatenate((kept[drop:], table))
        self._array = (self.first, len(self.cells), self.t_end, array)
        return True

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

    def states(self, t: np.ndarray, cells: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """state() at an array of times inside the table (from its first kept cell to t_end), as arrays: the
        error estimate's samples of the whole run at once. cells: np.asarray(self.cells) when already at hand."""
        cells = self.cell_array() if cells is None else cells
        t = np.asarray(t, dtype=float)
        u = (t - self.t0) / self.spacing
        i = np.minimum(np.trunc(u), self.first + len(cells) - 1)
        s = u - i
        index = i.astype(np.int64) - self.first
        if index.size and not (index.min() >= 0 and np.all(t <= self.t_end)):
            raise ValueError(f"the slow-flow table holds tau in [{self.t0 + self.first * self.spacing!r}, "
                             f"{self.t_end!r}] only")
        a0, a1, a2, a3, b0, b1, b2, b3 = cells[index].T
        g = 1.0 / self.spacing
        return self._reconstruct(t, a0 + s * (a1 + s * (a2 + s * a3)), b0 + s * (b1 + s * (b2 + s * b3)),
                                 g * (a1 + s * (2 * a2 + 3 * s * a3)), g * (b1 + s * (2 * b2 + 3 * s * b3)),
                                 g * g * (2 * a2 + 6 * s * a3), g * g * (2 * b2 + 6 * s * b3), np.cos, np.sin)

    def _reconstruct(self, t, A, B, dA, dB, ddA, ddB, cos=math.cos, sin=math.sin):
        """x = x_e + p + y2 + psi and its exact first and second derivatives, from A, B and theirs.

        p = A cos(w t) + B sin(w t) = r cos(theta) (first order); q = A sin - B cos = r sin(theta).
        y2 = k2/(6 k1) r^2 cos(2 theta) - k2/(2 k1) r^2: the second-order harmonics of the quadratic term
        (y'' + k1 y + k2 y^2, Nayfeh & Mook §4.1), the reconstruction that belongs to the Lindstedt
        backbone, which is second order in k2. psi: the fast AC response, Eq. 46.
        cos, sin: math's for a float t (the per-output path, state), numpy's for arrays (states).
        """
        w = self.omega
        c, sn = cos(w * t), sin(w * t)
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
            s1, c1 = sin(W * t), cos(W * t)
            s2, c2 = 2.0 * s1 * c1, c1 * c1 - s1 * s1
            x += P * s1 + Q * c2
            v += W * (P * c1 - 2.0 * Q * s2)
            a -= W * W * (P * s1 + 4.0 * Q * c2)
        return x, v, a
