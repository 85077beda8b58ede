"""Brute-force frequency sweeps with the plant FMU itself: up and down in omega, each point continued
from the previous point's end state, each run until the transient has decayed.

Settling criterion (stated in every result): the complex first-harmonic coefficient c (amplitude and
phase: the slow-flow point A - iB) is measured over windows of WINDOW_PERIODS forcing periods. Near a
steady state c - c* ~ e^(lambda t) with Re lambda = -mu/2 for a focus (tr J = -mu; docs/model.md, Averaging and slow flow), so
the step between two windows bounds what is left: |c_w - c_(w-1)| / (1 - e^(-mu T_w/2)) <=
SETTLE_TOLERANCE * |c_w|. The complex c is used, not |c|: on a slow spiral |c| can stand still while c
moves. Close to a fold the slow eigenvalue tends to 0 and the bound is optimistic. A point that does
not settle within MAX_PERIODS is kept and flagged.
"""
from __future__ import annotations

import math
import shutil
from dataclasses import dataclass

import numpy as np
from fmpy import extract
from fmpy.fmi1 import FMICallException

from vibromodel.parameters import Scene
from vibromodel.plant import Settings

from vibrofmu.hosts.run import FmuInstance, call_failure_reason
from vibrofmu.analyses.harmonics import first_harmonic
from vibrofmu.analyses.simulate import start_values

WINDOW_PERIODS = 10
SAMPLES_PER_PERIOD = 32  # communication steps per forcing period; the first harmonic is exact for these
# relative to |c|. Enough to tell the branches apart (> 20 % apart), and not tighter: with Omega near 2 omega
# (the paper's Omega = 2) the AC drive modulates a steady vibration by ~0.5 % over ~150 periods, so c never
# stops moving by more than that
SETTLE_TOLERANCE = 3e-2
MAX_PERIODS = 1500


@dataclass
class SweepPoint:
    omega: float
    r: float  # first-harmonic amplitude |2/T int x e^(-i omega t)| over the last window
    mean: float
    settled: bool
    periods: int  # forcing periods simulated at this frequency
    end_state: tuple[float, float]


@dataclass
class Sweep:
    direction: str  # "up" or "down"
    points: list[SweepPoint]
    stop_reason: str | None = None  # the FMU stopped early: its log message

    @property
    def omega(self) -> np.ndarray:
        return np.array([p.omega for p in self.points])

    @property
    def r(self) -> np.ndarray:
        return np.array([p.r for p in self.points])


HYSTERESIS_THRESHOLD = 0.05  # up and down amplitudes this far apart (relative) are on different branches


def hysteresis_jumps(up: Sweep, down: Sweep, threshold: float = HYSTERESIS_THRESHOLD) -> list[dict]:
    """Jumps read off the two sweeps over the same grid: where up and down both settle, on different
    branches, the response is bistable; the up sweep jumps just past the high end of that interval, the
    down sweep just past its low end. A point still unsettled is in transit (near a fold the jump can
    outlast MAX_PERIODS) and is not counted as bistable. Each jump is placed midway between the last point
    on the old branch and the next grid point (error <= half a step)."""
    omega = up.omega
    r_down = down.r[::-1]  # the down sweep ran over the same grid in reverse
    if len(down.points) != len(up.points) or not np.allclose(omega, down.omega[::-1], rtol=0, atol=1e-15):
        return []
    settled = np.array([p.settled for p in up.points]) & np.array([p.settled for p in down.points][::-1])
    apart = np.abs(up.r - r_down) > threshold * np.maximum(up.r, r_down)
    bistable = np.flatnonzero(apart & settled)
    if bistable.size == 0:
        return []
    jumps = []
    first, last = bistable[0], bistable[-1]
    if last + 1 < len(omega):
        jumps.append({"sweep": "up", "omega": 0.5 * (omega[last] + omega[last + 1]),
                      "r_before": float(up.r[last]), "r_after": float(up.r[last + 1])})
    if first > 0:
        jumps.append({"sweep": "down", "omega": 0.5 * (omega[first] + omega[first - 1]),
                      "r_before": float(r_down[first]), "r_after": float(r_down[first - 1])})
    return sorted(jumps, key=lambda jump: jump["omega"])


class SweepStopped(RuntimeError):
    """The FMU refused a call during a sweep; the message carries its log message."""


def settle_loop(step, scene: Scene, accept=None, rate: float | None = None,
                window=None) -> tuple[complex, float, bool, int]:
    """The settling loop of the module docstring on any stepper: step(t, h) advances one communication step
    from t and returns x at t + h (it may raise to stop); or window(k, h, count), if given: the x after each of
    the count steps from k h, (k + 1) h, ... (the same steps in one call). Returns (c, mean, settled, periods).

    accept(c), if given, must also hold to stop: near a saddle of the slow flow c creeps as slowly as at a
    settled focus (its unstable eigenvalue is small), and a caller that knows where the attractors are can
    refuse to stop there. rate: the slowest decay rate of the transient, -Re lambda (default mu/2, a focus);
    a caller that knows a slower one (a stable node near a fold) passes it, and the bound stays true."""
    T = 2 * math.pi / scene.omega
    h = T / SAMPLES_PER_PERIOD
    decay = 1.0 - math.exp(-(scene.mu / 2 if rate is None else rate) * WINDOW_PERIODS * T)
    c_previous, n, periods = complex(math.nan), 0, 0
    while True:
        if window is not None:
            x = window(n, h, WINDOW_PERIODS * SAMPLES_PER_PERIOD)
            n += len(x)
        else:
            x = np.empty(WINDOW_PERIODS * SAMPLES_PER_PERIOD)
            for k in range(len(x)):
                x[k] = step(n * h, h)
                n += 1
        periods += WINDOW_PERIODS
        c, mean = first_harmonic(np.roll(x, 1), SAMPLES_PER_PERIOD)  # x[k] is at (k + 1) h: roll so that index = phase
        settled = abs(c - c_previous) <= SETTLE_TOLERANCE * abs(c) * decay and (accept is None or accept(c))
        if settled or periods >= MAX_PERIODS:
            return c, mean, settled, periods
        c_previous = c


def settle(fmu_path, unzip_dir: str, scene: Scene, settings: Settings) -> SweepPoint:
    """Run one frequency from the scene's start state until the transient has decayed (module docstring).
    Raises SweepStopped with the FMU's own log message if the FMU fails."""
    instance = FmuInstance(fmu_path, unzip_dir=unzip_dir)
    fmu = instance.fmu
    refs = instance.value_references(["x", "v"])

    def step(t, h):
        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        return fmu.getReal(refs[:1])[0]

    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        instance.set(start_values(scene, settings))
        fmu.exitInitializationMode()
        c, mean, settled, periods = settle_loop(step, scene)
        return SweepPoint(scene.omega, abs(c), mean, settled, periods, tuple(fmu.getReal(refs)))
    except FMICallException as error:
        raise SweepStopped(call_failure_reason(error, instance.log)) from None
    finally:
        instance.close()


def sweep(fmu_path, scene: Scene, omegas, settings: Settings = Settings(), progress=None) -> Sweep:
    """Sweep through omegas in the given order (increasing: up, decreasing: down); each point starts
    from the previous point's end state, which lies at phase 0 of its forcing (whole periods)."""
    omegas = [float(w) for w in omegas]
    direction = "up" if omegas[-1] > omegas[0] else "down"
    unzip_dir = extract(str(fmu_path))
    points, current = [], scene
    try:
        for i, omega in enumerate(omegas):
            try:
                point = settle(fmu_path, unzip_dir, current.with_values(omega=omega), settings)
            except SweepStopped as error:
                return Sweep(direction, points, f"at omega = {omega:.8g}: {error}")
            points.append(point)
            current = current.with_values(x_start=point.end_state[0], v_start=point.end_state[1])
            if progress is not None:
                progress(i + 1, len(omegas))
    finally:
        shutil.rmtree(unzip_dir, ignore_errors=True)
    return Sweep(direction, points)
