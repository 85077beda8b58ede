"""The compiled core's constants and structures as ctypes: GENERATED from fmu_src/core/*.h by
harness/vibrofmu/fmus/layouts.py (python3 -m vibrofmu.fmus.layouts); do not edit. tests/test_core_layouts.py
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
VL_OK = 0
VL_BAD_STEP = 1
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
        ("rtol", ctypes.c_double),
        ("atol", ctypes.c_double),
        ("max_step", ctypes.c_double),
        ("step_budget", ctypes.c_double),
        ("events", DopEvent * DOP_MAX_EVENTS),
        ("t", ctypes.c_double),
        ("h", ctypes.c_double),
        ("y", ctypes.c_double * DOP_MAX_DIM),
        ("f", ctypes.c_double * DOP_MAX_DIM),
        ("t_old", ctypes.c_double),
        ("y_old", ctypes.c_double * DOP_MAX_DIM),
        ("f_old", ctypes.c_double * DOP_MAX_DIM),
        ("k", (ctypes.c_double * DOP_MAX_DIM) * DOP_STAGES),
        ("dense", (ctypes.c_double * DOP_MAX_DIM) * DOP_DENSE),
        ("stop_t", ctypes.c_double),
        ("stop_y", ctypes.c_double * DOP_MAX_DIM),
        ("has_old", ctypes.c_int64),
        ("n_stages", ctypes.c_int64),
        ("dense_ready", ctypes.c_int64),
        ("stopped", ctypes.c_int64),
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
        ("mu", ctypes.c_double),
        ("Delta", ctypes.c_double),
        ("omega", ctypes.c_double),
        ("alpha", ctypes.c_double),
        ("beta", ctypes.c_double),
        ("gamma", ctypes.c_double),
        ("Omega", ctypes.c_double),
        ("R", ctypes.c_double),
        ("poly", ctypes.c_double * 6),
        ("g1", ctypes.c_double * 6),
        ("g2", ctypes.c_double * 6),
        ("g3", ctypes.c_double * 6),
        ("pull_in_c", ctypes.c_double),
        ("pull_in_gap", ctypes.c_double),
        ("polynomial", ctypes.c_int64),
        ("load_forcing", ctypes.c_int64),
        ("electrostatics", ctypes.c_int64),
        ("ac", ctypes.c_int64),
    ]


class VmDrive(ctypes.Structure):
    """model.h's VmDrive."""
    _fields_ = [
        ("cos_omega_t", ctypes.c_double),
        ("sin_Omega_t", ctypes.c_double),
        ("cos_2Omega_t", ctypes.c_double),
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
        ("U", ctypes.c_double),
        ("plant_t", ctypes.c_double),
        ("U_input", ctypes.c_double),
        ("out", ctypes.c_double * 5),
        ("in_contact", ctypes.c_int64),
        ("enabled", ctypes.c_int64),
        ("error", ctypes.c_int64),
        ("error_t", ctypes.c_double),
        ("error_x", ctypes.c_double),
        ("error_v", ctypes.c_double),
        ("message", ctypes.c_char * VK_MESSAGE),
    ]


class SfTable(ctypes.Structure):
    """slowflow_eval.h's SfTable."""
    _fields_ = [
        ("t0", ctypes.c_double),
        ("spacing", ctypes.c_double),
        ("omega", ctypes.c_double),
        ("x_e", ctypes.c_double),
        ("harmonic", ctypes.c_double),
        ("mean_shift", ctypes.c_double),
        ("Omega", ctypes.c_double),
        ("psi_sin", ctypes.c_double),
        ("psi_cos", ctypes.c_double),
        ("ac", ctypes.c_int64),
        ("first", ctypes.c_int64),
        ("n_cells", ctypes.c_int64),
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
        ("decay_top", ctypes.c_int64 * OE_BASES),
        ("decay_bottom", ctypes.c_int64 * OE_BASES),
        ("decay_zero", ctypes.c_int64 * OE_BASES),
        ("freq_top", ctypes.c_int64 * OE_BASES),
        ("freq_zero", ctypes.c_int64 * OE_BASES),
        ("n_decay_table", ctypes.c_int64),
        ("n_decay_rows", ctypes.c_int64),
        ("n_freq_table", ctypes.c_int64),
        ("n_freq_rows", ctypes.c_int64),
        ("decay_chain", ctypes.POINTER(ctypes.c_int64)),
        ("freq_chain", ctypes.POINTER(ctypes.c_int64)),
        ("n_groups", ctypes.c_int64),
        ("group_decay", ctypes.POINTER(ctypes.c_int64)),
        ("group_secular", ctypes.POINTER(ctypes.c_int64)),
        ("group_end", ctypes.POINTER(ctypes.c_int64)),
        ("term_freq", ctypes.POINTER(ctypes.c_int64)),
        ("term_coefficient", ctypes.POINTER(ctypes.c_double)),
    ]


class OeCache(ctypes.Structure):
    """oafm_eval.h's OeCache."""
    _fields_ = [
        ("piece", ctypes.c_int64),
        ("count", ctypes.c_int64),
        ("s", ctypes.c_double),
        ("rotation_h", ctypes.c_double),
        ("seen_h", ctypes.c_double),
        ("wre", ctypes.c_double * OE_ITEMS),
        ("wim", ctypes.c_double * OE_ITEMS),
        ("D", ctypes.c_double * OE_ITEMS),
        ("rwre", ctypes.c_double * OE_ITEMS),
        ("rwim", ctypes.c_double * OE_ITEMS),
        ("rD", ctypes.c_double * OE_ITEMS),
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
        ("w_delta", ctypes.c_double),
        ("delta_sign", ctypes.c_double),
        ("w_beta", ctypes.c_double),
        ("w_gamma", ctypes.c_double),
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
        ("c", ctypes.c_double),
        ("k_damping", ctypes.c_double),
        ("promised_e1", ctypes.c_double),
        ("true_delta", ctypes.c_double),
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
        ("error_t", ctypes.c_double),
        ("error_x", ctypes.c_double),
        ("error_v", ctypes.c_double),
        ("message", ctypes.c_char * VL_MESSAGE),
        ("reference", OeSolution),
    ]


STRUCTURES = (DopEvent, Dop853, DopReport, Rk4, VkModel, VmDrive, VkPlant, SfTable, OePiece, OeCache, OeSolution,
    OlPlant, VcRegressor, VcController, VlLoop,)
