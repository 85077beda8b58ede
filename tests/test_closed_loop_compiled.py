"""The closed loop on the compiled kernel (fmu_src/core/closedloop.c) against vibromodel.closedloop."""
import ctypes

import numpy as np
import pytest

from vibrofmu.kernel import kernel_library
from vibromodel.closedloop import ERRATA_SCENE
from vibromodel.compiled_loop import CompiledReference, declare
from vibromodel.tracking import ReferenceKind, ReferenceSettings, make_reference

EPS = np.finfo(float).eps


@pytest.mark.parametrize("kind", list(ReferenceKind))
def test_reference_evaluation_matches_the_analytic_solution(kind):
    """vl_reference_state against oafm.AnalyticSolution.state on [-1, 250] (before the first piece, across pieces,
    beyond the fit). The two differ in rounding only: each term Re[c e^((-sigma + i nu) s) s^m] takes a few
    roundings (exp, cos/sin, products: <= 8 eps of |c| |z|) and the sums over K terms differ in order (<= K eps of
    the sum of |terms|); so |difference| <= (K + 8) eps sum_k |c_k| |z_k| per component."""
    library = kernel_library()
    assert declare(library) is None
    evaluate = library.vl_reference_state
    solution, _ = make_reference(ERRATA_SCENE, ReferenceSettings(kind=kind), 0.0, 200.0)
    reference = CompiledReference(solution)
    out = (ctypes.c_double * 3)()
    for tau in np.linspace(-1.0, 250.0, 1001):
        evaluate(ctypes.addressof(reference.structure), tau, out)
        piece = solution.pieces[int(solution._index(tau))]
        s = tau - piece.start
        z = np.abs(np.exp(s * piece._rates)) * np.where(piece._secular, abs(s), 1.0)
        bound = (len(z) + 8) * EPS * (np.abs(piece._coefficients) @ z)
        assert np.all(np.abs(np.array(out[:]) - np.array(solution.state(tau))) <= bound), tau
