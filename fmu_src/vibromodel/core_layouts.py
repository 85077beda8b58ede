"""The compiled core's constants and structures as ctypes: GENERATED from fmu_src/core/*.h by
harness/vibrofmu/fmus/layouts.py (python3 -m vibrofmu.fmus.layouts); do not edit. tests/core/test_core_layouts.py
checks that this module is current and that every size and offset is the C compiler's."""
import ctypes


# dop853.h
DOP_MAX_DIM = 16
DOP_MAX_EVENTS = 4
DOP_STAGES = 16
DOP_DENSE = 7
DOP_MESSAGE = 480
DOP_OK = 0
DOP_TERMINAL = 5
DOP_FAILED = 6
DOP_RAISED = 7

# rk4.h
RK4_MAX_PHASES = 3
RK4_PHASE_RESYNC = 16

# plant.h
VK_MESSAGE = DOP_MESSAGE
VK_OK = 0
VK_BAD_STEP = 1
VK_BAD_INPUT = 2
VK_TOO_MANY_STEPS = 3
VK_BAD_TIME = 4
VK_TERMINAL = DOP_TERMINAL
VK_FAILED = DOP_FAILED
VK_RAISED = DOP_RAISED
VK_DOP853 = 0
VK_RK4 = 1

# oafm_eval.h
OE_BASES = 6
OE_POWERS = 17
OE_ITEMS = 256
OE_RESYNC = 16
OE_STEP_SLACK = 4.0

# openloop_plant.h
OL_REFUSED = 20
OL_BEYOND = 21
OL_NONFINITE = 22

# controller.h
VC_N = 9
VC_INPUTS = 5
VC_OUTPUTS = 13
VC_GAINS = 11
VC_OK = 0
VC_BAD_STEP = 1
VC_BAD_INPUT = 2
VC_BAD_TIME = 4
VC_RAISED = 7
VC_NON_FINITE = 8

# closedloop.h
VL_DIM = 11
VL_OUTPUTS = 18
VL_MESSAGE = DOP_MESSAGE
VL_MAX_STEPS_PER_DOSTEP = 1000000.0
VL_OK = 0
VL_BAD_STEP = 1
VL_TOO_MANY_STEPS = 3
VL_BAD_TIME = 4
VL_TERMINAL = DOP_TERMINAL
VL_FAILED = DOP_FAILED
VL_RAISED = DOP_RAISED
VL_DOP853 = 0
VL_RK4 = 1


class DopEvent(ctypes.Structure):
    """dop853.h's DopEvent."""
    _fields_ = [
        ("c0", ctypes.c_double),
        ("c", ctypes.c_double * DOP_MAX_DIM),
        ("terminal", ctypes.c_int64),
    ]


class Dop853(ctypes.Structure):
    """dop853.h's Dop853."""
    _fields_ = [
        ("n", ctypes.c_int64),
        ("n_events", ctypes.c_int64),
        *[(name, ctypes.c_double) for name in ("rtol", "atol", "max_step", "step_budget")],
        ("events", DopEvent * DOP_MAX_EVENTS),
        *[(name, ctypes.c_double) for name in ("t", "h", "err_old")],
        ("y", ctypes.c_double * DOP_MAX_DIM),
        ("f", ctypes.c_double * DOP_MAX_DIM),
        ("t_old", ctypes.c_double),
        ("y_old", ctypes.c_double * DOP_MAX_DIM),
        ("f_old", ctypes.c_double * DOP_MAX_DIM),
        ("k", (ctypes.c_double * DOP_MAX_DIM) * DOP_STAGES),
        ("dense", (ctypes.c_double * DOP_MAX_DIM) * DOP_DENSE),
        ("stop_t", ctypes.c_double),
        ("stop_y", ctypes.c_double * DOP_MAX_DIM),
        *[(name, ctypes.c_int64) for name in ("has_old", "n_stages", "dense_ready", "stopped")],
        ("side", ctypes.c_int64 * DOP_MAX_EVENTS),
        ("nfev", ctypes.c_int64),
        ("n_steps", ctypes.c_int64),
    ]


class DopReport(ctypes.Structure):
    """dop853.h's DopReport."""
    _fields_ = [
        ("t", ctypes.c_double),
        ("y", ctypes.c_double * DOP_MAX_DIM),
        ("event", ctypes.c_int64),
        ("message", ctypes.c_char * DOP_MESSAGE),
    ]


class Rk4(ctypes.Structure):
    """rk4.h's Rk4."""
    _fields_ = [
        ("n", ctypes.c_int64),
        ("n_events", ctypes.c_int64),
        ("max_step", ctypes.c_double),
        ("events", DopEvent * DOP_MAX_EVENTS),
        ("t", ctypes.c_double),
        ("y", ctypes.c_double * DOP_MAX_DIM),
        ("nfev", ctypes.c_int64),
        ("n_steps", ctypes.c_int64),
    ]


class VkModel(ctypes.Structure):
    """model.h's VkModel."""
    _fields_ = [
        *[(name, ctypes.c_double) for name in ("mu", "Delta", "omega", "alpha", "beta", "gamma", "Omega", "R")],
        *[(name, ctypes.c_double * 6) for name in ("poly", "g1", "g2", "g3")],
        ("pull_in_c", ctypes.c_double),
        ("pull_in_gap", ctypes.c_double),
        *[(name, ctypes.c_int64) for name in ("polynomial", "load_forcing", "electrostatics", "ac")],
    ]


class VmDrive(ctypes.Structure):
    """model.h's VmDrive."""
    _fields_ = [
        *[(name, ctypes.c_double) for name in ("cos_omega_t", "sin_Omega_t", "cos_2Omega_t")],
    ]


class VkPlant(ctypes.Structure):
    """plant.h's VkPlant."""
    _fields_ = [
        ("model", VkModel),
        ("time_tolerance", ctypes.c_double),
        ("max_steps_per_dostep", ctypes.c_double),
        ("solver", ctypes.c_int64),
        ("dop", Dop853),
        ("rk4", Rk4),
        *[(name, ctypes.c_double) for name in ("U", "plant_t", "U_input")],
        ("out", ctypes.c_double * 5),
        *[(name, ctypes.c_int64) for name in ("in_contact", "enabled", "error")],
        *[(name, ctypes.c_double) for name in ("error_t", "error_x", "error_v")],
        ("message", ctypes.c_char * VK_MESSAGE),
    ]


class SfTable(ctypes.Structure):
    """slowflow_eval.h's SfTable."""
    _fields_ = [
        *[(name, ctypes.c_double) for name in ("t0", "spacing", "omega", "x_e", "harmonic", "mean_shift", "Omega",
    "psi_sin", "psi_cos")],
        *[(name, ctypes.c_int64) for name in ("ac", "first", "n_cells")],
        ("t_end", ctypes.c_double),
        ("cells", ctypes.POINTER(ctypes.c_double)),
    ]


class OePiece(ctypes.Structure):
    """oafm_eval.h's OePiece."""
    _fields_ = [
        ("start", ctypes.c_double),
        ("n_decay_bases", ctypes.c_int64),
        ("n_freq_bases", ctypes.c_int64),
        ("decay_base", ctypes.c_double * OE_BASES),
        ("freq_base", ctypes.c_double * OE_BASES),
        *[(name, ctypes.c_int64 * OE_BASES) for name in ("decay_top", "decay_bottom", "decay_zero", "freq_top",
    "freq_zero")],
        *[(name, ctypes.c_int64) for name in ("n_decay_table", "n_decay_rows", "n_freq_table", "n_freq_rows")],
        ("decay_chain", ctypes.POINTER(ctypes.c_int64)),
        ("freq_chain", ctypes.POINTER(ctypes.c_int64)),
        ("n_groups", ctypes.c_int64),
        *[(name, ctypes.POINTER(ctypes.c_int64)) for name in ("group_decay", "group_secular", "group_end",
    "term_freq")],
        ("term_coefficient", ctypes.POINTER(ctypes.c_double)),
    ]


class OeCache(ctypes.Structure):
    """oafm_eval.h's OeCache."""
    _fields_ = [
        ("piece", ctypes.c_int64),
        ("count", ctypes.c_int64),
        *[(name, ctypes.c_double) for name in ("s", "rotation_h", "seen_h")],
        *[(name, ctypes.c_double * OE_ITEMS) for name in ("wre", "wim", "D", "rwre", "rwim", "rD")],
    ]


class OeSolution(ctypes.Structure):
    """oafm_eval.h's OeSolution."""
    _fields_ = [
        ("n_pieces", ctypes.c_int64),
        ("pieces", ctypes.POINTER(OePiece)),
        ("cache", OeCache),
    ]


class OlPlant(ctypes.Structure):
    """openloop_plant.h's OlPlant."""
    _fields_ = [
        ("plant", VkPlant),
        ("fidelity", ctypes.c_int64),
        ("slowflow", SfTable),
        ("oafm", OeSolution),
    ]


class VcRegressor(ctypes.Structure):
    """controller.h's VcRegressor."""
    _fields_ = [
        *[(name, ctypes.c_double) for name in ("w_delta", "delta_sign", "w_beta", "w_gamma")],
    ]


class VcController(ctypes.Structure):
    """controller.h's VcController."""
    _fields_ = [
        ("g3", ctypes.c_double * 6),
        ("phi", VcRegressor),
        ("phi_update", VcRegressor),
        ("theta", ctypes.c_double * VC_N),
        ("l1", ctypes.c_double),
        ("l2", ctypes.c_double),
        ("Lambda", ctypes.c_double * VC_N),
        ("adaptation", ctypes.c_double * VC_N),
        *[(name, ctypes.c_double) for name in ("c", "k_damping", "promised_e1", "true_delta")],
        ("law", ctypes.c_int64),
        ("time_tolerance", ctypes.c_double),
        ("t", ctypes.c_double),
        ("theta_hat", ctypes.c_double * VC_N),
        ("in", ctypes.c_double * VC_INPUTS),
        ("out", ctypes.c_double * VC_OUTPUTS),
        ("enabled", ctypes.c_int64),
    ]


class VlLoop(ctypes.Structure):
    """closedloop.h's VlLoop."""
    _fields_ = [
        ("model", VkModel),
        ("controller", VcController),
        ("solver", ctypes.c_int64),
        ("time_tolerance", ctypes.c_double),
        ("dop", Dop853),
        ("rk4", Rk4),
        ("t", ctypes.c_double),
        ("out", ctypes.c_double * VL_OUTPUTS),
        ("enabled", ctypes.c_int64),
        ("error", ctypes.c_int64),
        *[(name, ctypes.c_double) for name in ("error_t", "error_x", "error_v")],
        ("message", ctypes.c_char * VL_MESSAGE),
        ("reference", OeSolution),
    ]


STRUCTURES = (DopEvent, Dop853, DopReport, Rk4, VkModel, VmDrive, VkPlant, SfTable, OePiece, OeCache, OeSolution,
    OlPlant, VcRegressor, VcController, VlLoop,)
