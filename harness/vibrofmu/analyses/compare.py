"""Errors of a run against a reference on the run's output grid."""
from __future__ import annotations

import numpy as np


def errors(time: np.ndarray, x: np.ndarray, v: np.ndarray, reference) -> dict:
    """Max abs and RMS error of x and v over the grid, and the error of x at the last point."""
    x_ref, v_ref = reference(time)
    ex, ev = np.abs(x - x_ref), np.abs(v - v_ref)
    return {
        "max_abs_error_x": float(np.max(ex)),
        "rms_error_x": float(np.sqrt(np.mean(ex**2))),
        "max_abs_error_v": float(np.max(ev)),
        "rms_error_v": float(np.sqrt(np.mean(ev**2))),
        "final_error_x": float(ex[-1]),
        "tau_of_max_error_x": float(time[int(np.argmax(ex))]),
    }
