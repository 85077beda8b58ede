"""Numerical stability at the extremes (issue 6): each extreme of vibrofmu.analyses.extremes as a test of its row's
outcome, plus the pieces it rests on (rtol clamp, RK4's response to a fast drive, RK4's pull-in location).

The two long runs have a quick default version and the issue's full length under @pytest.mark.slow:
- energy: tau = 1e3 (1 s of plant runs, 5 s with SciPy's RK45 at rtol 1e-12) with the issue's bound scaled to
  1e-10 because the drift grows linearly with tau; tau = 1e4 takes about a minute (RK45 alone 45 s).
- memory: tau = 1e4 at interval 0.1 (6 s), the same 1e5 doSteps as the full tau = 1e5 at interval 1 (15 s), so a
  leak per doStep is caught by either; the full run also takes 10 times the integrator steps.
"""
import math
import re

import pytest

from vibrofmu.analyses import extremes as ex
from vibrofmu.hosts.run import run_fmu
from vibromodel.integrate import RK4_DRIVE_ERROR, RK4_DRIVE_THETA, IntegrationError, Rk4, TerminalEvent, rk4_drive_gains
from vibromodel.models import Event
from vibromodel.parameters import MIN_RTOL, ParameterError, Scene, clamp_tolerance, validate
from vibromodel.plant import Plant, Settings, Solver, checked_settings


# -- rtol below MIN_RTOL: clamped with a warning ---------------------------------------------------------------

def test_rtol_below_the_floor_is_clamped_with_a_warning():
    rtol, warning = clamp_tolerance(1e-15)
    assert rtol == MIN_RTOL
    assert "rtol = 1e-15" in warning and f"using rtol = {MIN_RTOL:.3g}" in warning
    assert clamp_tolerance(MIN_RTOL) == (MIN_RTOL, None)  # the floor itself is no clamp
    assert clamp_tolerance(1e-8) == (1e-8, None)
    assert clamp_tolerance(5e-324)[0] == MIN_RTOL  # the smallest subnormal too


@pytest.mark.parametrize("bad", [0.0, -0.0, -1e-6, math.nan, math.inf, -math.inf])
def test_rtol_that_is_not_a_positive_number_stays_an_error(bad):
    with pytest.raises(ParameterError, match="parameter rtol"):
        clamp_tolerance(bad)


def test_plant_runs_at_the_clamped_tolerance_and_keeps_the_warning():
    plant = Plant(Scene(), Settings(rtol=1e-15))
    assert plant.settings.rtol == MIN_RTOL and plant.integrator.rtol == MIN_RTOL
    assert len(plant.warnings) == 1 and "using rtol" in plant.warnings[0]
    assert Plant(Scene(), Settings()).warnings == []
    # the warnings are rebuilt by the constructor, not part of the snapshot (the FMU state keeps its shape)
    assert "warnings" not in plant.snapshot()["plant"]


# -- RK4 and a fast drive: the criterion and its warning ----------------------------------------------------------

@pytest.mark.parametrize("theta", [0.3, 1.0, RK4_DRIVE_THETA, 2.5, 4.0, 5.0])
def test_rk4_drive_gains_are_what_rk4_does_to_a_pure_drive(theta):
    """x'' = cos(nu t) started on RK4's discrete particular solution x_n = -G_x cos(n theta)/nu^2,
    v_n = G_v sin(n theta)/nu stays on it: the closed forms of rk4_drive_gains are RK4's own response. Rounding
    (the drive's phase nu t is ~1e3 rad, good to ~1e-13) moves x over the 200 steps by up to ~1e-9 of 1/nu^2
    (measured); 1e-7 of it still tells G_x from 1 at every theta here (1 - G_x = 8e-6 at theta = 0.3)."""
    nu = 400.0
    h = theta / nu
    gx, gv = rk4_drive_gains(theta)
    ig = Rk4(lambda t, x, v, U: math.cos(nu * t), (), 0.0, -gx / nu**2, 0.0, 0.0, h)
    for n in range(1, 201):
        ig.advance(n * h)
    assert ig.x == pytest.approx(-gx * math.cos(200 * theta) / nu**2, abs=1e-7 / nu**2)
    assert ig.v == pytest.approx(gv * math.sin(200 * theta) / nu, abs=1e-7 / nu)


def test_rk4_drive_bound_is_one_percent_of_the_ripple():
    # theta is bisected to round-off, so 1 - G_x there is 0.01 up to the rounding of G_x (~1e-16 absolute,
    # 1e-14 relative to 0.01); rel 1e-9 checks that the bisection converged on the 1 % criterion
    assert 1.0 - rk4_drive_gains(RK4_DRIVE_THETA)[0] == pytest.approx(RK4_DRIVE_ERROR, rel=1e-9)
    assert 2 * math.pi / RK4_DRIVE_THETA == pytest.approx(3.7, abs=0.05)  # steps per period of the drive
    assert abs(rk4_drive_gains(RK4_DRIVE_THETA)[1] - 1.0) < RK4_DRIVE_ERROR  # v's ripple is the better one
    assert 1.0 - rk4_drive_gains(0.3)[0] == pytest.approx(0.3**4 / 960, rel=0.01)  # the leading term theta^4/960
    assert abs(rk4_drive_gains(4 * math.pi / 3)[0]) < 1e-12  # RK4 sees no ripple at all there
    assert abs(rk4_drive_gains(2 * math.pi)[0]) > 1e10  # and resonates at 2 pi


@pytest.mark.parametrize("values,settings,needles", [
    ({"Omega": 200.0}, {}, ["max_step = 0.01", "Omega = 200", "gamma cos(2 Omega tau)", "73%", "max_step = 0.00424"]),
    ({"Omega": 200.0, "gamma": 0.0}, {}, ["Omega = 200", "beta sin(Omega tau)", "max_step = 0.00848"]),
    ({"omega": 500.0}, {}, ["omega = 500", "Delta cos(omega tau)", "max_step = 0.00339"]),
    ({"Omega": 200.0}, {"fidelity": 1}, ["Omega = 200"]),  # the polynomial model's AC term is the same
    ({"Omega": 100 * math.pi}, {}, ["more than 1000%"]),  # 2 pi rad per step: the resonance
])
def test_rk4_warns_about_a_drive_its_step_does_not_resolve(values, settings, needles):
    _, warnings = checked_settings(Scene(**values), Settings(solver=Solver.RK4, **settings))
    assert len(warnings) == 1
    for needle in needles:
        assert needle in warnings[0], (needle, warnings[0])


@pytest.mark.parametrize("values,settings", [
    ({}, {"solver": Solver.RK4}),  # the paper example: Omega = 2, 0.04 rad per step
    ({"Omega": 200.0}, {"solver": Solver.RK4, "max_step": RK4_DRIVE_THETA / 400}),  # the step the warning names
    ({"Omega": 200.0, "beta": 0.0, "gamma": 0.0}, {"solver": Solver.RK4}),  # no AC term to resolve
    ({"omega": 500.0, "Delta": 0.0}, {"solver": Solver.RK4}),
    ({"Omega": 200.0}, {}),  # the adaptive solver resolves it by its error control
])
def test_no_drive_warning_when_the_drive_is_resolved_or_off(values, settings):
    assert checked_settings(Scene(**values), Settings(**settings))[1] == []


# -- RK4's terminal event on the step -----------------------------------------------------------------------------

def test_rk4_locates_a_terminal_event_inside_its_step():
    """x'' = 1 from rest: x = t^2/2 is a cubic, so the step's Hermite interpolant is exact and the event x = 1 is
    found at t = sqrt(2) with x'(t) = sqrt(2), not at the step's end 1.5 (where x = 1.125)."""
    ig = Rk4(lambda t, x, v, U: 1.0, (Event("wall", lambda x: 1.0 - x, True),), 0.0, 0.0, 0.0, 0.0, 0.5)
    with pytest.raises(TerminalEvent) as stop:
        ig.advance(2.0)
    # the interpolant is exact (a cubic), so only the root finder's tolerance remains: brentq on s = t/h in [0, 1]
    # with xtol = rtol = 1e-15 (integrate.py), |dt| <= h (1e-15 + 1e-15 s) = 1e-15 at h = 0.5; x = 1 to
    # v |dt| = 1.4e-15 plus rounding, inside abs 1e-14; t and v are asserted looser, to 1e-12
    assert stop.value.t == pytest.approx(math.sqrt(2), abs=1e-12)
    assert stop.value.x == pytest.approx(1.0, abs=1e-14)
    assert stop.value.v == pytest.approx(math.sqrt(2), abs=1e-12)


# -- the RK4 stability check at its limit --------------------------------------------------------------------------

def test_rk4_stability_check_sits_at_the_stability_limit():
    """mu = 50: the fast eigenvalue is ~ -50 and RK4's real stability interval ends at h lambda = -2.785, i.e.
    h = 0.0557. 0.055 runs (finite, to tau = 20), 0.06 is refused with the step to use."""
    scene = Scene(mu=50.0)
    plant = Plant(scene, Settings(solver=Solver.RK4, max_step=0.055))
    for i in range(20):
        out = plant.do_step(float(i), 1.0, 0.0)
    assert math.isfinite(out.x) and abs(out.x) < 0.1
    with pytest.raises(IntegrationError, match="RK4 unstable.*reduce max_step below 0.05"):
        Plant(scene, Settings(solver=Solver.RK4, max_step=0.06)).do_step(0.0, 1.0, 0.0)


# -- the extremes' rows -------------------------------------------------------------------------------------------

def assert_row(row):
    assert set(row) == {"name", "settings", "measured", "expected", "passed", "message"}
    assert row["expected"]["criterion"]
    assert row["passed"], row


def test_energy_closed_form_is_the_potential_of_the_hertz_force():
    """dE/dx at v = 0 is H(x) - 1 (central differences), in contact and beyond the contact edge x = -3/2."""
    for x in (-2.5, -1.6, -1.0, 0.0, 0.3, 1.0):
        d = 1e-6
        slope = (ex.energy(x + d, 0.0) - ex.energy(x - d, 0.0)) / (2 * d)
        s = 1 + 2 * x / 3
        # central differences, d = 1e-6: truncation d^2 |E'''| / 6 ~ 1e-13, rounding eps |E| / d ~ 2e-10 (|E| <= ~1):
        # abs 1e-8 has a margin of 50; a wrong force is off by O(1)
        assert slope == pytest.approx((s**1.5 if s > 0 else 0.0) - 1.0, abs=1e-8), x
    # E(-1.5) = 0.6 (0 - 1) + 1.5 = 0.9 in doubles: rounding only; approx's default rel 1e-6
    assert ex.energy(0.0, 0.0) == 0.0 and ex.energy(-1.5, 0.0) == pytest.approx(0.9)


def check_energy_row(row, tau):
    assert_row(row)
    drift = row["measured"]["relative_drift"]
    # tolerance proportionality: each 100-fold smaller rtol cuts the drift at least 10-fold (measured ~170-fold)
    assert drift["plant DOP853 rtol 1e-10"] < drift["plant DOP853 rtol 1e-08"] / 10
    assert drift["plant DOP853 rtol 1e-12"] < drift["plant DOP853 rtol 1e-10"] / 10
    # RK4 loses energy as tau h^5/72 (|R(i h)|^2 = 1 - h^6/72): measured within 1 % for every step; 5 % allowed
    for h in ex.RK4_STEPS:
        assert drift[f"plant RK4 h {h:g}"] == pytest.approx(drift[f"plant RK4 h {h:g} predicted"], rel=0.05)
    # the plant's DOP853 is SciPy's algorithm: the same drift to a factor 2 (measured 1.05)
    assert drift["plant DOP853 rtol 1e-12"] == pytest.approx(drift["scipy DOP853 rtol 1e-12"], rel=1.0)
    assert row["settings"]["tau"] == tau


@pytest.mark.long  # tau = 1000 at three tolerances
def test_undamped_energy_drift_quick():
    check_energy_row(ex.energy_drift(quick=True), 1e3)


@pytest.mark.slow
def test_undamped_energy_drift_full():
    """The issue's run: tau = 1e4, DOP853 at rtol 1e-12 below 1e-9 (measured 1.5e-10)."""
    check_energy_row(ex.energy_drift(quick=False), 1e4)


@pytest.mark.parametrize("mu", [50.0, 1e3])
def test_stiff_adaptive_finishes(plant_fmu, mu):
    row = ex.stiff_adaptive(plant_fmu, mu)
    assert_row(row)
    assert row["message"] is None  # no error, no warning


@pytest.mark.parametrize("mu,max_step", [(50.0, 0.1), (1e3, 0.01)])
def test_stiff_rk4_too_large_a_step_is_an_error_not_nan(plant_fmu, mu, max_step):
    row = ex.stiff_rk4(plant_fmu, mu, max_step)
    assert_row(row)
    # the step it names is RK4's limit 2.5/|lambda| with lambda ~ -mu
    limit = float(re.search(r"reduce max_step below (\S+)", row["message"]).group(1))
    assert limit == pytest.approx(2.5 / mu, rel=0.01)


@pytest.mark.parametrize("which", ["AC", "load"])
def test_fast_drive_under_rk4_is_warned_about(plant_fmu, which):
    row = ex.fast_drive(plant_fmu, which)
    assert_row(row)
    assert row["message"].startswith("[warning] RK4 max_step = 0.01 does not resolve")


def test_near_pull_in_adaptive(plant_fmu):
    validate(Scene(R=ex.PULL_IN_R, x_start=ex.NEAR_PULL_IN_X))  # a start the validation allows
    assert_row(ex.near_pull_in(plant_fmu))


def test_near_pull_in_rk4_agrees_with_the_adaptive_stop(plant_fmu):
    adaptive, rk4 = ex.near_pull_in(plant_fmu), ex.near_pull_in(plant_fmu, Solver.RK4, 1e-4)
    assert_row(rk4)
    # the pull-in time: RK4 at h lambda = 0.17 over ~6 steps is good to ~1e-8 here (measured 1.4e-8); 1e-7 is a
    # thousandth of a step, which the step's end (a whole step late) would miss
    assert rk4["measured"]["tau_at_stop"] == pytest.approx(adaptive["measured"]["tau_at_stop"], abs=1e-7)


def test_near_pull_in_rk4_default_step_is_a_clean_error(plant_fmu):
    assert_row(ex.near_pull_in_rk4_default_step(plant_fmu))


def test_start_inside_the_pull_in_gap_is_refused(plant_fmu):
    assert_row(ex.pull_in_start_refused(plant_fmu))


@pytest.mark.parametrize("rtol", [1e-8, 1e-10])
def test_contact_loss_and_hard_reimpact_keep_the_tolerance(plant_fmu, rtol):
    row = ex.contact_reimpact(plant_fmu, rtol)
    assert_row(row)
    measured = row["measured"]
    assert measured["impact_speeds"][0] > 2.0  # a hard re-impact: the first at |v| = 2.2
    assert measured["points_in_flight"] >= 20
    # located events are what keeps the error there: stepping over the kinks is at least twice as wrong (measured 7x)
    assert measured["max_abs_error_x_without_contact_event"] > 2 * measured["max_abs_error_x"]


@pytest.mark.parametrize("interval", [1e-6, 100.0])
def test_extreme_communication_steps(plant_fmu, interval):
    row = ex.comm_step(plant_fmu, interval)
    assert_row(row)
    assert row["measured"]["steps"] == (5000 if interval < 1 else 5)


@pytest.mark.parametrize("rtol", [1e-15, 1e-1])
def test_extreme_tolerances(plant_fmu, rtol):
    row = ex.tolerance_extreme(plant_fmu, rtol)
    assert_row(row)
    if rtol < MIN_RTOL:
        assert row["message"].startswith("[warning] parameter rtol = 1e-15")
        assert row["measured"]["warnings"] == 1
    else:
        assert row["measured"]["warnings"] == 0
        # rtol 0.1 is loose but not meaningless: the error is a fraction of the response (measured 14 %)
        assert row["measured"]["error_over_scale"] < 0.5


def test_fmu_rtol_from_setup_experiment_is_clamped_too(plant_fmu):
    run = run_fmu(plant_fmu, {}, 1.0, 0.1, tolerance=1e-300)
    assert run.completed and run.warnings() and "rtol = 1e-300" in run.warnings()[0]


def test_memory_stays_flat_quick(plant_fmu):
    row = ex.memory(plant_fmu, quick=True)
    assert_row(row)
    assert row["settings"]["doSteps"] == 100_000


@pytest.mark.slow
def test_memory_stays_flat_full(plant_fmu):
    """The issue's run: tau = 1e5 (interval 1)."""
    row = ex.memory(plant_fmu, quick=False)
    assert_row(row)
    assert row["settings"]["stop_time"] == 1e5


@pytest.mark.slow
def test_extreme_rows_full(plant_fmu):
    rows = ex.extreme_rows(quick=False, fmu=plant_fmu)
    assert len(rows) == 18 and len({row["name"] for row in rows}) == len(rows)
    for row in rows:
        assert_row(row)
