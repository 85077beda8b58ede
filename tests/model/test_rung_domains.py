"""Every rung answers inside its domain or refuses (issue 25): the polynomial fidelities stop at pull-in like the
exact one; the averaged (3) and analytic (4) rungs check their own validity at set-up."""
import math

import pytest

from vibrofmu.fmus import kernel
from vibromodel.integrate import TerminalEvent
from vibromodel.models import tolerance_factor
from vibromodel.parameters import PULL_IN_GAP, ParameterError, Scene
from vibromodel.plant import Kernel, Settings, make_plant

PULL_IN_WORDS = "pull-in: {side} gap 1 {sign} 2x/(3R) below 0.001 at tau = "


@pytest.fixture(scope="module")
def library():
    return kernel.kernel_library(), "the test's kernel"


def run_to_stop(plant, h=0.1, n=500):
    """Steps of h until an exception; returns (the largest |x| returned, the exception)."""
    largest = 0.0
    for i in range(n):
        try:
            largest = max(largest, abs(plant.do_step(i * h, h, 0.0).x))
        except TerminalEvent as stop:
            return largest, stop
    return largest, None


@pytest.mark.parametrize("kernel_kind", [Kernel.COMPILED, Kernel.PYTHON])
@pytest.mark.parametrize("fidelity", [1, 2])
@pytest.mark.parametrize("scene, side, sign", [(Scene(Delta=0.3), "lower", "+"), (Scene(beta=3.0), "upper", "-"),
                                               (Scene(v_start=-3.0), "lower", "+")])
def test_polynomial_fidelities_stop_at_pull_in_like_the_exact_one(library, kernel_kind, fidelity, scene, side, sign):
    """Fidelities 1 and 2 used to run past the electrodes (|x| up to 34.6 with fmi2OK). They now stop at the exact
    model's pull-in events: the same words, the stop on the gap PULL_IN_GAP, every returned |x| below 3R/2."""
    settings = Settings(fidelity=fidelity, kernel=kernel_kind)
    largest, stop = run_to_stop(make_plant(scene, settings, 0.0, 50.0, library=library))
    _, exact_stop = run_to_stop(make_plant(scene, Settings(kernel=kernel_kind), 0.0, 50.0, library=library))
    assert stop is not None and exact_stop is not None
    assert str(stop).startswith(PULL_IN_WORDS.format(side=side, sign=sign))
    assert str(exact_stop).startswith(PULL_IN_WORDS.format(side=side, sign=sign))
    # the event is located on the dense output to brentq's xtol 1e-15 in tau; x there is within rtol-sized
    # rounding of the gap's x, (1 - PULL_IN_GAP) 3R/2: 1e-6 relative is far above both and far below the gap (1e-3)
    assert abs(stop.x) == pytest.approx((1.0 - PULL_IN_GAP) * 1.5 * scene.R, rel=1e-6)
    assert largest < 1.5 * scene.R


def test_polynomial_pull_in_is_the_same_in_python_and_c(library):
    """The C kernel's message names the same gap as Python's event (its events are indexed differently)."""
    stops = [run_to_stop(make_plant(Scene(Delta=0.3), Settings(fidelity=1, kernel=k), 0.0, 50.0, library=library))[1]
             for k in (Kernel.COMPILED, Kernel.PYTHON)]
    assert str(stops[0]) == str(stops[1]) and math.isfinite(stops[0].t)


# ---- fidelity 3: the averaging's own domain (averaging.validity_estimates, checked_averaged, slowflow) ----------

def averaged_plant(**values):
    return make_plant(Scene(**values), Settings(fidelity=3, kernel=Kernel.PYTHON), 0.0, 50.0)


@pytest.mark.parametrize("name", ["alpha", "gamma", "beta"])
def test_fidelity_3_without_a_stable_equilibrium_names_the_parameter(name):
    """alpha or gamma >= 3 used to raise TypeError('must be real number, not complex'), naming nothing."""
    with pytest.raises(ParameterError) as refusal:
        averaged_plant(**{name: 3.0})
    assert refusal.value.name == name and refusal.value.value == 3.0
    assert "stable static equilibrium" in refusal.value.reason and "use fidelity 0" in refusal.value.reason


def test_fidelity_3_refuses_a_vibration_that_leaves_the_contact_where_fidelity_0_pulls_in(library):
    """Delta = 0.3 returned x(50) = -1.663 with fmi2OK; fidelity 0 stops at pull-in there."""
    with pytest.raises(ParameterError) as refusal:
        averaged_plant(Delta=0.3)
    assert refusal.value.name == "Delta" and "leaves the contact" in refusal.value.reason
    _, stop = run_to_stop(make_plant(Scene(Delta=0.3), Settings(), 0.0, 50.0, library=library))
    assert stop is not None  # the independent evidence: the exact model does not survive this scene either


def assert_refused_before_work(monkeypatch, module, function, what, make, name):
    """make() raises ParameterError naming `name` (and pointing to fidelity 0) before module.function (the slow
    work) is called: the function is replaced by one that fails the test, saying `what` happened."""
    def forbidden(*args, **kwargs):
        raise AssertionError(f"{what} before the refusal")

    monkeypatch.setattr(module, function, forbidden)
    with pytest.raises(ParameterError) as refusal:
        make()
    assert refusal.value.name == name and "use fidelity 0" in refusal.value.reason


@pytest.mark.parametrize("values, name", [({"omega": 1000.0}, "omega"), ({"omega": 2.0}, "omega"),
                                          ({"beta": 0.3}, "beta")])
def test_fidelity_3_refuses_outside_its_small_parameters_before_any_integration(monkeypatch, values, name):
    """omega = 1000 took 47 s to initialise; omega = 2 erred by 117 % of the amplitude; beta = 0.3 pumps the
    resonance (Mathieu growth > 0) to pull-in. Refused before the slow flow is integrated (solve_ivp must not run)."""
    import scipy.integrate
    assert_refused_before_work(monkeypatch, scipy.integrate, "solve_ivp", "the slow flow was integrated",
                               lambda: averaged_plant(**values), name)


def test_mathieu_growth_separates_the_scenes_fidelity_0_survives_from_those_it_pulls_in(library):
    """The refusal rule's evidence: beta = 0.1 (growth < 0) runs to tau = 50 at fidelity 0, beta = 0.3 (> 0) pulls in."""
    from vibromodel.averaging import averaged, parametric_growth
    for beta, grows in ((0.1, False), (0.3, True)):
        scene = Scene(beta=beta)
        growth = {name: rate for name, rate, _ in parametric_growth(scene, averaged(scene).omega_e)}
        _, stop = run_to_stop(make_plant(scene, Settings(), 0.0, 50.0, library=library))
        assert (growth["beta"] > 0.0) == grows == (stop is not None) and growth["gamma"] < 0.0


@pytest.mark.parametrize("values, words", [({"omega": 1.2}, "detuning"), ({"beta": 0.1}, "parametric pumping"),
                                           ({"mu": 1.0}, "mu/(2 omega_e)"), ({"Delta": 0.15}, "of the way")])
def test_fidelity_3_warns_with_its_estimate_where_it_is_approximate(values, words):
    """The rule's warning first; the error estimate's (error_estimates.warning) may follow it, never replace it."""
    plant = averaged_plant(**values)
    assert words in plant.warnings[0] and "use fidelity 0" in plant.warnings[0]
    assert all("error estimate" in warning for warning in plant.warnings[1:]) and len(plant.warnings) <= 2


def test_fidelity_3_on_the_paper_scene_has_no_warning():
    assert averaged_plant().warnings == []


@pytest.mark.parametrize("omega, rtol", [(1.3, 1e-8), (3.0, 1e-8), (3.0, 1e-6), (2.0, 1e-10)])
def test_predicted_spacing_bounds_the_table_spacing_from_below(omega, rtol):
    """The cost check's prediction (slowflow.predicted_spacing) against the refinement it predicts: the spacing
    chosen is never finer (else a table the check let through could cost more than MAX_TABLE_CELLS)."""
    from vibromodel.averaging import averaged
    from vibromodel.slowflow import SlowFlowSolution, predicted_spacing
    model = averaged(Scene(omega=omega))
    solution = SlowFlowSolution(model, 0.0, 0.04, 0.0, rtol, t_end=50.0, bounded=True)
    rate = abs(solution.flow.detuning) + 0.5 * model.scene.mu  # kappa(r) ~ 1e-5 at r = 0.04: inside the margin
    assert solution.spacing >= predicted_spacing(rate, rtol)


# ---- fidelity 4: the OAFM's domain (analytic.check_linear_domain, check_fit, MAX_AUTOMATIC_FIT_SPAN) ---------

def analytic_plant(stop=50.0, **values):
    return make_plant(Scene(**values), Settings(fidelity=4, kernel=Kernel.PYTHON), 0.0, stop)


@pytest.mark.parametrize("values, name", [({"Delta": 0.3}, "Delta"), ({"Delta": 1.0}, "Delta"),
                                          ({"Delta": 3.0}, "Delta"), ({"beta": 3.0}, "beta"), ({"mu": 0.01}, "mu")])
def test_fidelity_4_refuses_before_the_fit(monkeypatch, values, name):
    """Delta = 0.3, 1, 3 and beta = 3 took 258-301 s and returned x = 1.379 (fidelity 0: 0.347) or |x| = 4.38 beyond
    the electrode; mu = 0.01 fitted tau = 1031 for 6-8 s. Refused before least_squares runs."""
    import scipy.optimize
    assert_refused_before_work(monkeypatch, scipy.optimize, "least_squares", "the OAFM fit ran",
                               lambda: analytic_plant(**values), name)


def test_fidelity_4_linear_prediction_is_what_fidelity_0_does_at_small_amplitude(library):
    """The pre-check's evidence: at Delta = 0.01 (linear regime) x0 of Eq. 11 matches fidelity 0 within 5 % of the
    amplitude (the contact's quadratic term is ~x^2/6 ~ 1.5 % at x = 0.09), so its domain test is the exact model's."""
    import numpy as np
    from vibromodel.oafm import Piece
    from vibromodel.oafm_bases import eq11_operator, forced_x0
    scene = Scene(Delta=0.01)
    x0 = Piece(0.0, 50.0, "x0", (), forced_x0(eq11_operator(scene), scene, 0.0, scene.x_start, 0.0)[0].merged())
    plant = make_plant(scene, Settings(), 0.0, 50.0, library=library)
    exact = np.array([plant.do_step(0.1 * i, 0.1, 0.0).x for i in range(500)])
    linear = x0.evaluate(0.1 * np.arange(1, 501))[:, 0]
    assert np.max(np.abs(linear - exact)) <= 0.05 * np.max(np.abs(exact))


# ---- the step size respects the drive (models.drive_step_ceiling) ----------------------------------------------

def test_the_native_ceiling_constant_is_the_models():
    from pathlib import Path
    from vibromodel.models import DRIVE_STEP_TURN
    header = (Path(__file__).parents[2] / "fmu_src" / "native" / "plant_setup.h").read_text()
    assert f"#define NATIVE_DRIVE_STEP_TURN {DRIVE_STEP_TURN!r}" in header


def test_the_drive_ceiling_brings_a_lightly_damped_driven_run_within_its_tolerance(library):
    """Omega = 9.3 (beta on), mu = 0.02, a resonant load, rtol 1e-3 over tau = 1000: without the ceiling (max_step =
    1000, the rule's top) the error against a tight reference (rtol 1e-12, steps of 0.5/(2 Omega)) exceeds 1
    rtol max|x|; with max_step = 0 (the ceiling) it is within 1 rtol max|x|. Measured: 1.89 and 1.5e-5 (the ceiling's
    4 rad; 2.3e-7 at its former 2.25 rad); 6.9 without the ceiling under the I step controller that DOP853 had before
    its PI controller (integrate.PI_BETA: its step after a low error reading overshot into rejections, and the accepted
    errors sat higher).
    mu = 0.02 >= 2/150 keeps the solver at the rtol asked (models.tolerance_factor = 1): at mu = 0.002 the factor
    0.15 alone brings the run without the ceiling from 22 to 2.1, which would hide what the ceiling does (the
    factor's own test is test_the_tolerance_factor_brings_long_lightly_damped_runs_within_their_bound)."""
    import numpy as np
    scene = Scene(Omega=9.3, mu=0.02, Delta=0.015, beta=0.001)
    assert tolerance_factor(scene, 1000.0) == 1.0

    def run(rtol, max_step, stop=1000.0):
        plant = make_plant(scene, Settings(rtol=rtol, max_step=max_step), 0.0, stop, library=library)
        return np.array([plant.do_step(float(i), 1.0, 0.0).x for i in range(int(stop))])

    reference = run(1e-12, 0.5 / (2 * 9.3))
    scale = 1e-3 * np.max(np.abs(reference))
    assert np.max(np.abs(run(1e-3, 1000.0) - reference)) > scale
    assert np.max(np.abs(run(1e-3, 0.0) - reference)) < scale
