"""Fidelity 3's set-up on the compiled kernel: the slow flow integrated and tabulated in C (core/slowflow_table.c),
for slowflow.SlowFlowSolution on a plant whose settings ask for the compiled kernel.

compiled.load_library registers the kernel it loads (use_kernel). The C integrates with the core's DOP853 (scipy's
tableau and dense output, integrate.py's PI step controller), where the pure-Python set-up calls SciPy's solve_ivp:
both tabulate the same slow flow to the same tolerance, not to the same bits (tests/model/test_slowflow_kernel.py
bounds their difference). Packed inside the FMU: the standard library and numpy only.
"""
from __future__ import annotations

import ctypes

import numpy as np

_KERNEL = None
# core/slowflow_table.h's layouts: flow[] (SF_FLOW doubles), out[] (ST_OUTPUTS), its return codes, DOP_MESSAGE
SF_FLOW, ST_OUTPUTS, MESSAGE = 5, 7, 480
ST_OK, ST_CAPACITY, ST_FAILED = 0, 1, 2
_double_p = ctypes.POINTER(ctypes.c_double)


def use_kernel(library) -> None:
    """Tabulate fidelity 3's slow flow on this kernel library (compiled.load_library's; None: with SciPy)."""
    global _KERNEL
    if library is None or not hasattr(library, "vk_slowflow_tabulate"):
        _KERNEL = None
        return
    function = library.vk_slowflow_tabulate
    function.restype = ctypes.c_int
    function.argtypes = [ctypes.c_double * SF_FLOW, ctypes.c_double, ctypes.c_double * 2, ctypes.c_double,
                         ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_int64,
                         ctypes.c_int64, ctypes.c_int64, _double_p, ctypes.c_double * ST_OUTPUTS,
                         ctypes.c_char * MESSAGE]
    _KERNEL = function


def kernel_loaded() -> bool:
    return _KERNEL is not None


def tabulate(flow, t_start: float, Z0, span: float, rtol: float, atol: float, max_step: float, spacing: float,
             n: int, max_refinements: int, capacity: int):
    """(spacing, cells as an (n, 8) array, Z at t_start + span, the table's tolerance, the integrator's steps of
    its last grid) from the kernel
    (core/slowflow_table.h); None when the grid needs more than `capacity` cells; RuntimeError naming the
    integrator's failure. flow: an averaging.SlowFlow; spacing <= 0: refined (slowflow._refined_cells)."""
    backbone = flow.backbone
    parameters = (ctypes.c_double * SF_FLOW)(flow.mu, flow.detuning, flow.drive, backbone.kappa2, backbone.kappa4)
    cells = np.empty((max(int(capacity), 1), 8))
    out = (ctypes.c_double * ST_OUTPUTS)()
    message = (ctypes.c_char * MESSAGE)()
    code = _KERNEL(parameters, t_start, (ctypes.c_double * 2)(*Z0), span, rtol, atol, max_step, spacing, int(n),
                   int(max_refinements), int(capacity), cells.ctypes.data_as(_double_p), out, message)
    if code == ST_CAPACITY:
        return None
    if code != ST_OK:
        raise RuntimeError(f"slow flow integration failed: {message.value.decode(errors='replace')}")
    count = int(out[1])
    return out[0], cells[:count], (out[2], out[3]), out[5], int(out[6])
