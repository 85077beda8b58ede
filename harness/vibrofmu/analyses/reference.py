"""High-accuracy reference: scipy's solve_ivp on the same vibromodel right-hand side.

Contact and free-flight phases are integrated separately: each phase ends at the zero of the
indentation 1 + 2x/3 (a kink of the contact force) and the next one restarts there, so no step of
the reference straddles the kink. Pull-in ends the reference.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

from vibromodel.fidelities import make_model
from vibromodel.forces import contact_indentation
from vibromodel.parameters import Scene

REFERENCE_RTOL, REFERENCE_ATOL = 1e-12, 1e-14


@dataclass
class Reference:
    phases: list = field(default_factory=list)  # (t_start, t_end, OdeSolution, in_contact)
    stop_event: str | None = None
    nfev: int = 0

    @property
    def t_end(self) -> float:
        return self.phases[-1][1]

    def __call__(self, t) -> np.ndarray:
        """(x, v) at the times t (array, inside [0, t_end]); shape (2, len(t))."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.full((2, t.size), np.nan)
        for t0, t1, solution, _ in self.phases:
            inside = (t >= t0) & (t <= t1)
            if inside.any():
                out[:, inside] = solution(t[inside])
        return out

    @property
    def contact_changes(self) -> list[float]:
        return [p[0] for p in self.phases[1:]]


def reference_solution(scene: Scene, fidelity: int, t_end: float, method: str = "DOP853",
                       rtol: float = REFERENCE_RTOL, atol: float = REFERENCE_ATOL, U: float = 0.0) -> Reference:
    model = make_model(scene, fidelity)
    accel = model.accel

    def rhs(t, y):
        return [y[1], accel(t, y[0], y[1], U)]

    terminal = [e for e in model.events if e.terminal]
    has_contact = any(not e.terminal for e in model.events)
    reference = Reference()
    t, y = 0.0, np.array([scene.x_start, scene.v_start])
    in_contact = contact_indentation(y[0]) > 0.0
    while t < t_end:
        events = [_event(e.g, direction=0) for e in terminal]
        if has_contact:  # leaving the contact: indentation falls through 0; re-contact: it rises
            events.append(_event(contact_indentation, direction=-1.0 if in_contact else 1.0))
        sol = solve_ivp(rhs, (t, t_end), y, method=method, rtol=rtol, atol=atol, dense_output=True,
                        events=events)
        reference.nfev += sol.nfev
        if sol.status < 0:
            raise RuntimeError(f"reference integration failed at tau = {sol.t[-1]}: {sol.message}")
        reference.phases.append((t, float(sol.t[-1]), sol.sol, in_contact))
        t, y = float(sol.t[-1]), sol.y[:, -1]
        if sol.status == 0:
            break
        hit = [i for i, te in enumerate(sol.t_events) if te.size]
        if any(i < len(terminal) for i in hit):
            reference.stop_event = terminal[hit[0]].name
            break
        in_contact = not in_contact
    return reference


def _event(g, direction):
    def event(t, y):
        return g(y[0])

    event.terminal = True
    event.direction = direction
    return event
