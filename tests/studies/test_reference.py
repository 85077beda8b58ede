"""The DOP853 reference is cross-checked against an implicit method (Radau)."""
import numpy as np
import pytest

from vibromodel.parameters import Scene
from vibrofmu.analyses.reference import reference_solution


@pytest.mark.long  # a Radau solve at tight tolerance
def test_dop853_reference_agrees_with_radau():
    # tau in [0, 100] (~16 periods, the transient and the steady state): scipy's Radau at rtol 1e-12 is the cost
    # (about 0.1 s of CPU per unit of tau; [0, 200] took ~19 s); measured difference 1.8e-13
    tau = np.linspace(0, 100, 1001)
    dop = reference_solution(Scene(), 0, 100.0)(tau)
    radau = reference_solution(Scene(), 0, 100.0, method="Radau", rtol=1e-12, atol=1e-14)(tau)
    # two independent methods, each with a global error of a small multiple of its rtol (1e-12) over tau = 100
    # (the bound was derived for twice that span): 1e-10 = 100 rtol bounds their difference; a wrong right-hand side
    # shows at O(1e-3)
    assert np.max(np.abs(dop[0] - radau[0])) <= 1e-10


def test_reference_stops_at_pull_in():
    reference = reference_solution(Scene(x_start=0.29, R=0.2), 0, 10.0)
    assert reference.stop_event is not None and "pull-in" in reference.stop_event
    assert reference.t_end < 10.0
