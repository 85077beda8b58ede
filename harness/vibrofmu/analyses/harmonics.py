"""The first harmonic of a periodic signal sampled uniformly in phase: the one home of the amplitude and phase
that the shooting method (shooting.py), the FMU sweeps (sweep.py) and the cusp study report."""
from __future__ import annotations

import numpy as np


def first_harmonic(x, samples_per_period: int) -> tuple[complex, float]:
    """(c, mean) of the samples x_k at the phases 2 pi k / samples_per_period, k = 0 .. len(x) - 1, over whole
    periods: c = (2/N) sum x_k e^(-2 pi i k / samples_per_period), mean = (1/N) sum x_k, so that
    x(phase) ~ mean + Re(c e^(i phase)). For a periodic x this is the trapezoid rule of
    c = (1/pi) int_0^{2 pi} x(s) e^(-i s) ds, exact to round-off for an analytic x and enough samples."""
    x = np.asarray(x, dtype=float)
    phase = np.exp(-2j * np.pi * np.arange(len(x)) / samples_per_period)
    return complex(2.0 * np.mean(x * phase)), float(np.mean(x))
