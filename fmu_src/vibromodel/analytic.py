"""The OAFM analytic solution of a scene (fidelity 4): settings, tau* rule, the two-domain solve, cache.

Domain 1 is [t0, t0 + tau*] (the decaying free vibration dominates), domain 2 is [t0 + tau*, t0 + tau_end]
(the forced vibration dominates); x~ and x~' are continuous at tau*. The last piece is also used
beyond tau_end: its terms are periodic or decaying, so it extrapolates the steady vibration.
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .models import ExactModel
from .oafm import AnalyticSolution, Grid, Piece, continue_from, fit_domain
from .oafm_bases import FAMILIES, eq11_operator, forced_x0
from .parameters import PULL_IN_GAP, ParameterError, Scene, validate

# The cache key holds the source of every module the fit depends on: an edit there retires old entries.
FIT_SOURCES = ("analytic.py", "closedform.py", "oafm.py", "oafm_bases.py", "models.py", "forces.py", "parameters.py")
FREE_DECAY_SPAN = 20.0  # tau_end - tau* = FREE_DECAY_SPAN / mu: the free vibration decays by e^-10 ...
MAX_STEADY_SPAN = 1000.0  # ... but at most this long (light damping: the fit would grow without bound)
FORCED_FLOOR = 1e-3  # without forcing, tau* is where the free vibration has decayed to this fraction
# The fit's memory and time grow with its span (grid points x unknowns: ~60 kB and ~2 ms per unit of tau on the
# paper example; 1e4 took 19 s and 635 MB, 1e6 more than 20 GB): a longer span is refused up front. Beyond the fit
# the last piece extrapolates the steady vibration (see the module docstring), so a long run sets oafm_tau_end.
MAX_FIT_SPAN = 2000.0
# Set-up time bounded (issue 25): an automatic span (oafm_tau_end = 0) longer than this is refused up front in the
# FMU, before any fit: a fresh fit cost 2-4 ms per unit of tau here (the paper example: 235 in 0.48 s, to stop time
# 500 in 1.16 s; mu = 0.04: 545 in 0.91 s; mu = 0.05, x_start = 0.1: 448 in 1.9 s), so 600 is ~1.2-2.4 s. Light
# damping (mu = 0.01: tau* + 1000) took 6-8 s. An explicit oafm_tau_end up to MAX_FIT_SPAN is the user's choice.
MAX_AUTOMATIC_FIT_SPAN = 600.0
# A forcing frequency whose term turns by less than this many cycles over the fit cannot be told from a constant
# by the fit's basis (harmonics nu and nu + omega become collinear): refused (omega or Omega = 5e-324 made the
# fit's residual NaN and the least-squares loop run for minutes).
MIN_TURNS = 1e-3
# The domain of fidelity 4 (issue 25: at Delta = 0.3, 1, 3 or beta = 3 the fit ran 258-301 s, then returned
# x = 1.379 where fidelity 0 gives 0.347, or |x| up to 4.38 beyond the electrode, with fmi2OK).
# (1) Before the fit: the linear prediction x0 (Eq. 11 driven by the linear forcing of Eq. 7, the OAFM's own initial
#     approximation over the whole experiment) must stay inside the contact (1 + 2x/3 > 0: x > -3/2) and short of
#     pull-in (|x| < (1 - PULL_IN_GAP) 3R/2): the OAFM expands about the linearized contact, and a vibration that the
#     linear model already carries out of the contact or onto an electrode is not a correction of it.
# (2) The fit: at most MAX_FIT_EVALUATIONS evaluations of the residual per domain (the paper example needs 11-15;
#     the 258 s fits above ran thousands); a fit that does not converge within them is refused.
# (3) After the fit: x~ on the fit's span must stay in the same domain, and its error is estimated from the residual
#     R = x~'' - accel of Eq. 3, propagated through Eq. 11's linear operator (error_estimates.analytic_estimate,
#     calibrated against fidelity 0). The estimate above FIT_WARN of the run's amplitude (0.01 %) is logged as
#     fmi2Warning, above FIT_REFUSE (or not finite) refused: both say to use fidelity 0 (error_estimates.attach, the
#     registry's warn_share and refuse_share).
MAX_FIT_EVALUATIONS = 60
FIT_WARN = 1e-4
FIT_REFUSE = 0.1
DOMAIN_SAMPLES_PER_PERIOD = 40  # samples of x0 and x~ per period of the fastest term (the checks above) ...
MAX_DOMAIN_SAMPLES = 20_000  # ... at most (omega = 1000 over tau = 267: 1.7e6 samples took a minute; a forcing that
# fast moves x by Delta/omega^2, which the samples of the slower terms bound)


@dataclass(frozen=True)
class OafmSettings:
    basis: str = "harmonic"
    order: int = 3  # harmonic family: highest combination order (ignored by `paper`)
    tau_star: float = 0.0  # length of domain 1; 0 = automatic
    tau_end: float = 0.0  # end of the steady domain's fit, from t0; 0 = automatic
    grid: Grid = field(default_factory=Grid)

    def validate(self) -> None:
        if self.basis not in FAMILIES:
            raise ParameterError("basis", self.basis, f"known bases: {', '.join(FAMILIES)}")
        if not 1 <= self.order <= 8:
            raise ParameterError("oafm_order", self.order, "must be 1..8")
        for name, fmu_name in (("tau_star", "tau_star"), ("tau_end", "oafm_tau_end")):  # named as in the FMU
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ParameterError(fmu_name, value, "must be a finite number >= 0 (0 = automatic)")
        if self.tau_end and self.tau_star and self.tau_end <= self.tau_star:
            raise ParameterError("oafm_tau_end", self.tau_end, f"must exceed tau_star = {self.tau_star:g}")
        if not (self.grid.panel > 0 and self.grid.nodes >= 2):
            raise ParameterError("grid", self.grid, "panel must be > 0 and nodes >= 2")


def automatic_tau_star(scene: Scene) -> float:
    """Where the envelope of the free vibration, |free(0)| e^(-mu tau/2), falls to the forced amplitude.

    Both from L of Eq. 11: the forced amplitude Delta/|a1 - w^2 + i mu w|, the free amplitude from the
    initial state minus the forced particular solution. At least one free period 2 pi/q.
    """
    _require_damping(scene, "tau_star")
    L = eq11_operator(scene)
    free = forced_x0(L, scene, 0.0, scene.x_start, scene.v_start)[0].merged()
    homogeneous = (free.sigma == 0.5 * scene.mu) & (free.nu == L.q)
    free_amplitude = math.hypot(float(free.a[homogeneous].sum()), float(free.b[homogeneous].sum()))
    forced_amplitude = scene.Delta / abs(complex(L.k - scene.omega**2, scene.mu * scene.omega))
    ratio = free_amplitude / max(forced_amplitude, FORCED_FLOOR * free_amplitude, 1e-300)
    return max(2.0 * math.log(max(ratio, 1.0)) / scene.mu, 2.0 * math.pi / L.q)


def _require_damping(scene: Scene, name: str) -> None:
    if not scene.mu > 0.0:
        raise ParameterError(name, 0.0, f"automatic {name} needs damping mu > 0 (mu = {scene.mu:g}); give it")


def covering(scene: Scene, settings: OafmSettings, span: float | None, strict: bool = False) -> OafmSettings:
    """Settings whose fit reaches at least `span` past the start (an FMU's stop time): no extrapolation
    inside the experiment. Explicit tau_star / tau_end are kept; automatic ones are resolved to numbers.
    A span beyond MAX_FIT_SPAN: strict (the plant at fidelity 4) raises ParameterError (stopTime); otherwise (a
    reference) the fit stops at MAX_FIT_SPAN and the steady piece extrapolates beyond it. Strict also refuses an
    automatic span beyond MAX_AUTOMATIC_FIT_SPAN (set-up time), naming stopTime, tau_star or mu."""
    if settings.tau_end:
        return settings
    tau_star, tau_end = domains(scene, settings)
    if span is not None and span > max(tau_end, MAX_FIT_SPAN):
        if not strict:
            return dataclasses.replace(settings, tau_star=tau_star, tau_end=max(tau_end, MAX_FIT_SPAN))
        raise ParameterError("stopTime", span, f"fidelity 4 fits its solution over the whole experiment, at most "
                             f"tau = {MAX_FIT_SPAN:g} past the start (memory and set-up time grow with it); set "
                             f"oafm_tau_end <= {MAX_FIT_SPAN:g} to fit that far and extrapolate the steady vibration "
                             "beyond it, or use fidelity 0-3")
    if strict and max(tau_end, span or 0.0) > MAX_AUTOMATIC_FIT_SPAN:
        cause = (("stopTime", span) if span is not None and span > tau_end else
                 ("tau_star", settings.tau_star) if settings.tau_star else ("mu", scene.mu))
        raise ParameterError(*cause, f"fidelity 4's automatic fit would span tau = {max(tau_end, span or 0.0):.6g} "
                             f"(tau* = {tau_star:.6g}, then the free vibration's decay, 20/mu at most "
                             f"{MAX_STEADY_SPAN:g}, or the stop time), more than {MAX_AUTOMATIC_FIT_SPAN:g}: its set-up "
                             f"would take more than ~2 s (2-4 ms per unit of tau); set oafm_tau_end (<= "
                             f"{MAX_FIT_SPAN:g}) to choose the span, beyond which the steady piece extrapolates, or use "
                             "fidelity 0")
    return dataclasses.replace(settings, tau_star=tau_star, tau_end=max(tau_end, span or 0.0))


def check_affordable(scene: Scene, tau_end: float) -> None:
    """Raise ParameterError unless a fit to tau_end (from the start) is within MAX_FIT_SPAN and resolves the
    forcing frequencies of the scene (MIN_TURNS cycles over the fit)."""
    if tau_end > MAX_FIT_SPAN:
        raise ParameterError("oafm_tau_end", tau_end, f"the OAFM fit covers at most tau = {MAX_FIT_SPAN:g} (memory "
                             "and set-up time grow with it); beyond the fit the solution extrapolates its steady piece")
    for name, value, used in (("omega", scene.omega, scene.Delta != 0.0),
                              ("Omega", scene.Omega, scene.beta != 0.0 or scene.gamma != 0.0)):
        if used and value * tau_end < 2.0 * math.pi * MIN_TURNS:
            raise ParameterError(name, value, f"fidelity 4 needs its forcing to turn by at least {MIN_TURNS:g} cycles "
                                 f"over the fit (tau = {tau_end:g}): {name} >= {2 * math.pi * MIN_TURNS / tau_end:.3g}")


def domains(scene: Scene, settings: OafmSettings) -> tuple[float, float]:
    """(tau*, tau_end) measured from the start time, automatic where the settings say 0."""
    tau_star = settings.tau_star or automatic_tau_star(scene)
    if settings.tau_end:
        tau_end = settings.tau_end
    else:
        _require_damping(scene, "oafm_tau_end")
        tau_end = tau_star + min(FREE_DECAY_SPAN / scene.mu, MAX_STEADY_SPAN)
    if tau_end <= tau_star:
        raise ParameterError("oafm_tau_end", tau_end, f"must exceed tau* = {tau_star:g}")
    return tau_star, tau_end


def solve(scene: Scene, settings: OafmSettings = OafmSettings(), t0: float = 0.0) -> AnalyticSolution:
    """Fit both domains: the optimal C_i of each, joined with x, x' continuous at tau*."""
    validate(scene)
    settings.validate()
    accel = ExactModel(scene).accel
    return _chain(scene, settings, t0, lambda i, basis, start, end: fit_domain(accel, basis, start, end, settings.grid,
                                                                               MAX_FIT_EVALUATIONS))


def assemble(scene: Scene, settings: OafmSettings, t0: float, C: list, residual_max: list | None = None,
             converged: list | None = None) -> AnalyticSolution:
    """The solution from known C_i (a cache entry) without fitting: same bases, same closed forms; the fit's
    largest residual and convergence per piece where the entry has them (check_fit reads them)."""
    return _chain(scene, settings, t0, lambda i, basis, start, end: Piece(
        start=start, end=end, basis_name=basis.name, C=tuple(C[i]), x=basis.solution(C[i]),
        residual_max=math.nan if residual_max is None else float(residual_max[i]),
        fit={} if converged is None else {"converged": bool(converged[i])}))


def _chain(scene: Scene, settings: OafmSettings, t0: float, make_piece) -> AnalyticSolution:
    """Domain after domain, each starting from the previous one's x~, x~' at its end."""
    tau_star, tau_end = domains(scene, settings)
    check_affordable(scene, tau_end)
    check_linear_domain(scene, t0, tau_end)
    pieces, x, v, start = [], scene.x_start, scene.v_start, t0
    for i, (make_basis, end) in enumerate(zip(FAMILIES[settings.basis], (t0 + tau_star, t0 + tau_end))):
        basis = make_basis(scene, start, x, v, settings.order)
        pieces.append(make_piece(i, basis, start, end))
        x, v = continue_from(pieces[-1], end)
        start = end
    return AnalyticSolution(pieces)


def _samples(scene: Scene, t0: float, tau_end: float) -> np.ndarray:
    """Times on [t0, t0 + tau_end], DOMAIN_SAMPLES_PER_PERIOD per period of the fastest of q, omega, 2 Omega."""
    fastest = max(1.0, abs(scene.omega) if scene.Delta else 0.0, 2.0 * abs(scene.Omega) if scene.gamma or scene.beta
                  else 0.0)
    n = int(min(MAX_DOMAIN_SAMPLES, math.ceil(tau_end * fastest * DOMAIN_SAMPLES_PER_PERIOD / (2.0 * math.pi)))) + 1
    return t0 + np.linspace(0.0, tau_end, n)


def _outside(scene: Scene, x: np.ndarray) -> int | None:
    """The first index where x leaves fidelity 4's domain (contact x > -3/2, pull-in |x| < (1 - gap) 3R/2)."""
    electrode = (1.0 - PULL_IN_GAP) * 1.5 * scene.R
    bad = np.flatnonzero(~((x > -1.5) & (np.abs(x) < electrode)))
    return int(bad[0]) if bad.size else None


def _domain_words(scene: Scene, x: float) -> str:
    return "leaves the contact (1 + 2x/3 > 0: x > -3/2)" if not x > -1.5 else \
        f"reaches pull-in (|x| < (1 - {PULL_IN_GAP:g}) 3R/2 = {(1.0 - PULL_IN_GAP) * 1.5 * scene.R:.6g})"


def _dominant_drive(scene: Scene) -> str:
    """The parameter behind the largest linear amplitude (Eq. 11's gain at each forcing, the free vibration)."""
    L = eq11_operator(scene)

    def gain(w):
        return 1.0 / abs(complex(L.k - w * w, scene.mu * w))

    amplitudes = {"Delta": abs(scene.Delta) * gain(scene.omega), "beta": abs(scene.beta) * gain(scene.Omega),
                  "gamma": abs(scene.gamma) * gain(2.0 * scene.Omega),
                  "x_start": abs(scene.x_start), "v_start": abs(scene.v_start) / L.q}
    return max(amplitudes, key=amplitudes.get)


def check_linear_domain(scene: Scene, t0: float, tau_end: float) -> None:
    """ParameterError before any fit when the linear prediction leaves fidelity 4's domain (comment at
    MAX_FIT_EVALUATIONS, (1))."""
    L = eq11_operator(scene)
    x0 = Piece(start=t0, end=t0 + tau_end, basis_name="x0", C=(),
               x=forced_x0(L, scene, t0, scene.x_start, scene.v_start)[0].merged())
    tau = _samples(scene, t0, tau_end)
    x = x0.evaluate(tau - t0)[:, 0]
    i = _outside(scene, x)
    if i is not None:
        name = _dominant_drive(scene)
        raise ParameterError(name, getattr(scene, name), f"fidelity 4's linear prediction (Eq. 11, the OAFM's initial "
                             f"approximation) {_domain_words(scene, float(x[i]))} at tau = {tau[i]:.6g} (x = "
                             f"{x[i]:.4g}): outside the domain of the OAFM, which expands about the linearized contact; "
                             "refused before the fit; use fidelity 0")


def check_fit(scene: Scene, solution: AnalyticSolution, t0: float) -> list[str]:
    """The fitted solution's domain (comment at MAX_FIT_EVALUATIONS, (2) and (3)): raises ParameterError outside the
    domain or for an unconverged fit; returns [] (its warnings: the error estimate's are the plant's,
    error_estimates.attach by FIT_WARN and FIT_REFUSE)."""
    name = _dominant_drive(scene)
    for piece in solution.pieces:
        if piece.fit.get("converged") is False:
            raise ParameterError(name, getattr(scene, name), f"fidelity 4's OAFM fit on [{piece.start:.6g}, "
                                 f"{piece.end:.6g}] did not converge in {MAX_FIT_EVALUATIONS} evaluations (residual "
                                 f"rms {piece.residual_rms:.3g}): outside its domain; use fidelity 0")
    tau = _samples(scene, t0, solution.tau_end - t0)
    x = solution(tau)[0]
    i = _outside(scene, x)
    if i is not None:
        raise ParameterError(name, getattr(scene, name), f"fidelity 4's fitted solution {_domain_words(scene, float(x[i]))} "
                             f"at tau = {tau[i]:.6g} (x = {x[i]:.4g}): outside the domain of the OAFM; use fidelity 0")
    return []  # the error: the plant's estimate (error_estimates.analytic_plant_estimate) warns and refuses


# ---------------------------------------------------------------- cache keyed by the parameters

@functools.cache
def _source_digest() -> str:
    here = Path(__file__).parent
    return hashlib.sha256(b"".join((here / name).read_bytes() for name in FIT_SOURCES)).hexdigest()


def cache_key(scene: Scene, settings: OafmSettings, t0: float) -> str:
    text = json.dumps({"code": _source_digest(), "scene": asdict(scene), "settings": asdict(settings), "t0": t0},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def user_cache_dir() -> Path:
    """$VIBROFMU_CACHE_DIR, else $XDG_CACHE_HOME/vibrofmu/oafm, else ~/.cache/vibrofmu/oafm."""
    if os.environ.get("VIBROFMU_CACHE_DIR"):
        return Path(os.environ["VIBROFMU_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "vibrofmu" / "oafm"


def cached_solve(scene: Scene, settings: OafmSettings, t0: float = 0.0, read_dirs: tuple[Path, ...] = (),
                 write_dir: Path | None = None) -> tuple[AnalyticSolution, str]:
    """The solution from the first cache that has it (read_dirs, then write_dir), else solve and store it in
    write_dir (default: the user cache; a failed write is not an error). Returns (solution, its source)."""
    name = cache_key(scene, settings, t0) + ".json"
    write_dir = Path(write_dir) if write_dir is not None else user_cache_dir()
    for directory in (*read_dirs, write_dir):
        path = Path(directory) / name
        if path.is_file():
            try:
                entry = json.loads(path.read_text())
                return assemble(scene, settings, t0, entry["C"], entry["residual_max"], entry["converged"]), str(path)
            except (OSError, ValueError, KeyError, TypeError):
                continue  # unreadable entry: fall through to the next cache or a fresh fit
    solution = solve(scene, settings, t0)
    write_cache_entry(write_dir / name, solution)
    return solution, "fitted"


def write_cache_entry(path: Path, solution: AnalyticSolution) -> None:
    """Write atomically (temporary file, then rename); a cache that cannot be written is skipped."""
    entry = {"C": [list(p.C) for p in solution.pieces],
             "residual_rms": [p.residual_rms for p in solution.pieces],
             "residual_max": [p.residual_max for p in solution.pieces],
             "converged": [p.fit.get("converged", True) for p in solution.pieces]}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(entry))
        tmp.replace(path)
    except OSError:
        pass
