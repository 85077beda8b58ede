"""Reference trajectories x~(t) for the tracking controller, each with x~' and x~'' in closed form.

- OAFM: the analytic solution of the scene from the reference's own initial state (plant fidelity 4).
- ERRATA: x~ = x0 (Eq. 15) + X_f cos(w t - psi), the §3.5 simulation's reference: x0 solves L[x0] = gamma,
  L = x'' + mu x' + a1 x (Eq. 11), and X_f cos(w t - psi) is L's steady response to Delta cos w t.
- MULTITONE: ERRATA's reference plus extra tones sum A_k cos(nu_k t): a persistently exciting reference.

All are `AnalyticSolution`s (sums of damped harmonics), so state(t) gives (x~, x~', x~'').
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from .analytic import OafmSettings, cached_solve, covering
from .closedform import Terms
from .oafm import AnalyticSolution, Piece
from .oafm_bases import eq11_operator
from .parameters import ParameterError, Scene

# Persistent excitation (tests/test_closed_loop.py, README): tones incommensurate with each other and with
# omega, Omega, 2 Omega, large enough that x1^4 and x1^5 are not negligible.
MULTITONE_TONES = ((0.2, 0.37), (0.15, 1.53), (0.1, 2.71))  # (amplitude, frequency)


class ReferenceKind(IntEnum):
    OAFM = 0
    ERRATA = 1
    MULTITONE = 2


@dataclass(frozen=True)
class ReferenceSettings:
    kind: int = ReferenceKind.ERRATA
    x_start: float = 0.04  # x~(0) of the free part (ERRATA §3.5: A = 0.04)
    v_start: float = 0.0

    def validate(self) -> None:
        if self.kind not in set(ReferenceKind):
            raise ParameterError("reference", self.kind, f"must be one of {[int(k) for k in ReferenceKind]}")


def errata_terms(scene: Scene, x_start: float, v_start: float) -> Terms:
    """x0 of Eq. 15 (x0(0) = x_start, x0'(0) = v_start) + X_f cos(w t - psi) = Re[Delta e^(i w t)/(a1 - w^2 + i mu w)]."""
    L = eq11_operator(scene)
    x_static = scene.gamma / L.k
    response = scene.Delta / complex(L.k - scene.omega**2, scene.mu * scene.omega)
    return (Terms.of([(0, 0.0, 0.0, x_static, 0.0), (0, 0.0, scene.omega, response.real, -response.imag)])
            + L.free(x_start - x_static, v_start))


def multitone_terms(tones=MULTITONE_TONES) -> Terms:
    return Terms.of([(0, 0.0, nu, amplitude, 0.0) for amplitude, nu in tones])


def _closed_form(terms: Terms, t0: float, name: str) -> AnalyticSolution:
    return AnalyticSolution([Piece(start=t0, end=float("inf"), basis_name=name, C=(), x=terms.merged())])


def make_reference(scene: Scene, settings: ReferenceSettings, t0: float = 0.0, stop_time: float | None = None,
                   cache_dirs: tuple = ()) -> tuple[AnalyticSolution, str]:
    """(reference, a note saying what it is) for a scene; the OAFM fit covers [t0, stop_time]."""
    settings.validate()
    kind = ReferenceKind(settings.kind)
    if kind is ReferenceKind.OAFM:
        ref_scene = scene.with_values(x_start=settings.x_start, v_start=settings.v_start)
        oafm = covering(ref_scene, OafmSettings(), None if stop_time is None else stop_time - t0)
        solution, source = cached_solve(ref_scene, oafm, t0, read_dirs=cache_dirs)
        return solution, f"reference: OAFM analytic solution ({source})"
    terms = errata_terms(scene, settings.x_start, settings.v_start)
    if kind is ReferenceKind.MULTITONE:
        terms = terms + multitone_terms()
    return _closed_form(terms, t0, kind.name.lower()), f"reference: {kind.name.lower()} closed form"
