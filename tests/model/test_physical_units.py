"""Physical units (docs/model.md, Scaling): the dimensional Eq. 1 + 2, integrated in SI units, matches
z = z_s (1 + 2x/3), t = tau/omega0 of the dimensionless run."""
import math

import numpy as np
from scipy.integrate import solve_ivp

from vibromodel.parameters import PhysicalParameters, consistency_warning
from vibrofmu.analyses.reference import reference_solution

EPS0 = 8.8541878128e-12


def physical_example():
    m, k, N = 0.01, 1e7, 10.0  # z_s = (N/k)^(2/3) = 1e-4 m
    z_s = (N / k) ** (2 / 3)
    omega0 = math.sqrt(1.5 * k / m * math.sqrt(z_s))
    return PhysicalParameters(m=m, c=0.1 * m * omega0, k=k, N=N, Delta=0.0007, C0=EPS0 * 1e-4, d=2 * z_s,
                              V_bias=475.0, V_AC=60.0, nu1=0.9987 * omega0, nu2=2.0 * omega0)


def test_mapping_formulas():
    p = physical_example()
    scene = p.to_scene(z_start=p.z_s * (1 + 2 * 0.04 / 3), zdot_start=0.0)
    # each mapped quantity is a few powers, products and square roots (each rounding by <= 1.1e-16 relative):
    # rel_tol 1e-12 allows ~10^4 roundings, so it catches a wrong exponent or factor, never rounding
    assert math.isclose(p.z_s, 1e-4, rel_tol=1e-12)
    assert math.isclose(p.omega0**2, 1.5 * p.k / p.m * p.z_s**0.5, rel_tol=1e-12)  # corrected Eq. (4): z_s^(1/2)
    assert math.isclose(scene.mu, 0.1, rel_tol=1e-12)
    assert math.isclose(scene.R, 1.0, rel_tol=1e-12)
    assert math.isclose(scene.x_start, 0.04, rel_tol=1e-12)
    assert math.isclose(scene.alpha, p.C0 * 475.0**2 / (2 * p.k * p.z_s**3.5), rel_tol=1e-12)
    # a physical voltage pair always satisfies beta^2 = 8 alpha gamma; the paper's example does not
    assert math.isclose(scene.beta**2, 8 * scene.alpha * scene.gamma, rel_tol=1e-12)
    assert consistency_warning(scene) is None


def test_dimensional_equation_matches_the_dimensionless_run():
    p = physical_example()
    z0, zdot0 = p.z_s * (1 + 2 * 0.04 / 3), 0.002
    scene = p.to_scene(z_start=z0, zdot_start=zdot0)
    tau_end = 100.0
    reference = reference_solution(scene, 0, tau_end)
    t_end = p.t_of_tau(tau_end)
    # SI integration of Eq. 1 + 2; atol far below 1e-8 of z ~ 1e-4 m and of zdot ~ z_s omega0 A
    sol = solve_ivp(lambda t, y: [y[1], p.accel_eq1(t, y[0], y[1])], (0, t_end), [z0, zdot0],
                    method="DOP853", rtol=1e-12, atol=[1e-20, 1e-17], dense_output=True)
    tau = np.linspace(0, tau_end, 2001)
    z_dimensional = sol.sol(p.t_of_tau(tau))[0]
    z_from_x = p.z_of_x(reference(tau)[0])
    assert np.max(np.abs(z_dimensional - z_from_x) / np.abs(z_from_x)) <= 1e-8
