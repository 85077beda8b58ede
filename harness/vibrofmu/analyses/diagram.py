"""Bifurcation diagram by simulation and the largest Lyapunov exponent along it (issue 24, item 3).

Diagram. Stroboscopic samples x(kT), T = 2 pi / omega (the phase of Delta cos omega tau is 0 at every sample)
of the exact model (fidelity 0: Eq. 3 with the Hertz force cut at contact loss and the full AC drive) against one
parameter, swept up and down: each point starts from the previous point's end state (continued states), runs
`transient` periods that are discarded, then records `samples` periods. The plant is the compiled core
(vibromodel.compiled.CompiledPlant, DOP853 at rtol 1e-8), which integrates a period 100-500 times faster than
scipy's solve_ivp on the same equation (docs/bifurcation-diagram.md, Speed). Each point restarts the plant at
tau = 0 from the carried state, so the forcing phase of every sample is 0 (with beta, gamma != 0 the AC drive's
phase restarts too: its frequencies Omega, 2 Omega are not commensurate with omega and a stroboscopic section
at T is then not a Poincare section; set beta = gamma = 0 for a strictly periodic forcing, as shooting does).

Transient. A perturbation of the steady state decays like the linear part of Eq. 3, exp(-mu tau / 2), where
the Floquet multipliers are a complex pair (their product is exp(-mu T), so both moduli are exp(-mu T / 2): the
small-amplitude branch); where they are real one is larger. To shrink an O(1) offset to TRANSIENT_EPS takes
tau = 2 ln(1 / TRANSIENT_EPS) / mu, i.e. ceil(2 ln(1 / eps) / (mu T)) periods (transient_periods); the carried
state is usually much closer than O(1), and near a fold, where a multiplier tends to 1, the decay is slower and
the samples show the slow drift (which is how a fold looks in a diagram). The count is bounded to
[MIN_TRANSIENT, MAX_TRANSIENT].

Lyapunov exponents. From the end state of each diagram point, the state and its fundamental matrix Phi
(variational equations Phi' = J Phi, J = [[0, 1], [-g'(x, tau), -mu]]) are integrated with scipy's DOP853 (the
variational system is not in the core), one forcing period at a time, and Phi is re-orthonormalised by QR
after every period (Benettin et al. 1980): the running sums of ln |R_ii| over the elapsed time are the two
exponents. The integration stops and restarts at every contact crossing x = -3/2, where g' = (1 + 2x/3)^(1/2)
is continuous but g'' is not (shooting.py, module doc: no saltation matrix, the field is C^1). Checks
(tests/studies/test_diagram.py): lambda_1 + lambda_2 = trace J = -mu exactly; a damped linear oscillator gives
-mu/2 twice; on a periodic orbit the largest is ln|rho_max| / T of shooting's monodromy matrix.

Pull-in (an electrode gap below PULL_IN_GAP) ends a point: its samples are NaN, `pull_in` is set, and the next
point restarts from the scene's start state (x_start, v_start).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.integrate import solve_ivp

from vibromodel.integrate import IntegrationError, TerminalEvent
from vibromodel.parameters import PULL_IN_GAP, ParameterError, Scene, model_parameter_names, validate
from vibromodel.settings import Settings

from vibrofmu.output import export

TRANSIENT_EPS = 1e-8  # a discarded transient shrinks an O(1) offset below this (module doc)
MIN_TRANSIENT, MAX_TRANSIENT = 20, 20000
DEFAULT_SAMPLES = 64
DEFAULT_LYAPUNOV_PERIODS = 200
LYAPUNOV_RTOL = 1e-9  # DOP853 on state + Phi: an exponent needs a few digits; 1e-9 keeps the per-period
LYAPUNOV_ATOL = 1e-12  # log-stretch error ~ rtol, far below the 1 / (n T) statistical error of the estimate
SETTINGS = Settings()  # the core's plant: fidelity 0, DOP853, rtol 1e-8 (the FMU's defaults)
VOLTAGES = ("V_bias", "V_AC")  # factors on the scene's voltages: alpha ~ V_b^2, beta ~ V_b V_AC, gamma ~ V_AC^2
PARAMETERS = tuple(model_parameter_names()) + VOLTAGES
TWO_PI = 2.0 * math.pi
CONTACT_LOSS_X = -1.5  # 1 + 2x/3 = 0
CONTACT_PHASES = 32  # phases per recorded period at which contact loss is looked for (an indicator: a loss
# shorter than T / 32 can be missed; the Lyapunov integration locates every crossing exactly)


def scene_at(base: Scene, name: str, value: float) -> Scene:
    """The scene with parameter `name` at `value`. V_bias and V_AC scale the scene's voltages (docs/model.md,
    Scaling: alpha = c V_b^2, beta = 2 c V_b V_AC, gamma = c V_AC^2 / 2): V_bias = s gives alpha s^2, beta s;
    V_AC = s gives beta s, gamma s^2 (s = 1: the scene itself)."""
    if name == "V_bias":
        return base.with_values(alpha=base.alpha * value * value, beta=base.beta * value)
    if name == "V_AC":
        return base.with_values(beta=base.beta * value, gamma=base.gamma * value * value)
    if name not in PARAMETERS:
        raise ParameterError(name, value, f"not a diagram parameter; one of {', '.join(PARAMETERS)}")
    return base.with_values(**{name: value})


def transient_periods(scene: Scene) -> int:
    """ceil(2 ln(1 / TRANSIENT_EPS) / (mu T)) in [MIN_TRANSIENT, MAX_TRANSIENT] (module doc)."""
    if scene.mu <= 0.0:
        return MAX_TRANSIENT
    n = 2.0 * math.log(1.0 / TRANSIENT_EPS) / (scene.mu * TWO_PI / scene.omega)
    return int(min(MAX_TRANSIENT, max(MIN_TRANSIENT, math.ceil(n))))


@dataclass
class Point:
    """One diagram point: its samples x(kT), v(kT) and what happened."""

    value: float
    x: np.ndarray
    v: np.ndarray
    transient: int
    contact_loss: bool = False  # x <= -3/2 at one of CONTACT_PHASES phases of a recorded period
    pull_in: bool = False
    message: str = ""
    cost_s: float = 0.0  # wall seconds
    cpu_s: float = 0.0  # CPU seconds of the thread that computed it

    @property
    def end(self) -> tuple[float, float] | None:
        return None if self.pull_in else (float(self.x[-1]), float(self.v[-1]))


def sweep(library, base: Scene, name: str, values, samples: int = DEFAULT_SAMPLES, transient: int | None = None,
          start: tuple[float, float] | None = None, progress: Callable[[int], None] | None = None) -> list[Point]:
    """Points at `values` in the order given, each from the previous one's end state (the first from `start`,
    default the scene's x_start, v_start). transient None: transient_periods(scene) at each point."""
    from vibromodel.compiled import CompiledPlant

    state = start or (base.x_start, base.v_start)
    points = []
    for i, value in enumerate(values):
        started, cpu = time.perf_counter(), time.thread_time()
        scene = scene_at(base, name, float(value))
        n_tr = transient_periods(scene) if transient is None else transient
        period = TWO_PI / scene.omega
        x, v = np.full(samples, np.nan), np.full(samples, np.nan)
        point = Point(float(value), x, v, n_tr)
        plant = CompiledPlant(scene.with_values(x_start=state[0], v_start=state[1]), SETTINGS, library)
        try:
            for k in range(1, n_tr + 1):
                plant.advance(k * period)
            for k in range(samples):  # the recorded periods, also looked at CONTACT_PHASES times a period
                t0 = (n_tr + k) * period
                for j in range(1, CONTACT_PHASES):
                    point.contact_loss |= plant.advance(t0 + j * period / CONTACT_PHASES)[0] <= CONTACT_LOSS_X
                x[k], v[k], _ = plant.advance(t0 + period)
        except (TerminalEvent, IntegrationError) as error:
            point.pull_in, point.message = True, str(error)
            x[:], v[:] = np.nan, np.nan
        point.contact_loss |= bool(np.any(x <= CONTACT_LOSS_X))
        state = point.end or (base.x_start, base.v_start)
        point.cost_s, point.cpu_s = time.perf_counter() - started, time.thread_time() - cpu
        points.append(point)
        if progress is not None:
            progress(i + 1)
    return points


def distinct(x: np.ndarray, tol: float) -> int:
    """Number of clusters of the samples x (sorted, a gap > tol starts a new cluster): the period of a
    periodic attractor in forcing periods; grows with the samples on a chaotic or quasi-periodic one."""
    x = np.sort(x[np.isfinite(x)])
    return int(x.size and 1 + np.count_nonzero(np.diff(x) > tol))


# ----- Lyapunov exponents (Benettin) -------------------------------------------------------------------

def variational_rhs(scene: Scene, linear_stiffness: float | None = None):
    """f(tau, y), y = (x, v, Phi11, Phi21, Phi12, Phi22): Eq. 3 with the full AC drive and its variational
    equations in plain floats. linear_stiffness k: the damped linear oscillator x'' + mu x' + k x =
    Delta cos omega tau instead (the closed-form check)."""
    mu, Delta, w = scene.mu, scene.Delta, scene.omega
    alpha, beta, gamma, Om, R = scene.alpha, scene.beta, scene.gamma, scene.Omega, scene.R
    c, kc = 2.0 / (3.0 * R), 4.0 / (3.0 * R)
    sqrt, cos, sin = math.sqrt, math.cos, math.sin

    if linear_stiffness is not None:
        k0 = float(linear_stiffness)

        def linear(t, y):
            x, v, a, b, p, q = y
            return [v, Delta * cos(w * t) - mu * v - k0 * x, b, -k0 * a - mu * b, q, -k0 * p - mu * q]
        return linear

    def rhs(t, y):
        x, v, a, b, p, q = y
        s = 1.0 + 2.0 * x / 3.0
        if s > 0.0:
            r = sqrt(s)
            hertz, hertz_k = s * r, r
        else:
            hertz = hertz_k = 0.0
        u = c * x
        up, lo = 1.0 / (1.0 - u), 1.0 / (1.0 + u)
        drive = beta * sin(Om * t) + gamma * (1.0 - cos(2.0 * Om * t)) if (beta or gamma) else 0.0
        f3 = up * up
        force = alpha * (f3 - lo * lo) + drive * f3
        force_k = kc * (alpha * (f3 * up + lo * lo * lo) + drive * f3 * up)
        k = hertz_k - force_k
        return [v, 1.0 + Delta * cos(w * t) - mu * v - hertz + force, b, -k * a - mu * b, q, -k * p - mu * q]

    return rhs


def _events(R: float):
    c = 2.0 / (3.0 * R)

    def contact(t, y):
        return 1.0 + 2.0 * y[0] / 3.0

    def upper_gap(t, y):
        return 1.0 - c * y[0] - PULL_IN_GAP

    def lower_gap(t, y):
        return 1.0 + c * y[0] - PULL_IN_GAP

    contact.terminal = upper_gap.terminal = lower_gap.terminal = True
    return contact, upper_gap, lower_gap


# lambda_1(n) and lambda_1(n/2) within half of |lambda_1(n)| of each other: both have the same sign
SETTLED = 0.5


class PullIn(RuntimeError):
    """An electrode gap fell below PULL_IN_GAP during the Lyapunov integration."""


@dataclass
class Lyapunov:
    """The two exponents after `periods` forcing periods and the running estimate of the largest."""

    largest: float
    second: float
    periods: int
    running: np.ndarray = field(repr=False)  # lambda_1 after 1, 2, ..., periods periods

    @property
    def sum(self) -> float:
        return self.largest + self.second

    @property
    def drift(self) -> float:
        """|lambda_1(n) - lambda_1(n / 2)|: how much the estimate still moved over the second half."""
        return float(abs(self.running[-1] - self.running[len(self.running) // 2 - 1]))


def lyapunov(scene: Scene, z0, periods: int = DEFAULT_LYAPUNOV_PERIODS, rtol: float = LYAPUNOV_RTOL,
             atol: float = LYAPUNOV_ATOL, linear_stiffness: float | None = None) -> Lyapunov:
    """Benettin's algorithm from the state z0 = (x, v) at tau = 0 (forcing phase 0), QR after every period."""
    rhs = variational_rhs(scene, linear_stiffness)
    events = () if linear_stiffness is not None else _events(scene.R)
    period = TWO_PI / scene.omega
    y = np.array([z0[0], z0[1], 1.0, 0.0, 0.0, 1.0])
    logs = np.zeros(2)
    running = np.empty(periods)
    for n in range(periods):
        t, t_end = n * period, (n + 1) * period
        if events:  # the next contact crossing leaves the current side (after a crossing: the way back)
            events[0].direction = -1.0 if events[0](t, y) > 0.0 else 1.0
        while True:
            sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", rtol=rtol, atol=atol, events=events or None)
            if sol.status < 0:
                raise IntegrationError(f"DOP853 failed at tau = {sol.t[-1]:.10g}: {sol.message}")
            y, t = sol.y[:, -1], sol.t[-1]
            if events and (sol.t_events[1].size or sol.t_events[2].size):
                raise PullIn(f"pull-in at tau = {t:.10g}, x = {y[0]:.6g}")
            if sol.status == 0:
                break
            events[0].direction = -events[0].direction  # on the edge now: its sign says nothing
        q, r = np.linalg.qr(np.array([[y[2], y[4]], [y[3], y[5]]]))
        logs += np.log(np.abs(np.diag(r)))
        y = np.array([y[0], y[1], q[0, 0], q[1, 0], q[0, 1], q[1, 1]])
        running[n] = logs[0] / t_end
    elapsed = periods * period
    return Lyapunov(float(logs[0] / elapsed), float(logs[1] / elapsed), periods, running)


@dataclass
class PointExponent:
    """The exponents of one diagram point (NaN where the point ended in pull-in)."""

    value: float
    direction: str
    largest: float = math.nan
    second: float = math.nan
    drift: float = math.nan
    periods: int = 0
    running: list = field(default_factory=list)
    message: str = ""
    cost_s: float = 0.0
    cpu_s: float = 0.0

    @property
    def converged(self) -> bool:
        """The estimate moved by less than SETTLED |lambda_1| over the second half of the run: its sign is settled
        (an exponent still moving by more, e.g. an unsettled transient near a doubling, is not read as chaos)."""
        return bool(math.isfinite(self.largest) and math.isfinite(self.drift)
                    and self.drift <= SETTLED * abs(self.largest))


def point_exponent(base: Scene, name: str, value: float, direction: str, end, periods: int) -> PointExponent:
    """The exponents of the attractor the diagram point (value, direction) ended on (end: its last sample)."""
    started, cpu = time.perf_counter(), time.thread_time()
    out = PointExponent(value, direction)
    if end is not None:
        try:
            result = lyapunov(scene_at(base, name, value), end, periods)
            out.largest, out.second, out.drift, out.periods = result.largest, result.second, result.drift, periods
            out.running = result.running.tolist()
        except (PullIn, IntegrationError) as error:
            out.message = str(error)
    out.cost_s, out.cpu_s = time.perf_counter() - started, time.thread_time() - cpu
    return out


def check_request(base: Scene, name: str, lo: float, hi: float, points: int) -> None:
    """ParameterError for a parameter that is not swept or a range whose ends are not valid scenes."""
    if name not in PARAMETERS:
        raise ParameterError("--param", name, f"must be one of {', '.join(PARAMETERS)}")
    for end in (lo, hi):
        if not math.isfinite(end):
            raise ParameterError(name, end, "the range's ends must be finite")
        scene = scene_at(base, name, end)
        validate(scene)
        if scene.omega <= 0.0:
            raise ParameterError("omega", scene.omega, "the stroboscopic period 2 pi / omega needs omega > 0")
    if lo == hi:
        raise ParameterError("--to", hi, "must differ from --from")
    if points < 2:
        raise ParameterError("--points", points, "must be at least 2")


# ----- the whole diagram: serial, or on Dask ------------------------------------------------------------
#
# Cost. A diagram point costs transient + samples periods of the compiled core (~0.02-0.1 ms a period) and
# lyapunov_periods periods of scipy on state + Phi (~3 ms a period): the exponents are ~99 % of the work and
# independent of each other once the sweep has given each point's end state. So the two sweeps (up, down:
# sequential along the parameter by construction, continued states) run as two tasks, and the exponents as
# batches of points, several batches per worker. Splitting a sweep into overlapping segments would buy
# nothing (the sweeps are ~1 % of the wall time) and would change the continued states at the cuts.

_LIBRARY = []  # per process: the compiled kernel, loaded once


def _library():
    if not _LIBRARY:
        from vibrofmu.fmus.kernel import kernel_library

        _LIBRARY.append(kernel_library())
    return _LIBRARY[0]


def sweep_task(base: dict, name: str, values: list, samples: int, transient: int | None) -> list[Point]:
    return sweep(_library(), Scene(**base), name, values, samples, transient)


def exponent_task(base: dict, name: str, items: list, periods: int) -> list[PointExponent]:
    scene = Scene(**base)
    return [point_exponent(scene, name, value, direction, end, periods) for value, direction, end in items]


class TaskFailed(RuntimeError):
    """A Dask task of the diagram raised (its message says which error)."""


@dataclass
class Diagram:
    name: str
    values: np.ndarray
    sweeps: dict  # direction -> list[Point] in the sweep's order
    exponents: dict  # direction -> list[PointExponent] in the sweep's order (empty without exponents)
    wall_s: float = 0.0
    workers: int = 1

    @property
    def cpu_s(self) -> float:
        """CPU seconds of all points' sweeps and exponents (the work, whoever did it)."""
        return (sum(p.cpu_s for points in self.sweeps.values() for p in points)
                + sum(e.cpu_s for exps in self.exponents.values() for e in exps))


def batches(items: list, workers: int, per_worker: int = 4) -> list[list]:
    """items cut in consecutive batches, about per_worker of them per worker (balance at the end)."""
    size = max(1, math.ceil(len(items) / (workers * per_worker)))
    return [items[i:i + size] for i in range(0, len(items), size)]


def compute(base: Scene, name: str, values, samples: int = DEFAULT_SAMPLES, transient: int | None = None,
            periods: int = DEFAULT_LYAPUNOV_PERIODS, client=None, progress: Callable[[str, int], None] | None = None,
            stop: Callable[[], bool] | None = None) -> Diagram:
    """The up and down sweeps over `values` (ascending) and, if periods > 0, the exponents of every point.

    client None: in this process, in order; else a distributed Client: the sweeps as two tasks, the exponents
    in batches. Both run the same functions on the same inputs, so they give the same bits. progress(kind,
    n): n more sweep points ("sweep") or exponents ("lyapunov") done. stop(): checked after each result;
    True raises KeyboardInterrupt (Ctrl-C, scheduling.stop_on_sigint)."""
    started = time.perf_counter()
    values = np.asarray(values, dtype=float)
    orders = {"up": values.tolist(), "down": values[::-1].tolist()}
    base_dict = base.as_dict()
    report = progress or (lambda kind, n: None)
    sweeps, exponents = {}, {"up": [], "down": []}

    def items(direction):
        return [(p.value, direction, p.end) for p in sweeps[direction]]

    if client is None:
        for direction, order in orders.items():
            sweeps[direction] = sweep(_library(), base, name, order, samples, transient,
                                      progress=lambda i: report("sweep", 1))
        for direction in orders:
            if periods > 0:
                for value, d, end in items(direction):
                    exponents[direction].append(point_exponent(base, name, value, d, end, periods))
                    report("lyapunov", 1)
                    if stop and stop():
                        raise KeyboardInterrupt
        return Diagram(name, values, sweeps, exponents, time.perf_counter() - started, 1)

    from distributed import as_completed

    workers = max(1, len(client.scheduler_info(n_workers=-1)["workers"]))
    futures = {client.submit(sweep_task, base_dict, name, order, samples, transient, pure=False): direction
               for direction, order in orders.items()}
    pending = as_completed(list(futures))
    parts: dict = {}  # future -> (direction, batch index)
    done: dict = {"up": {}, "down": {}}  # direction -> batch index -> exponents
    for future in pending:
        if stop and stop():
            client.cancel(list(futures) + list(parts))
            raise KeyboardInterrupt
        try:
            result = future.result()
        except Exception as error:  # a task that raised on its worker (or a worker lost too often)
            client.cancel(list(futures) + list(parts))
            raise TaskFailed(f"a diagram task failed on a Dask worker: {type(error).__name__}: {error}") from None
        if future in futures:
            direction = futures[future]
            sweeps[direction] = result
            report("sweep", len(result))
            if periods > 0:  # half the workers' share per sweep: both sweeps' batches interleave
                for k, batch in enumerate(batches(items(direction), workers)):
                    more = client.submit(exponent_task, base_dict, name, batch, periods, pure=False)
                    parts[more] = (direction, k)
                    pending.add(more)
        else:
            direction, k = parts[future]
            done[direction][k] = result
            report("lyapunov", len(result))
    for direction, by_batch in done.items():
        exponents[direction] = [e for k in sorted(by_batch) for e in by_batch[k]]
    return Diagram(name, values, sweeps, exponents, time.perf_counter() - started, workers)


# ----- files and plots ------------------------------------------------------------------------------------

def diagram_table(d: Diagram):
    """One row per sample: parameter, direction, sample, x, v (and the point's transient, contact loss, pull-in)."""
    import pyarrow as pa

    cols = {k: [] for k in ("parameter", "direction", "sample", "x", "v", "transient", "contact_loss", "pull_in")}
    for direction, points in d.sweeps.items():
        for p in points:
            n = p.x.size
            cols["parameter"] += [p.value] * n
            cols["direction"] += [direction] * n
            cols["sample"] += list(range(n))
            cols["x"] += p.x.tolist()
            cols["v"] += p.v.tolist()
            cols["transient"] += [p.transient] * n
            cols["contact_loss"] += [p.contact_loss] * n
            cols["pull_in"] += [p.pull_in] * n
    return pa.table(cols).replace_schema_metadata({"parameter": d.name})


def lyapunov_table(d: Diagram, tol: float = 1e-6):
    """One row per point and direction: parameter, direction, largest and second exponent, their sum (= -mu),
    the estimate's drift over the second half, periods, the number of distinct x samples (clusters at `tol`)."""
    import pyarrow as pa

    cols = {k: [] for k in ("parameter", "direction", "largest", "second", "sum", "drift", "converged", "periods",
                            "distinct_x", "message")}
    for direction, points in d.sweeps.items():
        by_value = {e.value: e for e in d.exponents.get(direction, [])}
        for p in points:
            e = by_value.get(p.value, PointExponent(p.value, direction))
            cols["parameter"].append(p.value)
            cols["direction"].append(direction)
            cols["largest"].append(e.largest)
            cols["second"].append(e.second)
            cols["sum"].append(e.largest + e.second)
            cols["drift"].append(e.drift)
            cols["converged"].append(e.converged)
            cols["periods"].append(e.periods)
            cols["distinct_x"].append(distinct(p.x, tol))
            cols["message"].append(p.message or e.message)
    return pa.table(cols).replace_schema_metadata({"parameter": d.name})


def convergence_table(d: Diagram):
    """The running estimate of the largest exponent: parameter, direction, period, estimate."""
    import pyarrow as pa

    cols = {k: [] for k in ("parameter", "direction", "period", "estimate")}
    for direction, exps in d.exponents.items():
        for e in exps:
            n = len(e.running)
            cols["parameter"] += [e.value] * n
            cols["direction"] += [direction] * n
            cols["period"] += list(range(1, n + 1))
            cols["estimate"] += e.running
    return pa.table(cols).replace_schema_metadata({"parameter": d.name})


COLOURS = {"up": "tab:blue", "down": "tab:orange"}


def plot(d: Diagram, path, title: str = "") -> None:
    """diagram.png: the samples as small dots (up and down in two colours) and, if computed, the largest
    exponent below on the same parameter axis with a zero line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with_exponents = any(d.exponents.get(k) for k in d.sweeps)
    fig, axes = plt.subplots(2 if with_exponents else 1, 1, sharex=True, figsize=(9, 7 if with_exponents else 4.5),
                             gridspec_kw={"height_ratios": [3, 1.4]} if with_exponents else None, squeeze=False)
    ax = axes[0, 0]
    for direction, points in d.sweeps.items():
        xs = np.concatenate([np.full(p.x.size, p.value) for p in points])
        ys = np.concatenate([p.x for p in points])
        ax.scatter(xs, ys, s=1.5, color=COLOURS[direction], alpha=0.6, linewidths=0, label=f"sweep {direction}")
        pulled = [p.value for p in points if p.pull_in]
        if pulled:  # pull-in: no samples, the run ended; an end mark on the lower frame, not a point at x = 0
            ax.plot(pulled, [0.0] * len(pulled), "v", transform=ax.get_xaxis_transform(), clip_on=False,
                    color=COLOURS[direction], mec="k", mew=0.5, ms=6,
                    label=f"pull-in, run ended ({direction})")
    ax.axhline(-1.5, color="grey", lw=0.6, ls=":", label="contact loss $x = -3/2$")
    ax.set_ylabel("$x(kT)$ (stroboscopic, forcing phase 0)")
    legend = ax.legend(loc="best", markerscale=4, fontsize=8)  # the sample dots are tiny: scaled up in the legend
    for handle, text in zip(legend.legend_handles, legend.get_texts()):
        if text.get_text().startswith("pull-in") and hasattr(handle, "set_markersize"):
            handle.set_markersize(6)  # the end marks are drawn at their size already
    ax.set_title(title or f"bifurcation diagram in {export.symbol(d.name)}")
    if with_exponents:
        ax2 = axes[1, 0]
        for direction, exps in d.exponents.items():
            settled = [e for e in exps if e.converged]
            ax2.plot([e.value for e in settled], [e.largest for e in settled], ".-", ms=3, lw=0.8,
                     color=COLOURS[direction], label=rf"largest Lyapunov exponent $\lambda_1$, {direction}")
            moving = [e for e in exps if not e.converged and math.isfinite(e.largest)]
            if moving:  # hollow, unjoined: not evidence of chaos nor of order
                ax2.plot([e.value for e in moving], [e.largest for e in moving], "o", ms=4, mfc="none", mew=0.8,
                         color=COLOURS[direction],
                         label=rf"not converged ({direction}: drift > {SETTLED:g} $|\lambda_1|$)")
        ax2.axhline(0.0, color="black", lw=0.8)
        ax2.set_ylabel(r"$\lambda_1$ (per unit $\tau$)")
        ax2.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel(export.parameter_label(d.name))
    fig.tight_layout()
    export.save_figure(fig, path, dpi=140)  # atomic, then closed


def plot_convergence(d: Diagram, path, count: int = 6) -> None:
    """lyapunov_convergence.png: the running estimate against the periods for `count` points spread over the
    up sweep (the most positive exponent among them if any): the estimate must flatten."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    exps = [e for e in d.exponents.get("up", []) if e.running]
    if not exps:
        return
    picks = {exps[int(i)].value: exps[int(i)] for i in np.linspace(0, len(exps) - 1, min(count, len(exps)))}
    top = max(exps, key=lambda e: e.largest)
    picks[top.value] = top
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for e in sorted(picks.values(), key=lambda e: e.value):
        ax.plot(np.arange(1, len(e.running) + 1), e.running, lw=0.9, label=f"{export.symbol(d.name)} = {e.value:.6g}")
    ax.axhline(0.0, color="black", lw=0.8)
    ax.set_xlabel("forcing periods")
    ax.set_ylabel(r"running estimate of $\lambda_1$")
    ax.set_title("Benettin: convergence of the largest exponent")
    ax.legend(fontsize=8)
    fig.tight_layout()
    export.save_figure(fig, path, dpi=140)  # atomic, then closed


# ----- the integrators' costs, side by side (docs/bifurcation-diagram.md, Speed) ------------------------

def integrator_costs(scene: Scene, periods: int = 100) -> dict:
    """ms per forcing period of the core (state only, rtol 1e-8, as the sweeps run it) and of scipy's DOP853 on
    state + Phi (this module's Lyapunov integration, rtol LYAPUNOV_RTOL), from the same start, in this process."""
    from vibromodel.compiled import CompiledPlant

    period = TWO_PI / scene.omega
    plant = CompiledPlant(scene, SETTINGS, _library())
    started = time.perf_counter()
    for k in range(1, periods + 1):
        plant.advance(k * period)
    core = (time.perf_counter() - started) / periods
    started = time.perf_counter()
    lyapunov(scene, (scene.x_start, scene.v_start), periods)
    scipy = (time.perf_counter() - started) / periods
    return {"core_ms": 1e3 * core, "scipy_variational_ms": 1e3 * scipy, "ratio": scipy / core}


if __name__ == "__main__":  # python3 -m vibrofmu.analyses.diagram: the costs on a large orbit with contact loss
    costs = integrator_costs(Scene(mu=0.1, Delta=2.5, omega=2.0, beta=0.0, gamma=0.0, R=3.0, x_start=0.0))
    print(", ".join(f"{k} {v:.4g}" for k, v in costs.items()))
