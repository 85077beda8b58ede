"""Fidelity 3's set-up on the compiled kernel: the slow flow integrated and tabulated in C (core/slowflow_table.c),
for slowflow.SlowFlowSolution on a plant whose settings ask for the compiled kernel.

compiled.load_library registers the kernel it loads (use_kernel). The C integrates with the core's DOP853 (scipy's
tableau and dense output, integrate.py's PI step controller), where the pure-Python set-up calls SciPy's solve_ivp:
both tabulate the same slow flow to the same tolerance, not to the same bits (tests/model/test_slowflow_kernel.py
bounds their difference). Packed inside the FMU: the standard library and numpy only.
"""
from __future__ import annotations

import cmath
import ctypes
import math

import numpy as np

from .core_layouts import SfTable

_KERNEL = None
# core/slowflow_table.h's layouts: flow[] (SF_FLOW doubles), out[] (ST_OUTPUTS), its return codes, DOP_MESSAGE
SF_FLOW, ST_OUTPUTS, MESSAGE = 5, 7, 480
ST_OK, ST_CAPACITY, ST_FAILED = 0, 1, 2
_double_p = ctypes.POINTER(ctypes.c_double)


SR_SCENE, SR_FILTER, SR_OUTPUTS = 8, 7, 2  # core/slowflow_table.h: vk_slowflow_residual's scene[], filter[], out[]
_RESIDUAL = None


def use_kernel(library) -> None:
    """Tabulate fidelity 3's slow flow on this kernel library (compiled.load_library's; None: with SciPy)."""
    global _KERNEL, _RESIDUAL
    if library is None or not hasattr(library, "vk_slowflow_tabulate"):
        _KERNEL = _RESIDUAL = None
        return
    function = library.vk_slowflow_tabulate
    function.restype = ctypes.c_int
    function.argtypes = [ctypes.c_double * SF_FLOW, ctypes.c_double, ctypes.c_double * 2, ctypes.c_double,
                         ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_int64,
                         ctypes.c_int64, ctypes.c_int64, _double_p, ctypes.c_double * ST_OUTPUTS,
                         ctypes.c_char * MESSAGE]
    _KERNEL = function
    residual = library.vk_slowflow_residual
    residual.restype = ctypes.c_int
    residual.argtypes = [ctypes.c_void_p, ctypes.c_double * SR_SCENE, ctypes.c_double, ctypes.c_double,
                         ctypes.c_int64, ctypes.c_double * SR_FILTER, ctypes.c_double * SR_OUTPUTS]
    _RESIDUAL = residual


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


def slowflow_table(solution) -> tuple[SfTable, np.ndarray]:
    """The SfTable (core/slowflow_eval.h) of a slowflow.SlowFlowSolution and the array its cells pointer points into
    (keep it)."""
    cells = np.ascontiguousarray(solution.cell_array())
    ac = bool(solution.ac)
    table = SfTable(t0=solution.t0, spacing=solution.spacing, omega=solution.omega, x_e=solution.x_e,
                    harmonic=solution.harmonic, mean_shift=solution.mean_shift,
                    Omega=solution.Omega if ac else 0.0, psi_sin=solution.psi_sin if ac else 0.0,
                    psi_cos=solution.psi_cos if ac else 0.0, ac=int(ac), first=getattr(solution, "first", 0),
                    n_cells=len(cells),
                    t_end=solution.t_end, cells=cells.ctypes.data_as(_double_p))
    return table, cells


def residual_terms(solution, scene, span: float, n: int, mu: float, k1: float) -> tuple[float, float] | None:
    """(max|e|, max|R|) of error_estimates.averaged_terms on the kernel (core/slowflow_table.h, vk_slowflow_residual):
    its n samples over [t0, t0 + span] of the solution's table; None without a kernel or where a sample lies
    outside the table (averaged_terms then computes them with numpy)."""
    if _RESIDUAL is None:
        return None
    table, cells = slowflow_table(solution)
    p = math.sqrt(k1 - 0.25 * mu * mu)  # ValueError for an overdamped k1 <= mu^2/4, as averaged_terms
    lam, dt = complex(-0.5 * mu, p), span / (n - 1)
    step = cmath.exp(lam * dt)
    phi1, phi2 = (step - 1.0) / lam, (step - 1.0 - lam * dt) / (lam * lam * dt)  # linear_response's
    out = (ctypes.c_double * SR_OUTPUTS)()
    code = _RESIDUAL(ctypes.addressof(table), (ctypes.c_double * SR_SCENE)(
        scene.mu, scene.Delta, scene.omega, scene.alpha, scene.beta, scene.gamma, scene.R, scene.Omega),
        solution.t0, span, n, (ctypes.c_double * SR_FILTER)(step.real, step.imag, phi1.real, phi1.imag, phi2.real,
                                                            phi2.imag, p), out)
    del cells  # held until the call returned
    return None if code else (out[0], out[1])
