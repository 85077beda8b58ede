"""Fidelities 3 and 4 on the compiled kernel: the per-output evaluation in C (fmu_src/core/slowflow_eval.c,
oafm_eval.c, openloop_plant.c), the set-up in Python.

Set-up stays where it is: plant.Plant builds the slow-flow table (slowflow.py, itself in C where the kernel is
loaded: core/slowflow_table.c) or the OAFM fit (analytic.py).
CompiledOpenLoopPlant wraps that Plant, hands its table or closed-form sums to C once, and from then on
doStep is one C call (the FMU's fast path calls vk_open_loop_do_step directly, without Python). What C does not do
itself -- a refused step, a time beyond the slow flow's table, a non-finite output -- it leaves unchanged and
this class does in Python with the wrapped Plant, which raises the matching error or extends the table.

Fidelity 3 gives the same bits as the Python plant (same operations in the same order). Fidelity 4 computes
each term's exp((-sigma + i nu) s) from a few base exponentials by recurrence instead of one complex exp per
term, which changes the rounding: recurrence_error_bound() states how much.
"""
from __future__ import annotations

import ctypes
import functools
import math
from dataclasses import dataclass

import numpy as np

from . import slowflow_kernel
from .compiled import PlantFastPath, fill_model
# oafm_eval.h's and openloop_plant.h's constants and structures, generated from the headers (core_layouts.py)
from .core_layouts import (OE_BASES, OE_ITEMS, OE_POWERS, OE_RESYNC, OE_STEP_SLACK, OL_BEYOND, OL_REFUSED, OeCache,
                           OePiece, OeSolution, OlPlant)
from .fidelities import Evaluator, entry
from .forces import coefficients
from .oafm_bases import eq11_operator
from .settings import TIME_TOLERANCE, Outputs, check_step

EPS = np.finfo(float).eps
SEARCH_RANGE = 8  # largest |n_j| tried when writing a rate as a combination of bases (harmonic order <= 8)
SEARCH_LIMIT = 200_000  # combinations tried at most per value (the range shrinks with more bases)
MATCH_ULPS = 16.0  # a combination matches a rate within this many ulps of its largest part
EVALUATOR_SOURCES = {Evaluator.SLOWFLOW: "slowflow_eval.c", Evaluator.OAFM: "oafm_eval.c"}  # in fmu_src/core

_d, _i = ctypes.c_double, ctypes.c_int64
_dp, _ip = ctypes.POINTER(_d), ctypes.POINTER(_i)


def declare(library) -> str | None:
    """Declare the open-loop functions of the kernel library; None, or why the library cannot run them."""
    try:
        for name, restype, argtypes in (("vk_open_loop_layout", None, [_ip]),
                                        ("vk_open_loop_state", ctypes.c_int, [ctypes.c_void_p, _d, _dp]),
                                        ("vk_open_loop_do_step", ctypes.c_int, [ctypes.c_void_p, _d, _d]),
                                        ("vk_slowflow_state", ctypes.c_int, [ctypes.c_void_p, _d, _dp]),
                                        ("vk_oafm_state", None, [ctypes.c_void_p, _d, _dp]),
                                        ("vk_oafm_step", None, [ctypes.c_void_p, _d, _dp]),
                                        ("vk_open_loop_run", ctypes.c_int, [ctypes.c_void_p, _d, ctypes.c_size_t, _dp,
                                                                   ctypes.POINTER(ctypes.c_size_t)])):
            function = getattr(library, name)
            function.restype, function.argtypes = restype, argtypes
    except AttributeError as error:
        return f"the kernel has no open-loop evaluators ({error})"
    sizes = (_i * 4)()
    library.vk_open_loop_layout(sizes)
    expected = (ctypes.sizeof(OlPlant), ctypes.sizeof(OePiece), OlPlant.slowflow.offset, OlPlant.oafm.offset)
    if tuple(sizes) != expected:
        return f"OlPlant/OePiece layout {tuple(sizes)} in the kernel, {expected} in vibromodel.compiled_open_loop"
    return None


# ---------------------------------------------------------------- fidelity 3: the table

slowflow_table = slowflow_kernel.slowflow_table  # the SfTable of a slowflow.SlowFlowSolution (and its cells)


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


@functools.lru_cache(maxsize=None)
def _search_grid(n_bases: int) -> np.ndarray:
    """Every integer vector with entries in -reach..reach (reach <= SEARCH_RANGE, fewer for more bases), as rows."""
    reach = SEARCH_RANGE
    while reach > 1 and (2 * reach + 1) ** n_bases > SEARCH_LIMIT:
        reach -= 1
    axes = np.meshgrid(*[np.arange(-reach, reach + 1, dtype=float)] * n_bases, indexing="ij")
    grid = np.stack([axis.ravel() for axis in axes], axis=1)
    grid.flags.writeable = False
    return grid


def _combination(value: float, bases: list[float]):
    """The integer vector n with the smallest sum |n_j| such that sum n_j bases[j] matches value, or None."""
    if not bases:
        return None
    n = _search_grid(len(bases))
    b = np.array(bases)
    total = n @ b
    scale = np.abs(n) @ np.abs(b) + abs(value)
    ok = np.abs(total - value) <= MATCH_ULPS * EPS * scale
    if not ok.any():
        return None
    candidates = np.flatnonzero(ok)
    best = candidates[np.argmin(np.abs(n[candidates]).sum(axis=1))]
    return tuple(int(k) for k in n[best])


@dataclass
class Items:
    """oafm_eval.h's items of one kind (decay or frequency): the base powers' table, the chain rows, and the item
    of each rate."""

    zero: list[int]  # index of base j's power 0
    top: list[int]  # largest power of base j in the table
    bottom: list[int]  # largest negative power (decay only; 0 for frequencies: F^-n is a row with sign -1)
    n_table: int
    rows: list[tuple[int, int, int, int]]  # (parent, base, |power|, sign)
    index: dict  # rate -> item


def items(vectors: dict, n_bases: int, negative_table: bool) -> Items:
    """The items of the rates' integer vectors (combinations): each base's powers up to the largest used, then a
    row for every product of two or more bases (and, for frequencies, every negative power), built as
    item(n) = item(n without its last nonzero n_j) * base_j^n_j. Rows are ordered by depth: rows of one depth
    are independent, so the CPU overlaps their products."""
    n_bases = max(n_bases, 1)  # a base 0 (= 1) when there is none
    power = np.array([list(n)[:n_bases] for n in vectors.values()] or [[0] * n_bases], dtype=int).reshape(-1, n_bases)
    top = [max(0, int(power[:, j].max())) for j in range(n_bases)]
    bottom = [max(0, -int(power[:, j].min())) if negative_table else 0 for j in range(n_bases)]
    zero, start = [], 0
    for j in range(n_bases):
        zero.append(start + bottom[j])
        start += bottom[j] + top[j] + 1
    n_table, rows, depth, found = start, [], [], {}

    def item(n: tuple) -> int:
        nonzero = [j for j, k in enumerate(n) if k != 0]
        if not nonzero:
            return zero[0]
        if len(nonzero) == 1 and (n[nonzero[0]] > 0 or negative_table):
            return zero[nonzero[0]] + n[nonzero[0]]
        if n not in found:
            j = nonzero[-1]
            parent = item(tuple(0 if i == j else k for i, k in enumerate(n)))
            rows.append((parent, j, abs(n[j]), 1 if n[j] > 0 else -1))
            depth.append(len(nonzero))
            found[n] = n_table + len(rows) - 1
        return found[n]

    index = {value: item(tuple(n[:n_bases])) for value, n in vectors.items()}
    order = sorted(range(len(rows)), key=lambda r: (depth[r], r))
    moved = {n_table + old: n_table + new for new, old in enumerate(order)}
    rows = [(moved.get(rows[old][0], rows[old][0]), *rows[old][1:]) for old in order]
    return Items(zero, top, bottom, n_table, rows, {value: moved.get(i, i) for value, i in index.items()})


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
        self.struct = OeSolution(n_pieces=len(structs), pieces=self.array, cache=OeCache(piece=-1))

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
        decay_bases, freq_bases = decays[0] or [0.0], freqs[0] or [0.0]  # a base 0 (= 1) when there is none
        decay_items = items(decays[1], len(decay_bases), negative_table=True)
        freq_items = items(freqs[1], len(freq_bases), negative_table=False)
        if max(decay_items.n_table + len(decay_items.rows), freq_items.n_table + len(freq_items.rows)) > OE_ITEMS:
            self.reason = f"more than {OE_ITEMS} items"
            return None
        groups: dict[tuple[int, int], list[int]] = {}
        for k in range(len(sigma)):
            groups.setdefault((decay_items.index[float(sigma[k])], int(secular[k])), []).append(k)
        order = [k for key in groups for k in groups[key]]
        ends = np.cumsum([len(g) for g in groups.values()])
        c = coefficients[:, order]
        term_coefficient = np.stack([c[0].real, c[1].real, c[0].imag, c[1].imag, c[2].real, c[2].imag], axis=1)
        struct = OePiece(start=piece.start, n_decay_bases=len(decay_bases), n_freq_bases=len(freq_bases),
                         n_decay_table=decay_items.n_table, n_decay_rows=len(decay_items.rows),
                         n_freq_table=freq_items.n_table, n_freq_rows=len(freq_items.rows), n_groups=len(groups))
        for j, base in enumerate(decay_bases):
            struct.decay_base[j], struct.decay_top[j] = base, decay_items.top[j]
            struct.decay_bottom[j], struct.decay_zero[j] = decay_items.bottom[j], decay_items.zero[j]
        for j, base in enumerate(freq_bases):
            struct.freq_base[j], struct.freq_top[j], struct.freq_zero[j] = base, freq_items.top[j], freq_items.zero[j]
        struct.decay_chain = self._array(np.array(decay_items.rows, dtype=np.int64).ravel(), np.int64)
        struct.freq_chain = self._array(np.array(freq_items.rows, dtype=np.int64).ravel(), np.int64)
        struct.group_decay = self._array([key[0] for key in groups], np.int64)
        struct.group_secular = self._array([key[1] for key in groups], np.int64)
        struct.group_end = self._array(ends, np.int64)
        struct.term_freq = self._array([freq_items.index[float(nu[k])] for k in order], np.int64)
        struct.term_coefficient = self._array(term_coefficient.ravel(), float)
        self.pieces.append(piece)
        self.terms.append(dict(
            magnitude=np.abs(coefficients).max(axis=0), sigma=sigma, nu=nu, secular=secular,
            decay_n=np.array([decays[1][float(v)][:len(decays[0])] for v in sigma], dtype=float).reshape(len(sigma), -1),
            freq_n=np.array([freqs[1][float(v)][:len(freqs[0])] for v in nu], dtype=float).reshape(len(nu), -1),
            decay_bases=np.array(decays[0]), freq_bases=np.array(freqs[0])))
        return struct

    def error_bound(self, tau: float, stepped: bool = True) -> float:
        """A bound on |C - Python| of x, x' or x'' at tau (recurrence_error_bound): of vk_oafm_step (stepped) or
        vk_oafm_state."""
        starts = [p.start for p in self.pieces]
        i = max(0, int(np.searchsorted(starts, tau, side="right")) - 1)
        return recurrence_error_bound(self.terms[i], tau - starts[i], stepped)


def recurrence_error_bound(terms: dict, s: float, stepped: bool = True) -> float:
    """Bound on the difference between oafm_eval.c and oafm.Piece.evaluate at local time s, to first order in eps.

    Per term k with magnitude m_k = |c_k| e^(-sigma_k s) s^p_k (largest over x, x', x''), in units of eps:
      - C, the bases evaluated directly: the argument b_j s is rounded (|b_j s|) and cos, sin, exp err by <= 1 ulp:
        |b_j s| + 1 per base;
      - a base's phase or relative error is multiplied by |n_j| in its power n_j, and each of the |n_j| products
        of the powers and the products combining the bases adds 3, plus 3 for the coefficient, the decay and s;
      - C, the items stepped in time (vk_oafm_step, stepped=True): up to OE_RESYNC - 1 products with the term's items at
        the step h, W(h) and D(h), since the last direct evaluation, each adding 3 + 1 (the complex product W W(h),
        <= sqrt(5) eps: Brent, Percival & Zimmermann 2007, and the real product D D(h)) + the error of W(h) D(h)
        themselves, built like the items at s: 3 per power product (3 sum_j |n_j|) and, per base, |n_j| times
        (1 (the step's cos, sin, exp) + |b_j h| <= |b_j s| (its argument)) + the step mismatch the cache accepts,
        OE_STEP_SLACK ulps of s, which turns the phase of base j by OE_STEP_SLACK |b_j s| eps per step;
      - the combination differs from the rate by |sum n_j b_j - nu_k| (the rounding of the rates themselves):
        that times s;
      - Python: its argument s * rate is rounded (|nu_k s| + |sigma_k s|) and exp, cos, sin err by 1 ulp each (2);
    and both sums of K terms add at most (K - 1) eps sum_k m_k each (recursive summation, any order).
    """
    decay_n, freq_n = np.abs(terms["decay_n"]), np.abs(terms["freq_n"])
    db, fb = np.abs(terms["decay_bases"]), np.abs(terms["freq_bases"])
    sigma, nu = terms["sigma"], terms["nu"]
    magnitude = terms["magnitude"] * np.exp(-sigma * s) * np.where(terms["secular"], s, 1.0)

    def per_base(b):
        direct = b * s + 1.0
        if not stepped:
            return direct
        return direct + (OE_RESYNC - 1) * (1.0 + b * s * (1.0 + OE_STEP_SLACK))

    powers = decay_n.sum(axis=1) + freq_n.sum(axis=1)
    multiplications = 3.0 * (powers + 3.0)
    if stepped:  # the item products W W(h), D D(h) and the power products of W(h), D(h), once per step
        multiplications = multiplications + (OE_RESYNC - 1) * (4.0 + 3.0 * powers)
    bases = freq_n @ per_base(fb) + decay_n @ per_base(db)
    mismatch = (np.abs(terms["freq_n"] @ terms["freq_bases"] - nu)
                + np.abs(terms["decay_n"] @ terms["decay_bases"] - sigma)) * s / EPS
    python = np.abs(nu * s) + np.abs(sigma * s) + 2.0
    per_term = magnitude * (multiplications + bases + mismatch + python)
    return float(EPS * (per_term.sum() + 2.0 * (len(sigma) - 1) * magnitude.sum()))


def oafm_hints(scene):
    """(decay hints, frequency hints) of a scene: mu/2, q, sqrt(a1), omega, Omega (oafm_bases)."""
    a1 = coefficients(scene.alpha, scene.gamma, scene.R)[1]
    try:
        q = eq11_operator(scene).q
    except ValueError:
        q = 0.0
    return (0.5 * scene.mu,), (q, math.sqrt(a1) if a1 > 0 else 0.0, scene.omega, scene.Omega)


# ---------------------------------------------------------------- the plant

class CompiledOpenLoopPlant(PlantFastPath):
    """plant.Plant of an open-loop fidelity (3, 4) with doStep in C, on the level's evaluator (fidelities.Evaluator);
    built by make() from a plant.Plant that did the set-up. The FMU slave and its C fast path read and write it as
    a CompiledPlant (PlantFastPath: its VkPlant is the OlPlant's `plant`)."""

    STEP_FUNCTION = "vk_open_loop_do_step"  # vk_open_loop_do_step(OlPlant *, t, h)

    @property
    def _struct(self):
        return self._plant.plant

    @classmethod
    def make(cls, python_plant, library) -> tuple["CompiledOpenLoopPlant | None", str]:
        """(the compiled plant, what it runs on) or (None, why not)."""
        evaluator = entry(python_plant.settings.fidelity).evaluator
        if evaluator == Evaluator.NONE:
            return None, f"fidelity {python_plant.settings.fidelity} has no compiled evaluator"
        problem = declare(library)
        if problem is not None:
            return None, problem
        compiled = cls(python_plant, library)
        if compiled._problem is not None:
            return None, compiled._problem
        return compiled, f"C evaluator (fmu_src/core/{EVALUATOR_SOURCES[evaluator]})"

    def __init__(self, python_plant, library):
        self.python = python_plant
        self.scene, self.settings = python_plant.scene, python_plant.settings
        level = entry(self.settings.fidelity)
        self._evaluator = level.evaluator
        self.notes, self.warnings = python_plant.notes, python_plant.warnings
        self._library, self._problem = library, None
        self._plant = OlPlant()
        self.address = ctypes.addressof(self._plant)
        k = self._plant.plant  # the exact model's constants (its forces), the plant's time, input and outputs
        fill_model(k.model, python_plant.model)  # its forces
        k.time_tolerance, k.plant_t, k.U_input, k.enabled = TIME_TOLERANCE, python_plant.t, 0.0, 1
        self._plant.fidelity = int(self.settings.fidelity)  # C reads the level's evaluator (core/fidelity.h)
        if self._evaluator == Evaluator.SLOWFLOW:
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
        if self._library.vk_open_loop_state(self.address, tau, xva) == OL_BEYOND:  # outside the table: Python extends it
            state = self.python.solution.state(tau)  # (or raises for a time a bounded table has dropped)
            self._load_table()
            return state
        return tuple(xva)

    def state(self) -> tuple[float, float, float]:
        return self.state_at(self.t)

    def do_step(self, t: float, h: float, U: float) -> Outputs:
        """Plant.do_step in C; what C leaves (a bad step or input, a time beyond the table, a non-finite output)
        is done by the wrapped Plant, which raises its error or extends the table."""
        previous, self._plant.plant.U_input = self._plant.plant.U_input, U
        code = self._library.vk_open_loop_do_step(self.address, t, h)
        self._plant.plant.U_input = previous
        if code == 0:
            return self._outputs()
        if code == OL_REFUSED:
            check_step(self.t, t, h, U, math.inf, int(self.settings.fidelity))
        self.python.t = self.t
        out = self.python.do_step(t, h, U)  # raises, or extends the table and steps
        if self._evaluator == Evaluator.SLOWFLOW and self.python.solution.t_end != self._plant.slowflow.t_end:
            self._load_table()
        self._plant.plant.plant_t = self.python.t
        self._publish(out)
        return out

    def run(self, dt: float, n: int) -> np.ndarray:
        """x after each of n do_steps of dt in C (the compiled floor, no FMI); raises as do_step would."""
        x = np.empty(n)
        done, count = 0, ctypes.c_size_t()
        while done < n:
            code = self._library.vk_open_loop_run(self.address, dt, n - done, x[done:].ctypes.data_as(_dp), ctypes.byref(count))
            done += count.value
            if code == 0:
                break
            x[done] = self.do_step(self.t, dt, 0.0).x  # what C leaves: the Python plant raises or extends the table
            done += 1
        return x

    def advance(self, t_end: float, U: float = 0.0) -> tuple[float, float, float]:
        self._plant.plant.plant_t = t_end
        return self.state()

    def outputs(self) -> Outputs:
        self.python.t = self.t
        return self.python.outputs()

    def outputs_at(self, t: float, x: float, v: float, a: float | None = None) -> Outputs:
        return self.python.outputs_at(t, x, v, a)

    def snapshot(self) -> dict:
        """The wrapped Plant's snapshot, and with the OAFM evaluator its step cache (its bases at the last output
        decide the rounding of the next ones)."""
        self.python.t, self.python.U = self.t, 0.0
        snapshot = {"plant": self.python.snapshot()}
        if self._evaluator == Evaluator.OAFM:
            snapshot["oafm_cache"] = ctypes.string_at(ctypes.addressof(self._plant.oafm.cache),
                                                      ctypes.sizeof(OeCache)).hex()
        return snapshot

    def restore(self, snapshot: dict) -> None:
        """Return to the moment `snapshot` was taken; ValueError for anything but a snapshot of this kind of
        plant."""
        try:
            cache = bytes.fromhex(snapshot["oafm_cache"]) if "oafm_cache" in snapshot else b""
            plant_snapshot = snapshot["plant"]
        except (TypeError, ValueError, KeyError):
            raise ValueError("not a snapshot of a CompiledOpenLoopPlant") from None
        analytic = self._evaluator == Evaluator.OAFM
        if set(snapshot) != ({"plant", "oafm_cache"} if analytic else {"plant"}) or \
                (analytic and len(cache) != ctypes.sizeof(OeCache)):
            raise ValueError("not a snapshot of a CompiledOpenLoopPlant of this fidelity")
        self.python.restore(plant_snapshot)
        self._plant.plant.plant_t = self.python.t
        if analytic:
            restored = OeCache.from_buffer_copy(cache)
            values = [v for name in ("wre", "wim", "D", "rwre", "rwim", "rD") for v in getattr(restored, name)]
            sane = -1 <= restored.piece < self._plant.oafm.n_pieces and 0 <= restored.count <= OE_RESYNC and \
                all(map(math.isfinite, [restored.s, restored.rotation_h, restored.seen_h, *values]))
            self._plant.oafm.cache = restored if sane else OeCache(piece=-1)  # else: evaluate directly next
        else:
            self._load_table()

    def _outputs(self) -> Outputs:
        return Outputs(*self._plant.plant.out[:], bool(self._plant.plant.in_contact))

    def _publish(self, out: Outputs) -> None:
        k = self._plant.plant
        k.out[:] = [out.x, out.v, out.a, out.F_contact, out.F_electrostatic]
        k.in_contact = bool(out.in_contact)
