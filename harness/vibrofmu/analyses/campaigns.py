"""Contact-event campaigns (issue 15, docs/events.md): random contact-loss scenes and tangential grazes run through
the plant (vibromodel's Plant and the compiled plant directly, no FMI: the code inside the FMU) and compared with
independent references.

- contact_loss_campaign: random scenes that throw the mass out of contact (forcing up to Delta = 1, rtol log-uniform
  in [1e-10, 1e-3]), each run with DOP853 on the compiled kernel, with RK4 on the compiled kernel and (every
  `python_every`-th scene) with the pure-Python DOP853, which must give the same bits as the compiled one. A halt is
  any error other than pull-in. The error of a completed DOP853 run is max |x - x_ref| over the output points in
  units of rtol max|x_ref|; x_ref is reference.reference_solution (scipy's solve_ivp, contact phases integrated
  separately) at rtol min(1e-12, rtol / 1000), over completed runs (issue 15's acceptance); runs that stop at pull-in
  are reported apart, since the motion near the electrode diverges exponentially (the error there measures the
  problem's conditioning, not the solver).
- graze_reference / graze_run: the unforced, undamped oscillator started at its upper turning point with the energy
  that takes it exactly `depth` below the contact boundary x = -3/2 once per period. Energy is conserved, so the
  motion is periodic and every period has exactly one excursion of that depth; the reference x(t) is the contact
  phase (solve_ivp, no event needed: the indentation stays positive inside it) joined to the exact free-flight
  parabola x'' = 1, with the phase durations from quadrature.

Command line (no CLI entry): python -m vibrofmu.analyses.campaigns [n_scenes] [seed]; python -m vibrofmu.analyses.campaigns graze.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from vibromodel.forces import hertz, potential
from vibromodel.integrate import TerminalEvent
from vibromodel.parameters import Scene
from vibromodel.plant import Plant, Settings, Solver

from vibrofmu.analyses.reference import reference_solution

CONTACT_X = -1.5  # 1 + 2x/3 = 0


def random_contact_loss_scene(rng: np.random.Generator) -> Scene:
    """A scene that starts in contact and is thrown out of it: x_start below the static equilibrium, v_start < 0,
    load forcing up to Delta = 1, weak two-sided actuation, electrodes 2-6 contact lengths away."""
    return Scene(mu=float(rng.uniform(0.0, 0.2)), Delta=float(rng.uniform(0.0, 1.0)),
                 omega=float(rng.uniform(0.3, 3.0)), Omega=float(rng.uniform(0.3, 3.0)),
                 alpha=float(rng.uniform(0.0, 0.05)), beta=float(rng.uniform(0.0, 0.05)),
                 gamma=float(rng.uniform(0.0, 0.01)), R=float(rng.uniform(2.0, 6.0)),
                 x_start=float(rng.uniform(-1.45, -0.3)), v_start=float(rng.uniform(-2.0, 0.0)))


def run_plant(plant, stop_time: float, interval: float) -> tuple[np.ndarray, np.ndarray, str | None]:
    """(times, x at them from the start on, None or the error's text: "pull-in: ..." or "halt: <type>: ...")."""
    n = int(round(stop_time / interval))
    times, xs = [0.0], [plant.outputs().x]
    for i in range(n):
        try:
            out = plant.do_step(i * interval, interval, 0.0)
        except TerminalEvent as error:
            return np.array(times), np.array(xs), f"pull-in: {error}"
        except Exception as error:  # noqa: BLE001 -- every other error is a halt, the thing counted
            return np.array(times), np.array(xs), f"halt: {type(error).__name__}: {error}"
        times.append((i + 1) * interval)
        xs.append(out.x)
    return np.array(times), np.array(xs), None


@dataclass
class CampaignResult:
    scenes: int = 0
    runs: dict = field(default_factory=lambda: {"dop853": 0, "rk4": 0, "python": 0})
    halts: list = field(default_factory=list)  # (solver, scene index, scene, rtol, message)
    pull_ins: dict = field(default_factory=lambda: {"dop853": 0, "rk4": 0})
    twin_mismatches: list = field(default_factory=list)  # scene indices where Python and C differ
    worst_error: float = 0.0  # DOP853: max |x - x_ref| / (rtol max |x_ref|) over completed runs
    worst_case: tuple | None = None
    pull_in_worst_error: float = 0.0  # the same over runs that stopped at pull-in (ill-conditioned near it)
    rk4_worst_abs_error: float = 0.0
    errors_over_100: int = 0
    seconds: float = 0.0

    def summary(self) -> dict:
        refusals = sum("RK4 unstable" in halt[4] for halt in self.halts)
        return {"scenes": self.scenes, "runs": self.runs, "halts other than pull-in": len(self.halts),
                "of them RK4 stability refusals (reduce max_step)": refusals,
                "pull-ins": self.pull_ins, "python/C twin mismatches": len(self.twin_mismatches),
                "worst DOP853 error in rtol max|x|": self.worst_error, "runs above 100 rtol max|x|": self.errors_over_100,
                "worst case (index, rtol)": self.worst_case,
                "worst DOP853 error of pull-in runs, up to the last output before it": self.pull_in_worst_error, "worst RK4 |x - x_ref| (h = 0.01)": self.rk4_worst_abs_error,
                "seconds": round(self.seconds, 1)}


def contact_loss_campaign(n_scenes: int, seed: int = 0, stop_time: float = 10.0, interval: float = 0.1,
                          python_every: int = 10, library=None) -> CampaignResult:
    """Run n_scenes random contact-loss scenes (module docstring); library: the compiled kernel (kernel.kernel_library)
    or None for the pure-Python plant only."""
    from vibromodel.compiled import CompiledPlant

    rng = np.random.default_rng(seed)
    result = CampaignResult()
    start = time.perf_counter()
    for index in range(n_scenes):
        scene = random_contact_loss_scene(rng)
        rtol = float(10.0 ** rng.uniform(-10.0, -3.0))
        result.scenes += 1
        settings = Settings(rtol=rtol)

        def make(solver: Solver, compiled: bool):
            chosen = Settings(rtol=rtol, solver=solver)
            return (CompiledPlant(scene, chosen, library, 0.0, stop_time) if compiled and library is not None
                    else Plant(scene, chosen, 0.0, stop_time))

        times, x, stop = run_plant(make(Solver.ADAPTIVE, True), stop_time, interval)
        result.runs["dop853"] += 1
        if index % python_every == 0 and library is not None:
            result.runs["python"] += 1
            times_py, x_py, stop_py = run_plant(make(Solver.ADAPTIVE, False), stop_time, interval)
            if stop_py != stop or x_py.tobytes() != x.tobytes():
                result.twin_mismatches.append(index)
        _count(result, "dop853", index, scene, rtol, stop)
        times_rk4, x_rk4, stop_rk4 = run_plant(make(Solver.RK4, True), stop_time, interval)
        result.runs["rk4"] += 1
        _count(result, "rk4", index, scene, rtol, stop_rk4)
        if stop is not None and not stop.startswith("pull-in"):
            continue
        end = times[-1]
        if end <= 0.0:
            continue
        reference = reference_solution(scene, settings.fidelity, end, rtol=min(1e-12, rtol / 1000.0),
                                       atol=min(1e-14, rtol / 1e5))
        inside = times <= reference.t_end
        x_ref = reference(times[inside])[0]
        scale = rtol * max(np.max(np.abs(x_ref)), 1e-300)
        error = float(np.max(np.abs(x[inside] - x_ref))) / scale
        if stop is not None:  # pull-in: not a completed run; near it the motion diverges exponentially
            result.pull_in_worst_error = max(result.pull_in_worst_error, error)
        elif error > result.worst_error:
            result.worst_error, result.worst_case = error, (index, rtol)
        result.errors_over_100 += stop is None and error > 100.0
        rk4_inside = times_rk4 <= reference.t_end
        if rk4_inside.any():
            rk4_error = float(np.max(np.abs(x_rk4[rk4_inside] - reference(times_rk4[rk4_inside])[0])))
            result.rk4_worst_abs_error = max(result.rk4_worst_abs_error, rk4_error)
    result.seconds = time.perf_counter() - start
    return result


def _count(result: CampaignResult, solver: str, index: int, scene: Scene, rtol: float, stop: str | None) -> None:
    if stop is None:
        return
    if stop.startswith("pull-in"):
        result.pull_ins[solver] += 1
    else:
        result.halts.append((solver, index, scene, rtol, stop))


# -- grazes ---------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GrazeReference:
    """The periodic motion of energy E = 3/2 + depth (module docstring): x_max, the contact phase's duration
    t_contact (from x_max down to x = -3/2), the free flight's duration 2 sqrt(2 depth), the period."""

    depth: float
    x_max: float
    t_contact: float
    contact: object  # solve_ivp's dense output of the contact phase from (x_max, 0)

    @property
    def t_flight(self) -> float:
        return 2.0 * math.sqrt(2.0 * self.depth)

    @property
    def period(self) -> float:
        return 2.0 * self.t_contact + self.t_flight

    def x(self, t: np.ndarray) -> np.ndarray:
        """x at the times t >= 0 (start at x_max, v = 0)."""
        phase = np.mod(np.asarray(t, dtype=float), self.period)
        out = np.empty_like(phase)
        down = phase <= self.t_contact
        if down.any():
            out[down] = self.contact(phase[down])[0]
        flight = (phase > self.t_contact) & (phase < self.t_contact + self.t_flight)
        tf = phase[flight] - self.t_contact  # x = -3/2 - v_exit t + t^2/2, v_exit = sqrt(2 depth)
        out[flight] = CONTACT_X - math.sqrt(2.0 * self.depth) * tf + 0.5 * tf * tf
        up = ~(down | flight)
        if up.any():
            out[up] = self.contact(self.period - phase[up])[0]  # the return is the descent reversed in time
        return out

    def exits(self, t_end: float) -> int:
        """Number of contact losses (exits through x = -3/2) in (0, t_end]."""
        return int(math.floor((t_end - self.t_contact) / self.period)) + 1 if t_end >= self.t_contact else 0


def graze_reference(depth: float) -> GrazeReference:
    """The reference motion of a graze of `depth` (module docstring)."""
    from scipy.integrate import quad, solve_ivp
    from scipy.optimize import brentq

    energy = 1.5 + depth
    x_max = brentq(lambda x: potential(x) - energy, 0.0, 10.0, xtol=1e-15, rtol=1e-15)
    # t_contact = integral from -3/2 to x_max of dx / sqrt(2 (E - V(x))), split at the middle:
    # upper half x = x_max - u^2 (the turning point's square-root singularity); lower half xi = x + 3/2 = w^2 - depth,
    # where E - V = w^2 - 0.6 (2 xi / 3)^(5/2) (exact: V = -x + 0.6 g^(5/2), g = 2 xi / 3), so the integrand
    # 2 w / sqrt(2 (E - V)) stays smooth however small depth is.
    middle = 0.5 * (x_max + CONTACT_X)

    def upper(u):
        x = x_max - u * u
        return 2.0 * u / math.sqrt(2.0 * (energy - potential(x))) if u > 0.0 else math.sqrt(2.0 / _potential_slope(x_max))

    def lower(w):
        xi = w * w - depth
        g = 2.0 * xi / 3.0
        return 2.0 * w / math.sqrt(2.0 * (w * w - 0.6 * g * g * math.sqrt(g)))

    t_contact = (quad(upper, 0.0, math.sqrt(x_max - middle), epsabs=0.0, epsrel=1e-13, limit=200)[0]
                 + quad(lower, math.sqrt(depth), math.sqrt(middle - CONTACT_X + depth), epsabs=0.0, epsrel=1e-13,
                        limit=200)[0])

    def rhs(t, y):
        return [y[1], 1.0 - hertz(y[0])]

    contact = solve_ivp(rhs, (0.0, t_contact), [x_max, 0.0], method="DOP853", rtol=1e-13, atol=1e-15,
                        dense_output=True).sol
    return GrazeReference(depth, x_max, t_contact, contact)


def _potential_slope(x: float) -> float:
    return hertz(x) - 1.0


def graze_scene(reference: GrazeReference) -> Scene:
    """The unforced, undamped scene of a graze reference (electrodes far and off)."""
    return Scene(mu=0.0, Delta=0.0, alpha=0.0, beta=0.0, gamma=0.0, R=100.0, x_start=reference.x_max, v_start=0.0)


def count_contact_losses(plant: Plant, stop_time: float, interval: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Run the pure-Python plant (DOP853) and count the contact side's flips from contact to no contact inside its
    integrator (the compiled twin gives the same bits): (times, x, exits)."""
    integrator = plant.integrator
    exits = 0
    handle = integrator._handle_events

    def counting(t0, x0, v0):
        nonlocal exits
        before = integrator.contact_side["contact"]
        handle(t0, x0, v0)
        exits += before and not integrator.contact_side["contact"]

    integrator._handle_events = counting
    times, x, stop = run_plant(plant, stop_time, interval)
    if stop is not None:
        raise RuntimeError(f"graze run stopped: {stop}")
    return times, x, exits


def graze_sweep(depth_exponents=np.arange(1.0, 12.01, 0.5), rtols=(1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
                stop_time: float = 20.0, interval: float = 0.1) -> list[dict]:
    """The graze sweep of docs/events.md: for each depth 10^-k and rtol, the contact losses the plant located against
    the reference's (three in tau <= 20) and max |x - x_ref| in units of rtol max|x_ref|."""
    rows = []
    for k in depth_exponents:
        reference = graze_reference(10.0 ** -float(k))
        for rtol in rtols:
            plant = Plant(graze_scene(reference), Settings(rtol=rtol, kernel=1), 0.0, stop_time)
            times, x, exits = count_contact_losses(plant, stop_time, interval)
            x_ref = reference.x(times)
            rows.append({"depth": reference.depth, "rtol": rtol, "exits": exits, "reference_exits":
                         reference.exits(stop_time), "error": float(np.max(np.abs(x - x_ref)) / (rtol * np.max(np.abs(x_ref))))})
    return rows


def main(argv: list[str]) -> None:
    """Run N scenes (default 10,000) in chunks of 500 (seeds SEED*1000 + chunk), printing the running totals after
    each chunk."""
    from vibrofmu.fmus import kernel

    if argv and argv[0] == "graze":
        rows = graze_sweep()
        located = [row for row in rows if row["exits"] == row["reference_exits"]]
        missed = [row for row in rows if row["exits"] != row["reference_exits"]]
        print(f"{len(rows)} graze runs: all excursions located in {len(located)}; largest depth/rtol with a miss "
              f"{max((row['depth'] / row['rtol'] for row in missed), default=0.0):.3g}; worst error "
              f"{max(row['error'] for row in rows):.3g} rtol max|x| (located runs: "
              f"{max((row['error'] for row in located), default=0.0):.3g})")
        return
    n = int(argv[0]) if argv else 10000
    seed = int(argv[1]) if len(argv) > 1 else 0
    library = kernel.kernel_library()
    total = CampaignResult()
    for chunk, start in enumerate(range(0, n, 500)):
        part = contact_loss_campaign(min(500, n - start), seed * 1000 + chunk, library=library)
        total.scenes += part.scenes
        for key in total.runs:
            total.runs[key] += part.runs[key]
        for key in total.pull_ins:
            total.pull_ins[key] += part.pull_ins[key]
        total.halts += part.halts
        total.twin_mismatches += [(chunk, index) for index in part.twin_mismatches]
        if part.worst_error > total.worst_error:
            total.worst_error, total.worst_case = part.worst_error, (chunk, *part.worst_case)
        total.errors_over_100 += part.errors_over_100
        total.rk4_worst_abs_error = max(total.rk4_worst_abs_error, part.rk4_worst_abs_error)
        total.pull_in_worst_error = max(total.pull_in_worst_error, part.pull_in_worst_error)
        total.seconds += part.seconds
        print(f"after {total.scenes} scenes: {total.summary()}", flush=True)
        for solver, index, scene, rtol, message in part.halts:
            print(f"  halt {solver} chunk {chunk} #{index} rtol {rtol:.3g}: {message} -- {scene}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
