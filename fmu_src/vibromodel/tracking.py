"""Reference trajectories x~(t) for the tracking controller, each with x~' and x~'' in closed form.

- OAFM: the analytic solution of the scene from the reference's own initial state (plant fidelity 4).
- ERRATA (the corrected paper reference): x~ = x0 (Eq. 15) + X_f cos(w t - psi), the §3.5 simulation's reference: x0 solves L[x0] = gamma,
  L = x'' + mu x' + a1 x (Eq. 11), and X_f cos(w t - psi) is L's steady response to Delta cos w t.
- MULTITONE: the corrected reference plus extra tones sum A_k cos(nu_k t): a persistently exciting reference.

All are `AnalyticSolution`s (sums of damped harmonics), so state(t) gives (x~, x~', x~'').

Persistent excitation (acceptance 4, tests/model/test_parameter_estimates.py): `regressor_gram` measures it along a reference,
G = (1/T) int phi phi^T dt with x1 = x~, x2 = x~'; `excitation_gains` are the adaptation gains lambda_i = G_ii
(i = 3..11) that make every direction adapt at a comparable rate; `on_reference` starts the plant on x~.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from .analytic import OafmSettings, cached_solve, covering
import numpy as np

from .closedform import Terms
from .control import Gains, Regressor
from .oafm import AnalyticSolution, Piece
from .oafm_bases import eq11_operator
from .parameters import ParameterError, Scene

# G is averaged over [GRAM_START, GRAM_START + GRAM_SPAN] (after the free part of x0 has decayed) every GRAM_STEP.
GRAM_START, GRAM_SPAN, GRAM_STEP = 50.0, 2000.0, 0.05

# Persistent excitation (tests/fmus/test_closed_loop.py, README): tones incommensurate with each other and with
# omega, Omega, 2 Omega, large enough that x1^4 and x1^5 are not negligible.
MULTITONE_TONES = ((0.2, 0.37), (0.15, 1.53), (0.1, 2.71))  # (amplitude, frequency)


class ReferenceKind(IntEnum):
    OAFM = 0
    ERRATA = 1
    MULTITONE = 2


@dataclass(frozen=True)
class ReferenceSettings:
    kind: int = ReferenceKind.ERRATA
    x_start: float = 0.04  # x~(0) of the free part (docs/model.md, Adaptive controller: A = 0.04)
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


def reference_terms(scene: Scene, settings: ReferenceSettings) -> Terms:
    """x~ of the closed-form references (ERRATA = the corrected paper reference, MULTITONE) as Terms."""
    settings.validate()
    if settings.kind == ReferenceKind.OAFM:
        raise ParameterError("reference", settings.kind, "the OAFM reference is not a closed form")
    terms = errata_terms(scene, settings.x_start, settings.v_start)
    return terms + multitone_terms() if settings.kind == ReferenceKind.MULTITONE else terms


def regressor_gram(scene: Scene, settings: ReferenceSettings, start: float = GRAM_START, span: float = GRAM_SPAN,
                   step: float = GRAM_STEP) -> np.ndarray:
    """G = (1/T) int phi(x~, x~', t) phi^T dt over [start, start + span]: the level of persistent excitation."""
    terms = reference_terms(scene, settings)
    t = np.arange(start, start + span, step)
    phi = Regressor(scene)
    rows = np.array([phi(ti, xi, vi) for ti, xi, vi in zip(t, terms(t), terms.derivative()(t))])
    return rows.T @ rows / len(t)


def excitation_gains(scene: Scene, settings: ReferenceSettings, lambda1: float = 4.0, lambda2: float = 1.0,
                     scale: float = 1.0):
    """Gains (lambda1, lambda2, lambda3..11 = G_ii/scale): lambda2 Lambda^-1 G then has unit diagonal
    (times scale), so every direction adapts at a comparable rate; any lambda_i > 0 keeps V' <= 0."""
    G = regressor_gram(scene, settings)
    return Gains(lambdas=(lambda1, lambda2) + tuple(float(g) / scale for g in np.diag(G)))


def on_reference(scene: Scene, settings: ReferenceSettings) -> Scene:
    """The scene with the plant starting on the reference: x(0) = x~(0), x'(0) = x~'(0)."""
    terms = reference_terms(scene, settings)
    return scene.with_values(x_start=float(terms(0.0)), v_start=float(terms.derivative()(0.0)))
