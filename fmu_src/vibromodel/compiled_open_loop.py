"""Fidelities 3 and 4 on the compiled kernel: the per-output evaluation in C (fmu_src/core/slowflow_eval.c,
oafm_eval.c, openloop_plant.c), the set-up in Python.

Set-up stays where it is: plant.Plant builds the slow-flow table (slowflow.py) or the OAFM fit (analytic.py).
CompiledOpenLoopPlant wraps that Plant, hands its table or closed-form sums to C once, and from then on
doStep is one C call (the FMU's fast path calls ol_do_step directly, without Python). What C does not do
itself -- a refused step, a time beyond the slow flow's table, a non-finite output -- it leaves unchanged and
this class does in Python with the wrapped Plant, which raises the matching error or extends the table.

Fidelity 3 gives the same bits as the Python plant (same operations in the same order). Fidelity 4 computes
each term's exp((-sigma + i nu) s) from a few base exponentials by recurrence instead of one complex exp per
term, which changes the rounding: recurrence_error_bound() states how much.
"""
from __future__ import annotations

import ctypes
import itertools
import math

import numpy as np

from . import plant as plant_module
from .compiled import VkPlant, _model_fields
from .models import Fidelity
from .plant import Outputs, Plant, check_step

OE_BASES, OE_POWERS = 6, 17  # oafm_eval.h
MAX_ITEMS = 256  # oafm_eval.c: distinct decays and distinct frequencies per piece
OL_REFUSED, OL_BEYOND, OL_NONFINITE = 20, 21, 22  # openloop_plant.h
EPS = np.finfo(float).eps
SEARCH_RANGE = 8  # largest |n_j| tried when writing a rate as a combination of bases (harmonic order <= 8)
SEARCH_LIMIT = 200_000  # combinations tried at most per value (the range shrinks with more bases)
MATCH_ULPS = 16.0  # a combination matches a rate within this many ulps of its largest part
OPEN_LOOP = (Fidelity.AVERAGED, Fidelity.ANALYTIC)

_d, _i = ctypes.c_double, ctypes.c_int64
_dp, _ip = ctypes.POINTER(_d), ctypes.POINTER(_i)


class SfTable(ctypes.Structure):
    _fields_ = [(name, _d) for name in ("t0", "spacing", "omega", "x_e", "harmonic", "mean_shift", "Omega",
                                        "psi_sin", "psi_cos")] + \
               [("ac", _i), ("n_cells", _i), ("t_end", _d), ("cells", _dp)]


class OePiece(ctypes.Structure):
    _fields_ = [("start", _d), ("n_decay_bases", _i), ("n_freq_bases", _i),
                ("decay_base", _d * OE_BASES), ("freq_base", _d * OE_BASES),
                ("decay_top", _i * OE_BASES), ("freq_top", _i * OE_BASES),
                ("n_decays", _i), ("n_freqs", _i), ("n_groups", _i),
                ("decay_power", _ip), ("freq_power", _ip), ("group_decay", _ip), ("group_secular", _ip),
                ("group_end", _ip), ("term_freq", _ip), ("term_coefficient", _dp)]


class OeSolution(ctypes.Structure):
    _fields_ = [("n_pieces", _i), ("pieces", ctypes.POINTER(OePiece))]


class OlPlant(ctypes.Structure):
    _fields_ = [("plant", VkPlant), ("fidelity", _i), ("slowflow", SfTable), ("oafm", OeSolution)]


def declare(library) -> str | None:
    """Declare the open-loop functions of the kernel library; None, or why the library cannot run them."""
    try:
        for name, restype, argtypes in (("ol_layout", None, [_ip]),
                                        ("ol_state", ctypes.c_int, [ctypes.c_void_p, _d, _dp]),
                                        ("ol_do_step", ctypes.c_int, [ctypes.c_void_p, _d, _d]),
                                        ("sf_state", ctypes.c_int, [ctypes.c_void_p, _d, _dp]),
                                        ("oe_state", None, [ctypes.c_void_p, _d, _dp])):
            function = getattr(library, name)
            function.restype, function.argtypes = restype, argtypes
    except AttributeError as error:
        return f"the kernel has no open-loop evaluators ({error})"
    sizes = (_i * 4)()
    library.ol_layout(sizes)
    expected = (ctypes.sizeof(OlPlant), ctypes.sizeof(OePiece), OlPlant.slowflow.offset, OlPlant.oafm.offset)
    if tuple(sizes) != expected:
        return f"OlPlant/OePiece layout {tuple(sizes)} in the kernel, {expected} in vibromodel.compiled_open_loop"
    return None


# ---------------------------------------------------------------- fidelity 3: the table

def slowflow_table(solution) -> tuple[SfTable, np.ndarray]:
    """The SfTable of a slowflow.SlowFlowSolution and the array its cells pointer points into (keep it)."""
    cells = np.ascontiguousarray(np.array(solution.cells, dtype=float).reshape(-1, 8))
    ac = bool(solution.ac)
    table = SfTable(t0=solution.t0, spacing=solution.spacing, omega=solution.omega, x_e=solution.x_e,
                    harmonic=solution.harmonic, mean_shift=solution.mean_shift,
                    Omega=solution.Omega if ac else 0.0, psi_sin=solution.psi_sin if ac else 0.0,
                    psi_cos=solution.psi_cos if ac else 0.0, ac=int(ac), n_cells=len(cells),
                    t_end=solution.t_end, cells=cells.ctypes.data_as(_dp))
    return table, cells


# ---------------------------------------------------------------- fidelity 4: rates as combinations of bases

def combinations(values, hints=(), max_bases: int = OE_BASES, top: int = OE_POWERS - 1):
    """(bases, {value: integer vector n}) with value ~ sum_j n_j bases[j], or None if that needs more than
    max_bases bases or a |n_j| > top.

    Values equal to a hint become bases first (the scene's own frequencies q, omega, Omega and decay mu/2, so that
    the combinations are the ones the OAFM basis was built from); every other value, smallest first, is written
    as a combination of the bases so far (the one with the smallest sum |n_j| within MATCH_ULPS ulps), else it
    becomes a base itself.
    """
    distinct = sorted({float(v) for v in values}, key=abs)
    hinted = [v for v in distinct if v != 0.0 and any(v == h for h in hints)]
    order = hinted + [v for v in distinct if v not in hinted]
    bases: list[float] = []
    found: dict[float, tuple[int, ...]] = {}
    for value in order:
        n = None if value in hinted else _combination(value, bases)
        if n is None:
            if value == 0.0:
                n = (0,) * len(bases)
            else:
                bases.append(value)
                n = (0,) * (len(bases) - 1) + (1,)
        found[value] = n
    if len(bases) > max_bases:
        return None
    padded = {v: tuple(n) + (0,) * (max_bases - len(n)) for v, n in found.items()}
    if any(abs(k) > top for n in padded.values() for k in n):
        return None
    return bases, padded


def _combination(value: float, bases: list[float]):
    """The integer vector n with the smallest sum |n_j| such that sum n_j bases[j] matches value, or None."""
    if not bases:
        return None
    reach = SEARCH_RANGE
    while reach > 1 and (2 * reach + 1) ** len(bases) > SEARCH_LIMIT:
        reach -= 1
    n = np.array(list(itertools.product(range(-reach, reach + 1), repeat=len(bases))), dtype=float)
    b = np.array(bases)
    total = n @ b
    scale = np.abs(n) @ np.abs(b) + abs(value)
    ok = np.abs(total - value) <= MATCH_ULPS * EPS * scale
    if not ok.any():
        return None
    candidates = np.flatnonzero(ok)
    best = candidates[np.argmin(np.abs(n[candidates]).sum(axis=1))]
    return tuple(int(k) for k in n[best])


class OafmProgram:
    """The OeSolution of an oafm.AnalyticSolution and the arrays it points into; None-like if unsupported."""

    def __init__(self, solution, hints_sigma=(), hints_nu=()):
        self.keep, self.pieces, self.terms, self.reason = [], [], [], None
        structs = []
        for piece in solution.pieces:
            struct = self._piece(piece, hints_sigma, hints_nu)
            if struct is None:
                return
            structs.append(struct)
        self.array = (OePiece * len(structs))(*structs)
        self.struct = OeSolution(n_pieces=len(structs), pieces=self.array)

    def _array(self, values, kind):
        array = np.ascontiguousarray(np.array(values, dtype=kind))
        self.keep.append(array)
        return array.ctypes.data_as(_ip if kind == np.int64 else _dp)

    def _piece(self, piece, hints_sigma, hints_nu):
        """OePiece of one oafm.Piece: terms grouped by (decay, secular), each with its frequency's index."""
        coefficients = piece._coefficients  # (3, K) complex: c of x, x', x'' per term
        sigma, nu, secular = -piece._rates.real, piece._rates.imag, piece._secular
        decays, freqs = combinations(sigma, hints_sigma), combinations(nu, hints_nu)
        if decays is None or freqs is None:
            self.reason = f"a rate needs more than {OE_BASES} bases or a power beyond {OE_POWERS - 1}"
            return None
        decay_values, freq_values = sorted(decays[1]), sorted(freqs[1])
        if max(len(decay_values), len(freq_values)) > MAX_ITEMS:
            self.reason = f"more than {MAX_ITEMS} distinct rates"
            return None
        decay_index = {v: i for i, v in enumerate(decay_values)}
        freq_index = {v: i for i, v in enumerate(freq_values)}
        groups: dict[tuple[int, int], list[int]] = {}
        for k in range(len(sigma)):
            groups.setdefault((decay_index[float(sigma[k])], int(secular[k])), []).append(k)
        order = [k for key in groups for k in groups[key]]
        ends = np.cumsum([len(g) for g in groups.values()])
        c = coefficients[:, order]
        term_coefficient = np.stack([c[0].real, c[0].imag, c[1].real, c[1].imag, c[2].real, c[2].imag], axis=1)
        decay_power = np.array([decays[1][v] for v in decay_values], dtype=np.int64)
        freq_power = np.array([freqs[1][v] for v in freq_values], dtype=np.int64)
        struct = OePiece(start=piece.start, n_decay_bases=len(decays[0]), n_freq_bases=len(freqs[0]),
                         n_decays=len(decay_values), n_freqs=len(freq_values), n_groups=len(groups))
        for j, base in enumerate(decays[0]):
            struct.decay_base[j] = base
            struct.decay_top[j] = int(np.abs(decay_power[:, j]).max())
        for j, base in enumerate(freqs[0]):
            struct.freq_base[j] = base
            struct.freq_top[j] = int(np.abs(freq_power[:, j]).max())
        struct.decay_power = self._array(decay_power.ravel(), np.int64)
        struct.freq_power = self._array(freq_power.ravel(), np.int64)
        struct.group_decay = self._array([key[0] for key in groups], np.int64)
        struct.group_secular = self._array([key[1] for key in groups], np.int64)
        struct.group_end = self._array(ends, np.int64)
        struct.term_freq = self._array([freq_index[float(nu[k])] for k in order], np.int64)
        struct.term_coefficient = self._array(term_coefficient.ravel(), float)
        self.pieces.append(piece)
        self.terms.append(dict(
            magnitude=np.abs(coefficients).max(axis=0), sigma=sigma, nu=nu, secular=secular,
            decay_n=np.array([decays[1][float(v)][:len(decays[0])] for v in sigma], dtype=float).reshape(len(sigma), -1),
            freq_n=np.array([freqs[1][float(v)][:len(freqs[0])] for v in nu], dtype=float).reshape(len(nu), -1),
            decay_bases=np.array(decays[0]), freq_bases=np.array(freqs[0])))
        return struct

    def error_bound(self, tau: float) -> float:
        """A bound on |C - Python| of x, x' or x'' at tau (recurrence_error_bound)."""
        starts = [p.start for p in self.pieces]
        i = max(0, int(np.searchsorted(starts, tau, side="right")) - 1)
        return recurrence_error_bound(self.terms[i], tau - starts[i])


def recurrence_error_bound(terms: dict, s: float) -> float:
    """Bound on the difference between oafm_eval.c and oafm.Piece.evaluate at local time s, to first order in eps.

    Per term k with magnitude m_k = |c_k| e^(-sigma_k s) s^p_k (largest over x, x', x''), in units of eps:
      - C: each complex or real multiplication adds <= 3 eps (sqrt(5) eps for a complex product, Brent, Percival &
        Zimmermann 2007); the term takes sum_j |n_j| of them for the base powers and their product, plus 3 for its
        coefficient, the decay and s;
      - C: a base's argument b_j s is rounded (eps |b_j s|) and cos/sin/exp err by <= 1 ulp; the power n_j
        multiplies that phase or relative error by |n_j|: sum_j |n_j| (|b_j s| + 1);
      - the combination differs from the rate by |sum n_j b_j - nu_k| (the rounding of the rates themselves):
        that times s;
      - Python: its argument s * rate is rounded (|nu_k s| + |sigma_k s|) and exp/cos/sin err by 1 ulp each (2);
    and both sums of K terms add at most (K - 1) eps sum_k m_k each (recursive summation).
    """
    decay_n, freq_n = terms["decay_n"], terms["freq_n"]
    db, fb = terms["decay_bases"], terms["freq_bases"]
    sigma, nu = terms["sigma"], terms["nu"]
    magnitude = terms["magnitude"] * np.exp(-sigma * s) * np.where(terms["secular"], s, 1.0)
    multiplications = 3.0 * (np.abs(decay_n).sum(axis=1) + np.abs(freq_n).sum(axis=1) + 3.0)
    bases = np.abs(freq_n) @ (np.abs(fb) * s + 1.0) + np.abs(decay_n) @ (np.abs(db) * s + 1.0)
    mismatch = (np.abs(freq_n @ fb - nu) + np.abs(decay_n @ db - sigma)) * s / EPS
    python = np.abs(nu * s) + np.abs(sigma * s) + 2.0
    per_term = magnitude * (multiplications + bases + mismatch + python)
    return float(EPS * (per_term.sum() + 2.0 * (len(sigma) - 1) * magnitude.sum()))


def oafm_hints(scene):
    """(decay hints, frequency hints) of a scene: mu/2, q, sqrt(a1), omega, Omega (oafm_bases)."""
    from .forces import coefficients
    from .oafm_bases import eq11_operator

    a1 = coefficients(scene.alpha, scene.gamma, scene.R)[1]
    try:
        q = eq11_operator(scene).q
    except ValueError:
        q = 0.0
    return (0.5 * scene.mu,), (q, math.sqrt(a1) if a1 > 0 else 0.0, scene.omega, scene.Omega)


# ---------------------------------------------------------------- the plant

class CompiledOpenLoopPlant:
    """plant.Plant of fidelity 3 or 4 with doStep in C; built by make() from a Plant that did the set-up."""

    @classmethod
    def make(cls, python_plant: Plant, library) -> tuple["CompiledOpenLoopPlant | None", str]:
        """(the compiled plant, what it runs on) or (None, why not)."""
        problem = declare(library)
        if problem is not None:
            return None, problem
        compiled = cls(python_plant, library)
        if compiled._problem is not None:
            return None, compiled._problem
        return compiled, "C evaluator (fmu_src/core/" + \
            ("slowflow_eval.c)" if python_plant.settings.fidelity == Fidelity.AVERAGED else "oafm_eval.c)")

    def __init__(self, python_plant: Plant, library):
        self.python = python_plant
        self.scene, self.settings = python_plant.scene, python_plant.settings
        self.notes, self.warnings = python_plant.notes, python_plant.warnings
        self._library, self._problem = library, None
        self._plant = OlPlant()
        self._address = ctypes.addressof(self._plant)
        k = self._plant.plant
        for name, value in _model_fields(self.scene, python_plant.model).items():
            setattr(k, name, value if isinstance(value, (int, float)) else (_d * 6)(*value))
        k.time_tolerance, k.max_step, k.plant_t, k.U_input, k.enabled = \
            plant_module.TIME_TOLERANCE, math.inf, python_plant.t, 0.0, 1
        self._plant.fidelity = int(self.settings.fidelity)
        if self.settings.fidelity == Fidelity.AVERAGED:
            self._load_table()
        else:
            self._program = OafmProgram(python_plant.solution, *oafm_hints(self.scene))
            if self._program.reason is not None:
                self._problem = f"the OAFM sums cannot be evaluated by recurrence: {self._program.reason}"
                return
            self._plant.oafm = self._program.struct

    def _load_table(self) -> None:
        table, self._cells = slowflow_table(self.python.solution)
        self._plant.slowflow = table

    # -- what plant.Plant offers ------------------------------------------------------------------------------
    @property
    def t(self) -> float:
        return self._plant.plant.plant_t

    @property
    def U(self) -> float:
        return self._plant.plant.U_input

    @property
    def solution(self):
        return self.python.solution

    def state_at(self, tau: float) -> tuple[float, float, float]:
        """(x, x', x'') at tau from the C evaluator (the table extended in Python when needed)."""
        xva = (_d * 3)()
        if self._library.ol_state(self._address, tau, xva) == OL_BEYOND:
            self.python.solution.extend(tau)
            self._load_table()
            self._library.ol_state(self._address, tau, xva)
        return tuple(xva)

    def state(self) -> tuple[float, float, float]:
        return self.state_at(self.t)

    def do_step(self, t: float, h: float, U: float) -> Outputs:
        """Plant.do_step in C; what C leaves (a bad step or input, a time beyond the table, a non-finite output)
        is done by the wrapped Plant, which raises its error or extends the table."""
        previous, self._plant.plant.U_input = self._plant.plant.U_input, U
        code = self._library.ol_do_step(self._address, t, h)
        self._plant.plant.U_input = previous
        if code == 0:
            return self._outputs()
        if code == OL_REFUSED:
            check_step(self.t, t, h, U, math.inf, int(self.settings.fidelity))
        self.python.t = self.t
        out = self.python.do_step(t, h, U)  # raises, or extends the table and steps
        if self.settings.fidelity == Fidelity.AVERAGED and self.python.solution.t_end != self._plant.slowflow.t_end:
            self._load_table()
        self._plant.plant.plant_t = self.python.t
        self._publish(out)
        return out

    def advance(self, t_end: float, U: float = 0.0) -> tuple[float, float, float]:
        self._plant.plant.plant_t = t_end
        return self.state()

    def outputs(self) -> Outputs:
        self.python.t = self.t
        return self.python.outputs()

    def outputs_at(self, t: float, x: float, v: float, a: float | None = None) -> Outputs:
        return self.python.outputs_at(t, x, v, a)

    def snapshot(self) -> dict:
        self.python.t, self.python.U = self.t, 0.0
        return self.python.snapshot()

    def restore(self, snapshot: dict) -> None:
        self.python.restore(snapshot)
        self._plant.plant.plant_t = self.python.t
        if self.settings.fidelity == Fidelity.AVERAGED:
            self._load_table()

    # -- what the FMU slave and its C fast path read and write (as vibromodel.compiled.CompiledPlant) ---------
    @property
    def address(self) -> int:
        return self._address

    @property
    def step_function(self) -> int:
        return ctypes.cast(self._library.ol_do_step, ctypes.c_void_p).value

    def field_address(self, name: str, index: int = 0) -> int:
        return self._address + OlPlant.plant.offset + getattr(VkPlant, name).offset + index * ctypes.sizeof(_d)

    def output(self, index: int) -> float:
        return self._plant.plant.out[index]

    def set_output(self, index: int, value: float) -> None:
        self._plant.plant.out[index] = value

    @property
    def in_contact(self) -> bool:
        return bool(self._plant.plant.in_contact)

    @in_contact.setter
    def in_contact(self, value: bool) -> None:
        self._plant.plant.in_contact = bool(value)

    @property
    def next_input(self) -> float:
        return self._plant.plant.U_input

    @next_input.setter
    def next_input(self, value: float) -> None:
        self._plant.plant.U_input = value

    @property
    def fast_path_enabled(self) -> bool:
        return bool(self._plant.plant.enabled)

    @fast_path_enabled.setter
    def fast_path_enabled(self, value: bool) -> None:
        self._plant.plant.enabled = bool(value)

    def _outputs(self) -> Outputs:
        return Outputs(*self._plant.plant.out[:], bool(self._plant.plant.in_contact))

    def _publish(self, out: Outputs) -> None:
        k = self._plant.plant
        k.out[:] = [out.x, out.v, out.a, out.F_contact, out.F_electrostatic]
        k.in_contact = bool(out.in_contact)
