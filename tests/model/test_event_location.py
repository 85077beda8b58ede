"""Event location that cannot lose a crossing (issue 15, docs/events.md): the halting reproducers complete, an
excursion across the event and back inside one step is found (DOP853's dense output, RK4's cubic), grazes match an
independent reference, and a sample of the random contact-loss campaign runs without a halt."""
import math

import numpy as np
import pytest

from vibrofmu.fmus import kernel
from vibrofmu.analyses.campaigns import contact_loss_campaign, count_contact_losses, graze_reference, graze_scene, run_plant
from vibrofmu.analyses.reference import reference_solution
from vibromodel.compiled import CompiledPlant
from vibromodel.integrate import Dop853, Rk4, TerminalEvent
from vibromodel.models import affine_event
from vibromodel.parameters import Scene
from vibromodel.plant import Plant, Settings

# The two reproducers of issue 15: before the fix both kernels halted with brentq's "f(a) and f(b) must have
# different signs" (the first in the doStep from tau = 0.7, the second at tau = 1.6).
REPRODUCERS = {
    "unforced, rtol 1e-3": (Scene(mu=0.1, Delta=0.0, alpha=0.0, beta=0.0, gamma=0.0, R=3.0, x_start=-0.84,
                                  v_start=-1.22), 1e-3, 0.1),
    "forced, rtol 2.2e-7": (Scene(R=3.6083, x_start=-0.72145, v_start=-1.4169, mu=0.014102, Delta=0.81034,
                                  omega=2.02775, Omega=0.411637, alpha=0.044361, beta=0.041015, gamma=0.0042673),
                            2.2e-7, 0.05),
    "forced, rtol 1e-7": (Scene(R=3.6083, x_start=-0.72145, v_start=-1.4169, mu=0.014102, Delta=0.81034,
                                omega=2.02775, Omega=0.411637, alpha=0.044361, beta=0.041015, gamma=0.0042673),
                          1e-7, 0.05),
}


@pytest.fixture(scope="module")
def library():
    return kernel.kernel_library()


@pytest.mark.parametrize("name", REPRODUCERS)
def test_the_halting_reproducers_complete_in_both_kernels(name, library):
    scene, rtol, interval = REPRODUCERS[name]
    runs = [run_plant(make(scene, Settings(rtol=rtol)), 40.0, interval)
            for make in (Plant, lambda s, st: CompiledPlant(s, st, library))]
    for times, _x, stop in runs:
        # default rel 1e-6: times[-1] is the last grid point (n x interval, rounding ~1e-14); the check is that the
        # run reached tau = 40 and did not halt
        assert stop is None and times[-1] == pytest.approx(40.0)
    # the compiled plant performs the Python plant's operations in the same order (-ffp-contract=off, no
    # -ffast-math; tests/core/test_plant_kernel.py): the same bits
    assert runs[0][1].tobytes() == runs[1][1].tobytes()


# -- an excursion inside one step -------------------------------------------------------------------------------
# x'' = -2 from x = 0.9, v = 1: x(t) = 0.9 + t - t^2 rises above the wall x = 1 at t1 = (1 - sqrt(0.6))/2 and falls
# back below it at t2 = (1 + sqrt(0.6))/2, both inside one step [0, 1] whose ends lie below the wall. DOP853 and RK4
# are exact on a quadratic (their dense output and cubic Hermite interpolant too), so the events are located to the
# root finder's tolerance (brentq xtol 1e-15 plus rtol 1e-15 times t) up to rounding of the interpolant: 1e-12.
T1, T2 = (1.0 - math.sqrt(0.6)) / 2.0, (1.0 + math.sqrt(0.6)) / 2.0


def falling(t, x, v, U):
    return -2.0


def test_dop853_finds_a_terminal_excursion_inside_one_step():
    wall = affine_event("wall", 1.0, -1.0, True)  # g = 1 - x
    ig = Dop853(falling, (wall,), 0.0, 0.9, 1.0, 0.0, 1e-8)
    ig.h = 1.0  # one step over the whole excursion (its error estimate is 0: accepted)
    with pytest.raises(TerminalEvent) as stop:
        ig.advance(1.0)
    assert stop.value.t == pytest.approx(T1, abs=1e-12)


def test_dop853_cuts_an_excursion_inside_one_step_twice():
    flips = []
    contact = affine_event("contact", 1.0, -1.0, False)  # positive below the wall
    ig = Dop853(falling, (contact,), 0.0, 0.9, 1.0, 0.0, 1e-8)
    ig.h = 1.0
    handle = ig._handle_events

    def recording(t0, x0, v0):
        side = ig.contact_side["contact"]
        handle(t0, x0, v0)
        if ig.contact_side["contact"] != side:
            flips.append((ig.t, ig.x))

    ig._handle_events = recording
    ig.advance(1.0)
    assert [t for t, _ in flips] == [pytest.approx(T1, abs=1e-12), pytest.approx(T2, abs=1e-12)]
    assert ig.contact_side["contact"] is True  # back on the start side
    assert ig.x == pytest.approx(0.9 + ig.t - ig.t ** 2, rel=1e-12)  # the quadratic, exact up to rounding


def test_rk4_finds_a_terminal_excursion_inside_one_step():
    wall = affine_event("wall", 1.0, -1.0, True)
    ig = Rk4(falling, (wall,), 0.0, 0.9, 1.0, 0.0, 1.0)
    with pytest.raises(TerminalEvent) as stop:
        ig.advance(1.0)
    assert stop.value.t == pytest.approx(T1, abs=1e-12)


def test_a_touch_that_stays_on_its_side_is_no_event():
    """x(t) = 0.9 + t - t^2 peaks at 1.15: a wall at 1.15 + 1e-9 is never reached (no event, no chattering); one at
    1.15 - 1e-9 is (its zero at the peak minus sqrt(1e-9))."""
    for offset, reached in ((1e-9, False), (-1e-9, True)):
        wall = affine_event("wall", 1.15 + offset, -1.0, True)
        ig = Dop853(falling, (wall,), 0.0, 0.9, 1.0, 0.0, 1e-8)
        ig.h = 1.0
        if reached:
            with pytest.raises(TerminalEvent) as stop:
                ig.advance(1.0)
            # near the peak the zero of 1e-9 - (t - 0.5)^2 moves by dg / (2 sqrt(1e-9)) = 1.6e4 dg: a rounding of g
            # (~2e-16) moves it ~4e-12; abs 1e-9 is still 3e4 times below the distance to the peak (3.2e-5)
            assert stop.value.t == pytest.approx(0.5 - math.sqrt(1e-9), abs=1e-9)
        else:
            ig.advance(1.0)
            assert ig.n_steps == 1


# -- grazes against an independent reference ---------------------------------------------------------------------
# Unforced, undamped (energy conserved): one excursion of `depth` below x = -3/2 per period, the reference from
# quadrature and exact free flight (campaigns.graze_reference; its x_max, t_contact and contact phase agree with a
# 30-digit mpmath quadrature to 3e-13, i.e. 2e-3 rtol max|x| at rtol 1e-10). docs/events.md: every excursion deeper
# than 10 rtol is located (the sweep there found all with depth >= 3.2 rtol, misses only at depth <= rtol, where the
# dense output's own error is as large as the excursion). The error bound is issue 15's acceptance, 10 rtol max|x|:
# the period is a smooth function of the energy (the potential is C^2 at the boundary, dT/dE = 0.61-0.64 at depths 1e-2 ... 1e-6),
# so near grazing the error is the integrator's local error at the contact kink, which the error norm counts in full
# there (integrate.py, the comment at ATOL_PER_RTOL); the 184-run sweep measured at most 1.84 (before: 15.2).
GRAZE_DEPTHS = (1e-1, 1e-3, 1e-6, 1e-9, 1e-12)
GRAZE_RTOLS = (1e-6, 1e-8, 1e-10)
GRAZE_BOUND = 10.0  # rtol max|x|, issue 15's acceptance


@pytest.mark.parametrize("depth", GRAZE_DEPTHS)
def test_grazes_match_the_independent_reference(depth, library):
    reference = graze_reference(depth)
    stop_time = 20.0
    for rtol in GRAZE_RTOLS:
        plant = Plant(graze_scene(reference), Settings(rtol=rtol, kernel=1))
        times, x, exits = count_contact_losses(plant, stop_time, 0.1)
        x_ref = reference.x(times)
        assert np.max(np.abs(x - x_ref)) <= GRAZE_BOUND * rtol * np.max(np.abs(x_ref))
        if depth >= 10.0 * rtol:
            assert exits == reference.exits(stop_time) == 3
        compiled_run = run_plant(CompiledPlant(graze_scene(reference), Settings(rtol=rtol), library), stop_time, 0.1)
        # the compiled plant is the Python plant's operations in the same order (see above): the same bits
        assert compiled_run[1].tobytes() == x.tobytes()


def test_worst_graze_of_the_sweep_is_within_the_acceptance_bound(library):
    """The sweep's worst run before the kink-aware error norm: depth 10^-2.5, rtol 1e-8 gave 15.2 rtol max|x| (the
    step starting at the third re-contact had a true local error 34 times its estimate). All three excursions are
    located, the error is within GRAZE_BOUND, and the compiled kernel gives the same bits."""
    reference = graze_reference(10.0 ** -2.5)
    plant = Plant(graze_scene(reference), Settings(rtol=1e-8, kernel=1))
    times, x, exits = count_contact_losses(plant, 20.0, 0.1)
    x_ref = reference.x(times)
    assert exits == reference.exits(20.0) == 3
    assert np.max(np.abs(x - x_ref)) <= GRAZE_BOUND * 1e-8 * np.max(np.abs(x_ref))
    compiled_run = run_plant(CompiledPlant(graze_scene(reference), Settings(rtol=1e-8), library), 20.0, 0.1)
    # the compiled plant is the Python plant's operations in the same order (see above): the same bits
    assert compiled_run[1].tobytes() == x.tobytes()


def test_graze_reference_period_is_the_quadratures():
    """The reference's own check: the contact phase it integrates ends on the boundary at t_contact (solve_ivp's
    dense output at rtol 1e-13 reaches x = -3/2 there to 1e-9, the sqrt-slow approach's conditioning)."""
    reference = graze_reference(1e-3)
    assert reference.contact(reference.t_contact)[0] == pytest.approx(-1.5, abs=1e-9)
    assert reference.x(np.array([reference.period]))[0] == pytest.approx(reference.x_max, abs=1e-9)


@pytest.mark.long  # a 200-scene campaign
# -- the campaign's sample -----------------------------------------------------------------------------------------
def test_contact_loss_campaign_sample_has_no_halt(library):
    """200 random contact-loss scenes (campaigns.contact_loss_campaign, tau <= 5): no halt other than pull-in for
    DOP853 (compiled; every 10th also pure Python, the same bits) and RK4, and every completed DOP853 run within
    100 rtol max|x| of the reference (issue 15's acceptance bound; the 10,000-scene run is in docs/events.md)."""
    result = contact_loss_campaign(200, seed=15, stop_time=5.0, library=library)
    assert result.halts == []
    assert result.twin_mismatches == []
    assert result.runs == {"dop853": 200, "rk4": 200, "python": 20}
    assert result.errors_over_100 == 0 and result.worst_error <= 100.0


# The campaign's worst completed run (seed 3, chunk 1, #72: 134 rtol max|x| at rtol 1.23e-6, docs/events.md). It never
# leaves contact; the excess comes from two long steps (h 2 Omega = 5.2 and 6.9 rad of the gamma cos(2 Omega tau)
# drive) whose true local errors were 29 and 73 times their estimates (with gamma = 0 the same steps are estimated
# conservatively), and the dense output inside the second one multiplies the step-end error (11.6) by about 10.
WORST_CAMPAIGN_SCENE = Scene(mu=0.17534537734078748, Delta=0.4825723641002341, omega=1.7839930805211193,
                             Omega=2.97757448060958, alpha=0.04495698082072221, beta=0.021819321012593734,
                             gamma=0.006706313281011708, R=5.803507089203329, x_start=-0.6071110791578956,
                             v_start=-1.3978717100090192)
WORST_CAMPAIGN_RTOL = 1.2296129547570618e-06


def test_worst_campaign_run_is_the_unresolved_drive(library):
    """The run within issue 15's 100 rtol max|x| of the reference (solve_ivp at rtol 1e-12, itself converged there:
    rtol 1e-13 changes it by 2e-6 rtol max|x|), twice: with max_step resolving the 2 Omega drive (3 rad per step; the
    two failing steps had 5.2 and 6.9), measured 0.10 (0.121 with the PI step controller); and at max_step = 0
    (automatic), measured 4.7 since the kink-aware error norm: the run passes within g = 0.1 of the contact kink near
    tau = 1, the stricter norm there changes the later step sequence and the two failing steps are no longer taken
    (with the PI step controller 0.017 at the ceiling's former 2.25 rad, 0.30 at its 4 rad, which binds no step here,
    as without a ceiling: models.DRIVE_STEP_TURN). The second is a regression check of this scene, not a guarantee: estimates too low by
    such factors remain possible on other long smooth steps."""
    scene, rtol = WORST_CAMPAIGN_SCENE, WORST_CAMPAIGN_RTOL
    reference = reference_solution(scene, 0, 10.0, rtol=1e-12, atol=1e-14)
    for max_step in (3.0 / (2.0 * scene.Omega), 0.0):
        times, x, stop = run_plant(CompiledPlant(scene, Settings(rtol=rtol, max_step=max_step), library), 10.0, 0.1)
        assert stop is None
        x_ref = reference(times)[0]
        assert np.max(np.abs(x - x_ref)) <= 100.0 * rtol * np.max(np.abs(x_ref))
