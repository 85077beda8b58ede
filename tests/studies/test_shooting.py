"""Shooting and continuation of periodic orbits (harness/vibrofmu/analyses/shooting.py): the ground truth of issue 4."""
import math

import numpy as np
import pytest

from vibromodel import forces
from vibromodel.averaging import equilibrium
from vibromodel.parameters import Scene
from vibrofmu.analyses import shooting as sh

STRONG = Scene(mu=0.002, Delta=0.0007)  # the strongly nonlinear scene of docs/model.md, Averaging and slow flow, issue 4
OMEGA_E = equilibrium(STRONG).omega_e  # sqrt(k1) of the averaged model (lead's averaging.py)

# docs/model.md, Averaging and slow flow at sigma = omega - omega_e = -0.0024: shooting column r, multipliers of the saddle.
ERRATA_SIGMA = -0.0024
ERRATA_R = (0.16638, 0.30329, 0.35092)
ERRATA_SADDLE_MULTIPLIERS = (0.98532, 1.00217)
ERRATA_KINDS = ("stable", "saddle", "stable")


def slow_flow_guess(model, omega, r, branch):
    """z0 of y = A cos + B sin on the slow-flow curve (docs/model.md, Averaging and slow flow) at amplitude ~r; branch -1: below
    the backbone (nu < 0), +1: above. Only a Newton starting point."""
    s = model.scene
    nu = branch * math.sqrt(s.Delta**2 / (4 * omega**2 * r**2) - s.mu**2 / 4)
    d = omega * (s.mu**2 + 4 * nu**2)
    return np.array([model.equilibrium()[0] - 2 * nu * s.Delta / d, omega * s.mu * s.Delta / d])


def errata_orbits(model):
    omega = OMEGA_E + ERRATA_SIGMA
    return [sh.shoot(model, omega, slow_flow_guess(model, omega, r, b)) for r, b in zip(ERRATA_R, (-1, -1, 1))]


# ----- stiffness functions ------------------------------------------------------------------------

# Central differences with h = 1e-5: truncation h^2/6 |f'''| <= 2e-10 |f'''| (|f'''| <= ~50 on these grids,
# away from the contact-loss singularity of H''), round-off eps |f| / h ~ 1e-11: tolerance 1e-8.
FD_H = 1e-5


def central(f, x):
    return (f(x + FD_H) - f(x - FD_H)) / (2 * FD_H)


@pytest.mark.parametrize("x", [-1.4, -0.7, -0.2, 0.0, 0.13, 0.35, 0.9])
def test_hertz_stiffness_is_the_derivative_of_hertz(x):
    assert forces.hertz_stiffness(x) == pytest.approx(central(forces.hertz, x), rel=1e-8, abs=1e-8)


def test_hertz_stiffness_is_continuous_and_zero_without_contact():
    assert forces.hertz_stiffness(-1.5 + 1e-12) == pytest.approx(0.0, abs=1e-6)  # sqrt(2e-12/3)
    assert forces.hertz_stiffness(-1.5) == forces.hertz_stiffness(-2.0) == 0.0


@pytest.mark.parametrize("R", [1.0, 0.7, 3.0])
@pytest.mark.parametrize("x", [-0.6, -0.1, 0.0, 0.2, 0.5])
@pytest.mark.parametrize("t", [0.0, 0.37, 2.1])
def test_electrostatic_stiffness_is_the_derivative_of_electrostatic(R, x, t):
    args = (0.003, 0.0004, 0.0007, 2.0, R)
    expected = central(lambda y: forces.electrostatic(t, y, *args), x)
    assert forces.electrostatic_stiffness(t, x, *args) == pytest.approx(expected, rel=1e-8, abs=1e-12)


@pytest.mark.parametrize("x", [-0.4, 0.0, 0.3])
def test_electrostatic_mean_is_the_ac_period_mean_and_its_stiffness_the_derivative(x):
    alpha, beta, gamma, Omega, R = 0.003, 0.0004, 0.0007, 2.0, 1.3
    # the drive is a trigonometric polynomial of degree 2 in Omega t: 16 equispaced samples average it exactly
    t = np.arange(16) * (2 * math.pi / Omega / 16)
    mean = np.mean([forces.electrostatic(ti, x, alpha, beta, gamma, Omega, R) for ti in t])
    assert forces.electrostatic_mean(x, alpha, gamma, R) == pytest.approx(mean, rel=1e-14, abs=1e-18)
    expected = central(lambda y: forces.electrostatic_mean(y, alpha, gamma, R), x)
    assert forces.electrostatic_mean_stiffness(x, alpha, gamma, R) == pytest.approx(expected, rel=1e-8)


# ----- variational equations ----------------------------------------------------------------------

# Central differences of the period map with eps = 1e-5: truncation eps^2/6 |P'''| ~ 2e-11 |P'''|; DOP853's
# error in P (~1e-13 absolute, not smooth in z because the adaptive steps change) divided by eps: ~1e-8.
# Tolerance 1e-7 relative to the largest entry (measured: 1e-10 for M, 9e-10 for P_omega).
FD_EPS = 1e-5


def fd_period_map(model, z, omega):
    def end(dz, dw):
        return sh.period_map(model, z + dz, omega + dw).end

    columns = [(end(FD_EPS * e, 0.0) - end(-FD_EPS * e, 0.0)) / (2 * FD_EPS) for e in np.eye(2)]
    return np.column_stack(columns), (end(0.0, FD_EPS) - end(0.0, -FD_EPS)) / (2 * FD_EPS)


@pytest.mark.parametrize("polynomial", [False, True])
def test_monodromy_and_omega_sensitivity_match_finite_differences(polynomial):
    model = sh.PeriodicModel(STRONG, polynomial=polynomial)
    z, omega = np.array([0.25, 0.1]), OMEGA_E - 0.002  # any state: P need not be periodic here
    pmap = sh.period_map(model, z, omega)
    fd_m, fd_w = fd_period_map(model, z, omega)
    np.testing.assert_allclose(pmap.monodromy, fd_m, atol=1e-7 * np.abs(fd_m).max())
    np.testing.assert_allclose(pmap.d_omega, fd_w, atol=1e-7 * np.abs(fd_w).max())


def test_contact_loss_is_crossed_by_restarts_and_the_monodromy_stays_right():
    """mu = 0.1, Delta = 1: the orbit leaves the contact (x < -1.5) twice per period; H is C^1 there, so
    M needs no jump. Electrodes far away (R = 20), no electrostatics. FD tolerance as above, 1e-7 (measured
    3e-10); a missing jump (saltation) term at the crossings would be O(1)."""
    model = sh.PeriodicModel(Scene(mu=0.1, Delta=1.0, alpha=0.0, beta=0.0, gamma=0.0, R=20.0))
    omega = 0.5
    orbit = sh.shoot(model, omega, sh.linear_guess(model, omega))
    assert orbit.contact_crossings == 2 and orbit.x_min < -1.5 < orbit.x_max
    assert orbit.liouville_error < 1e-9
    fd_m, _ = fd_period_map(model, orbit.z0, omega)
    np.testing.assert_allclose(orbit.monodromy, fd_m, atol=1e-7 * np.abs(fd_m).max())


def test_pull_in_stops_the_period_map():
    """Paper scene (R = 1) with Delta = 1: x reaches the lower electrode gap 1 + 2x/3 = PULL_IN_GAP."""
    with pytest.raises(sh.ShootingError, match="pull-in"):
        sh.period_map(sh.PeriodicModel(Scene(mu=0.1, Delta=1.0)), [0.0, 0.0], 0.9)


# ----- Floquet data -------------------------------------------------------------------------------

def test_liouville_identity_on_the_errata_orbits():
    """det M = exp(-mu T) exactly (tr J = -mu). M's entries carry DOP853's error ~ a few rtol = 1e-11
    relative over a period; 1e-9 leaves a factor 100 (measured: <= 1e-12)."""
    for orbit in errata_orbits(sh.PeriodicModel(STRONG)):
        assert orbit.liouville_error < 1e-9
        assert orbit.residual <= sh.NEWTON_TOL


@pytest.mark.parametrize("omega", [0.6, 0.9, 0.99, 1.0, 1.05, 1.4])
def test_small_forcing_gives_the_linear_response(omega):
    """Delta = 1e-4, alpha = beta = gamma = 0, mu = 0.1: x_e = 0, k1 = H'(0) = 1.

    The neglected nonlinearity shifts the stiffness by 2 omega kappa2 r^2 (Lindstedt backbone, ERRATA
    §3.4(c), kappa2 = (9 k1 k3 - 10 k2^2)/(24 k1^1.5) = -1/54 with k2 = 1/6, k3 = -1/54), so
    |r/r_lin - 1| ~ 2 omega |kappa2| r^2 / |k1 - omega^2 + i mu omega| (the relative change of
    1/|k1 - omega^2 + i mu omega|), <= 4e-7 at resonance; this is a leading-order estimate, so twice it
    is allowed (measured: up to 0.96 of it at omega = 0.9). Newton's residual moves the state by
    <= residual / sigma_min(M - I), and DOP853's absolute error ~1e-13 on r >= 1e-4 adds 1e-9.
    """
    model = sh.PeriodicModel(Scene(mu=0.1, Delta=1e-4, alpha=0.0, beta=0.0, gamma=0.0))
    x_e, k1 = model.equilibrium()
    assert x_e == 0.0 and k1 == forces.hertz_stiffness(x_e) == 1.0
    denominator = abs(complex(k1 - omega**2, model.scene.mu * omega))
    r_lin = model.scene.Delta / denominator
    orbit = sh.shoot(model, omega, sh.linear_guess(model, omega))
    nonlinear = 2 * omega * (1 / 54) * r_lin**2 / denominator
    newton = orbit.residual / np.linalg.svd(orbit.monodromy - np.eye(2), compute_uv=False).min() / r_lin
    assert orbit.r == pytest.approx(r_lin, rel=2 * nonlinear + newton + 1e-9)
    assert orbit.kind == "stable"


def test_errata_table_is_the_polynomial_model_to_the_printed_digits():
    """docs/model.md, Averaging and slow flow shooting column, reproduced with g = sum a_k x^k (Eq. 7, corrected a_k, AC averaged):
    the table's numbers come from that degree-5 model. Tolerance: half a unit of the 5th decimal (5e-6)
    plus the Newton error (1e-10 / sigma_min(M - I) ~ 1e-10 / 2e-3 = 5e-8)."""
    orbits = errata_orbits(sh.PeriodicModel(STRONG, polynomial=True))
    assert [o.r for o in orbits] == pytest.approx(ERRATA_R, abs=6e-6)
    assert [o.kind for o in orbits] == list(ERRATA_KINDS)
    assert sorted(orbits[1].multipliers.real) == pytest.approx(ERRATA_SADDLE_MULTIPLIERS, abs=6e-6)
    assert np.all(orbits[1].multipliers.imag == 0.0)


def test_errata_table_with_the_exact_forces():
    """Eq. 3's forces instead of their degree-5 series move the backbone by delta_omega <= |g - g5|(r)/(2r)
    ~ 6e-4 r^5 / 2 = 7e-7 at r = 0.3 (first neglected term of G1, docs/model.md, Series and polynomial model). The middle branch has
    |dr/domega| ~ 220 there (measured by shooting at omega + 1e-5), so r moves by up to 1.6e-4 (measured 8e-5);
    the outer branches and the multipliers (|drho/domega| ~ 2) far less. Tolerances: 2e-4 on r, 1e-5 on
    the multipliers (rounding 5e-6 + 1.4e-6)."""
    orbits = errata_orbits(sh.PeriodicModel(STRONG))
    assert [o.r for o in orbits] == pytest.approx(ERRATA_R, abs=2e-4)
    assert [o.kind for o in orbits] == list(ERRATA_KINDS)
    assert sorted(orbits[1].multipliers.real) == pytest.approx(ERRATA_SADDLE_MULTIPLIERS, abs=1e-5)
    for orbit in orbits:  # x_max, x_min bracket the first harmonic about the mean
        assert orbit.x_min < orbit.mean - 0.9 * orbit.r < orbit.mean + 0.9 * orbit.r < orbit.x_max


# ----- continuation -------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def strong_branch():
    """sigma in [-0.004, 0]: unique small response at the left end, through both folds."""
    return sh.frequency_response(sh.PeriodicModel(STRONG), OMEGA_E - 0.004, OMEGA_E)


@pytest.mark.long  # a continuation along the strong branch (the module fixture)
def test_continuation_finds_two_folds_where_a_multiplier_crosses_one(strong_branch):
    """Both fold frequencies are located twice by Brent (tangent omega-component, multiplier = 1, on the
    same arclength bracket, xtol 1e-12 relative): they agree to ~1e-12. Independently, the sampled branch
    must change stability (stable <-> saddle) exactly between the two points that bracket each fold."""
    fr = strong_branch
    assert len(fr.folds) == 2
    for fold in fr.folds:
        assert fold.omega == pytest.approx(fold.omega_multiplier, abs=1e-10)
        assert np.min(np.abs(fold.orbit.multipliers - 1.0)) < 1e-6
    # docs/model.md, Averaging and slow flow: three orbits at sigma = -0.0024, so the folds bracket it
    sigma_folds = sorted(f.omega - OMEGA_E for f in fr.folds)
    assert sigma_folds[0] < ERRATA_SIGMA < sigma_folds[1]
    changes = np.flatnonzero(fr.stable[1:] != fr.stable[:-1])
    assert len(changes) == 2
    for i, fold in zip(changes, fr.folds):
        assert fold.omega == pytest.approx(fr.omega[i], abs=abs(fr.omega[i + 1] - fr.omega[i]) + 1e-5)
    assert not np.any(fr.stable[changes[0] + 1: changes[1] + 1])
    assert {fr.kind[i] for i in range(changes[0] + 1, changes[1] + 1)} == {"saddle"}


@pytest.mark.long  # a continuation along the strong branch (the module fixture)
def test_continuation_branch_is_consistent(strong_branch):
    """Ends in the unique-response range: stable; omega passes hi; Liouville on every point (<= 1e-9)."""
    fr = strong_branch
    assert fr.stable[0] and fr.stable[-1] and fr.omega[-1] >= OMEGA_E
    assert fr.liouville_error.max() < 1e-9
    assert np.all(fr.x_max > fr.x_min)


@pytest.mark.long  # a continuation along the strong branch (the module fixture)
def test_peak_amplitude_of_errata(strong_branch):
    """docs/model.md, Averaging and slow flow peak-amplitude table: shooting r = 0.3387 at sigma = -0.002 (upper branch, past both
    folds). The orbit there is shot from the nearest branch point; tolerance: rounding 5e-5 + truncation
    (upper branch, < 2e-5 as above)."""
    fr = strong_branch
    omega = OMEGA_E - 0.002
    upper = np.arange(len(fr.omega)) > np.flatnonzero(fr.stable[1:] != fr.stable[:-1])[-1]
    nearest = np.flatnonzero(upper)[np.argmin(np.abs(fr.omega[upper] - omega))]
    orbit = sh.shoot(sh.PeriodicModel(STRONG), omega, fr.orbits[nearest].z0)
    assert orbit.r == pytest.approx(0.3387, abs=7e-5)


def test_progress_callback_sees_every_point():
    seen = []
    fr = sh.frequency_response(sh.PeriodicModel(STRONG), OMEGA_E - 0.02, OMEGA_E - 0.019,
                               progress=lambda i, orbit: seen.append((i, orbit.omega)))
    assert [i for i, _ in seen] == list(range(1, len(fr.omega)))
    assert [w for _, w in seen] == list(fr.omega[1:])


@pytest.mark.slow
def test_full_resonance_sweep():
    """sigma in [-0.01, 0.01] with ~200 points: unique stable response at both ends, two folds."""
    fr = sh.frequency_response(sh.PeriodicModel(STRONG), OMEGA_E - 0.01, OMEGA_E + 0.01, max_step=0.008)
    assert len(fr.omega) >= 200 and len(fr.folds) == 2
    assert fr.liouville_error.max() < 1e-9
    assert fr.stable[0] and fr.stable[-1]


# ----- the compiled period map (fmu_src/core/periodmap.c) against scipy's --------------------------------------

# Both integrate the same system with DOP853 at rtol 1e-11 (shooting.RTOL): each differs from the exact flow by a
# small multiple of rtol times the size of what is integrated, and from each other by no more. Measured: <= 6e-13 in
# P, 1.2e-10 relative in M and d_param (the contact-loss orbits, M up to ~1e3); the bounds leave a factor 10.
COMPILED_P_TOL, COMPILED_M_REL = 1e-11, 1e-9


@pytest.mark.parametrize("scene, z, periods, param", [
    (Scene(mu=0.05, Delta=0.1, R=3.0, beta=0.0, gamma=0.0, omega=0.9), [0.3, 0.1], 1, "omega"),
    (Scene(mu=0.05, Delta=0.5, R=2.0, beta=0.0, gamma=0.0, omega=0.8), [-1.0, -2.0], 1, "Delta"),  # 4 crossings
    (Scene(mu=0.05, Delta=0.5, R=2.0, beta=0.0, gamma=0.0, omega=0.8), [1.0, 0.0], 2, "mu"),  # 2 crossings
    (Scene(), [0.0, 0.0], 1, "gamma"),
    (Scene(), [0.1, 0.0], 1, "alpha"),
])
def test_the_compiled_period_map_is_scipys(scene, z, periods, param):
    function, why = sh.compiled_period_map()
    assert function is not None, why
    model = sh.PeriodicModel(scene)
    python = sh.period_map(model, z, scene.omega, param=param, periods=periods)
    compiled = sh.period_map(model, z, scene.omega, param=param, periods=periods, dense=False)
    assert compiled.segments == [] and python.segments  # the compiled one was used
    assert compiled.crossings == python.crossings
    np.testing.assert_allclose(compiled.end, python.end, rtol=0, atol=COMPILED_P_TOL)
    for a, b in ((compiled.monodromy, python.monodromy), (compiled.d_param, python.d_param)):
        np.testing.assert_allclose(a, b, rtol=0, atol=COMPILED_M_REL * np.abs(b).max())
    # the extremes: x at v = 0, located on each integrator's own dense output (root finding to ~1e-15 in s)
    assert compiled.x_min == pytest.approx(python.x_min, abs=COMPILED_P_TOL)
    assert compiled.x_max == pytest.approx(python.x_max, abs=COMPILED_P_TOL)


def test_the_compiled_period_map_stops_at_pull_in():
    with pytest.raises(sh.ShootingError, match="pull-in"):
        sh.period_map(sh.PeriodicModel(Scene(mu=0.1, Delta=1.0)), [0.0, 0.0], 0.9, dense=False)
