"""The exact cusp beside the slow flow's, and the order of their difference in the averaging's small parameter
(harness/vibrofmu/analyses/cusp_order.py; docs/continuation.md)."""
import numpy as np
import pytest
from numpy.polynomial import polynomial as P

from vibromodel import averaging as av
from vibrofmu.analyses import cusp_order as co

from test_curves import FOLD_SYSTEM_TOL, independent_map


@pytest.mark.parametrize("eps", [1.0, 0.25, 0.03125])
def test_the_slow_flow_cusp_is_a_triple_root_of_the_response_polynomial(eps):
    """At the closed-form cusp (omega_c, Delta_c, r_c) the averaging's own response polynomial F(s) (s = r^2,
    averaging.response_polynomial) has a triple root at s_c: F, s F', s^2 F'' vanish beside s^3 F''' (~6 d^2).
    Rounding: the coefficients are sums of terms ~ d^2 and the derivatives cancel them to ~1e-16 relative, amplified
    by the powers of s (measured 3e-13 d^2); 1e-10 d^2 leaves a margin of 300."""
    scene = co.scene_of(eps)
    cusp = co.slow_flow_cusp(scene)
    flow = av.averaged(scene.with_values(Delta=cusp["Delta"])).flow(cusp["omega"])
    p, s = av.response_polynomial(flow), cusp["r"] ** 2
    scaled = [P.polyval(s, P.polyder(p, k)) * s**k / flow.drive**2 for k in range(4)]
    assert max(abs(x) for x in scaled[:3]) <= 1e-10
    assert abs(scaled[3]) > 1.0  # a triple root, not a quadruple one: the cusp is non-degenerate


@pytest.fixture(scope="module")
def small_eps():
    return co.study(epsilons=(0.125, 0.0625, 0.03125))


@pytest.mark.long
def test_the_cusp_error_has_the_averagings_order(small_eps):
    """Fitted over eps = 1/8 .. 1/32 the orders are the derived 5 (Delta) and 4 (omega). Tolerances: the next term
    is relative O(eps^2) with a coefficient ~ 1/0.3^2 (the Delta error changes sign near eps = 0.3), which biases
    the local order at eps = 1/8 by log2((1 + c/64) / (1 + c/256)) ~ 0.2 and less below: 0.3 for Delta; the omega
    error has no sign change, its correction is smaller (measured local orders 3.94 .. 4.00): 0.1."""
    orders = small_eps["orders"]
    assert abs(orders["Delta"]["order"] - 5) <= 0.3
    assert abs(orders["omega"]["order"] - 4) <= 0.1
    for row in small_eps["rows"]:
        # the exact cusp's own error (two tolerances apart 10x) far below the averaging's error being measured
        assert abs(row["exact_Delta"] - row["check_Delta"]) <= 0.05 * abs(row["error_Delta"])
        assert abs(row["exact_omega"] - row["check_omega"]) <= 0.05 * abs(row["error_omega"])
        # the cusp is located as Delta's extremum and, independently, by the quadratic coefficient's sign change:
        # both agree to the looser location's tolerance (the curve's own, 1e-10 in the fold system)
        assert row["sign_change_Delta"] == pytest.approx(row["exact_Delta"], rel=1e-4)


@pytest.mark.slow
def test_the_located_cusp_solves_an_independent_fold_system(small_eps):
    """The cusp at eps = 1/8 on the fold curve: Radau's P(z) = z, det(M - I) = 0 (test_curves.independent_map)."""
    row = small_eps["rows"][0]
    scene = co.scene_of(row["eps"]).with_values(omega=row["exact_omega"], Delta=row["exact_Delta"])
    result = co.exact_cusp(co.scene_of(row["eps"]))["tight"]
    assert (result["omega"], result["Delta"]) == (row["exact_omega"], row["exact_Delta"])
    z0 = np.array(result["z0"])
    end, M = independent_map(scene, z0)
    assert np.max(np.abs(end - z0)) <= FOLD_SYSTEM_TOL
    assert abs(np.linalg.det(M - np.eye(2))) <= FOLD_SYSTEM_TOL
