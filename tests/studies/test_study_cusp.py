"""Issue 16: locating the cusp from the runs (vibrofmu.study.cusp) and the batch plan of the scheduler.

The extrapolation is checked on the cusp normal form, where the width and jump laws are exact; the two-start
test's verdicts on runs whose first harmonic is known in closed form; the FMU engine's reused instances
(fmi2Reset) bit for bit against the compiled core, also after a run that failed.
"""
import math

import numpy as np
import pytest

from vibromodel.parameters import Scene
from vibrofmu.study import cusp
from vibrofmu.study.cases import make_cases, run_case
from vibrofmu.study.engines import CoreEngine, FmuEngine
from vibrofmu.study.scheduling import guided_batches
from vibrofmu.study.spec import build_spec
from vibrofmu.analyses.sweep import WINDOW_PERIODS


def normal_form_band(delta, delta_c=0.00055, omega_c=0.9968, a=2.0, b=-3.0, c=40.0):
    """Cusp normal form s' = h + l s - s^3, h = a (omega - omega_c) + b (Delta - Delta_c), l = c (Delta - Delta_c):
    bistable for |h| < 2 (l/3)^{3/2}; the jump at a fold, from s = sqrt(l/3) to -2 sqrt(l/3), is 3 sqrt(l/3).
    Returns (width in omega, centre omega, jump)."""
    l = c * (delta - delta_c)
    half = 2 * (l / 3) ** 1.5 / a
    return 2 * half, omega_c - b * (delta - delta_c) / a, 3 * math.sqrt(l / 3)


def test_extrapolation_recovers_the_cusp_of_the_normal_form():
    """With the exact width and jump of the normal form, width^(2/3) and jump^2 are exactly linear in Delta:
    the fits' zeros and the centre line at the zero must give (Delta_c, omega_c) to rounding (1e-9 relative:
    the fitted values are ~1e-3 .. 1e-2, least squares in double precision loses a few digits)."""
    rows = []
    for delta in np.linspace(0.0007, 0.0010, 7):
        width, centre, jump = normal_form_band(delta)
        rows.append({"Delta": float(delta), "width": width, "centre": centre, "jump": jump})
    e = cusp.extrapolate(rows)
    assert e["Delta"] == pytest.approx(0.00055, rel=1e-9)
    assert e["from_jump"]["zero"] == pytest.approx(0.00055, rel=1e-9)
    assert e["omega"] == pytest.approx(0.9968, rel=1e-12)
    assert e["Delta_stderr"] < 1e-12  # an exact line: no residual


def test_extrapolation_error_covers_a_noisy_width():
    """Widths rounded to a grid of omega steps (as the runs' bands are): the fit's standard error must be
    of the size of the actual error of its zero (within a factor 4 either way on this sample)."""
    step = 2.5e-5
    rows = []
    for delta in np.linspace(0.0007, 0.0012, 11):
        width, centre, jump = normal_form_band(delta)
        rows.append({"Delta": float(delta), "width": round(width / step) * step, "centre": centre, "jump": jump})
    e = cusp.extrapolate(rows)
    error = abs(e["from_width"]["zero"] - 0.00055)
    assert e["from_width"]["stderr"] / 4 < max(error, 1e-7) < 4 * e["from_width"]["stderr"]


def test_band_rows_count_the_bistable_points():
    omegas = np.linspace(0.99, 0.991, 11)  # step 1e-4
    mask = np.zeros((3, 11), bool)
    mask[0, 4:6] = True  # 2 points: fewer than MIN_POINTS, left out
    mask[1, 2:7] = True
    mask[2, 1:9] = True
    jump = np.where(mask, 0.1, np.nan)
    rows = cusp.band_rows(np.array([1e-4, 2e-4, 3e-4]), omegas, mask, jump)
    assert [row["Delta"] for row in rows] == [2e-4, 3e-4]
    # widths and centres are differences of linspace points (step 1e-4, rounding ~1e-19 absolute): approx's
    # default rel 1e-6 checks the count of points, which one point more or less changes by 12 % or more
    assert rows[0]["width"] == pytest.approx(5e-4) and rows[1]["width"] == pytest.approx(8e-4)
    assert rows[0]["centre"] == pytest.approx(omegas[4])


def test_aitken_extrapolates_a_geometric_approach():
    for limit, a, q in ((0.3, 0.2, 0.5), (0.0, 0.5, 0.9), (0.05, -0.02, 0.3)):
        d = [limit + a * q**k for k in range(3)]
        assert cusp.aitken(*d) == pytest.approx(limit, abs=1e-15)
    assert cusp.aitken(0.1, 0.1, 0.1) == 0.1  # no change: the last value
    assert cusp.aitken(0.1, 0.2, 0.4) == 0.4  # diverging: the last value


class _AnalyticRun:
    """x(t) = mean + Re(c(t) e^{-i omega t}), c(t) = c_inf + (c0 - c_inf) e^{-rate t}: a run whose first harmonic
    relaxes to c_inf at a known rate."""

    def __init__(self, scene, c0, c_inf, rate):
        self.omega, self.c0, self.c_inf, self.rate = scene.omega, c0, c_inf, rate
        self.contact_loss = False

    def step(self, t, h):
        t += h
        c = self.c_inf + (self.c0 - self.c_inf) * math.exp(-self.rate * t)
        return 0.1 + (c * complex(math.cos(self.omega * t), -math.sin(self.omega * t))).real

    def release(self, ok=True):
        pass


class _AnalyticEngine:
    def __init__(self, targets, rate):
        self.targets, self.rate, self.opened = targets, rate, 0

    def open(self, scene):
        c0, c_inf = self.targets[self.opened]
        self.opened += 1
        return _AnalyticRun(scene, c0, c_inf, self.rate)


SCENE = Scene(mu=0.002, Delta=0.0006, omega=0.9967)


@pytest.mark.parametrize("targets, verdict", [
    # both relax to one state: monostable
    (((0.30, 0.30), (0.15, 0.30)), "monostable"),
    # they relax to states 50 % apart: bistable
    (((0.30, 0.32), (0.15, 0.16)), "bistable"),
])
def test_two_start_verdicts(monkeypatch, targets, verdict):
    """The slow flow's rate at SCENE sets the wait; the analytic runs relax at 3x that rate, so the wait (ln(d0
    / bound) + 1 relaxation times of the slow flow) leaves e^-(3 (ln 25 + 1)) of the initial distance: far below
    the bound when the two runs share a state."""
    rate = cusp.slowest_rate(SCENE)
    engine = _AnalyticEngine([(complex(c0), complex(c_inf)) for c0, c_inf in targets], 3 * rate)
    result = cusp.two_start(engine, SCENE, [(0, 0), (0, 0)], max_periods=20000)
    assert result["verdict"] == verdict, result
    if verdict == "bistable":
        # the beat-averaged amplitudes are the two states' (the transient has decayed to < 1e-3 of them)
        assert result["r"] == pytest.approx([0.32, 0.16], rel=1e-3)


def test_two_start_undecided_when_the_cap_cuts_the_wait():
    """Runs that would meet, stopped long before: neither verdict."""
    rate = cusp.slowest_rate(SCENE)
    engine = _AnalyticEngine([(0.30 + 0j, 0.20 + 0j), (0.10 + 0j, 0.20 + 0j)], rate / 50)
    beat = cusp.beat_windows(SCENE) * WINDOW_PERIODS
    result = cusp.two_start(engine, SCENE, [(0, 0), (0, 0)], max_periods=4 * beat)
    assert result["verdict"] == "undecided", result


def test_beat_window_count():
    """Omega = 2 against 2 omega = 1.9934: a beat of omega / |Omega - 2 omega| = 151 periods = 15 windows of 10."""
    assert cusp.beat_windows(SCENE) == round(0.9967 / abs(2.0 - 2 * 0.9967) / WINDOW_PERIODS)
    assert cusp.beat_windows(SCENE.with_values(beta=0.0, gamma=0.0)) == 1


@pytest.mark.parametrize("n, smallest, workers", [(120, 2, 2), (7, 1, 2), (1000, 3, 64), (1, 1, 1)])
def test_guided_batches_cover_every_case_largest_first(n, smallest, workers):
    sizes = guided_batches(n, smallest, workers)
    assert sum(sizes) == n
    assert all(a >= b for a, b in zip(sizes, sizes[1:]))  # largest first
    assert all(size >= smallest for size in sizes[:-1])  # only the remainder can be smaller
    assert sizes[0] <= max(smallest, math.ceil(n / (4 * workers)))  # a worker's first batch: a quarter of its share


def test_reused_fmu_instances_give_the_core_bits_also_after_a_failure(plant_fmu):
    """A pull-in (fmi2Error, the instance reset and reused) followed by ordinary samples: every sample on the
    reused instance equals the core's to the last bit."""
    core, fmu = CoreEngine(), FmuEngine(plant_fmu.read_bytes())
    spec = build_spec("monte-carlo", quick=True)
    cases = make_cases(spec)[:2]
    failing = {"case": 999, "params": {"Delta": 0.9}}  # a static load beyond the pull-in limit
    bad = run_case(spec, fmu, failing)[0]
    assert bad["pull_in"] or bad["failed"]
    assert bad == {**bad, **{k: run_case(spec, core, failing)[0][k] for k in ("pull_in", "failed")}}
    for case in cases:
        a, b = run_case(spec, core, case)[0], run_case(spec, fmu, case)[0]
        for key in ("r", "A", "B", "mean", "settled", "periods", "x_end", "v_end", "contact_loss", "pull_in", "failed"):
            assert a[key] == b[key], (case, key, a[key], b[key])
    assert fmu.made == 1  # one instance served every run


@pytest.mark.parametrize("order", ["1,x", "0,2", ""])
def test_scaling_command_rejects_a_bad_order(capsys, order):
    from vibrofmu.study.scaling import main as scaling

    assert scaling(["--order", order]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --order")


@pytest.mark.parametrize("item, message", [("cusp_test=2", "cusp_test = 2"), ("cusp_test_periods=0.5", "cusp_test_periods")])
def test_bad_cusp_test_settings_give_one_line_and_exit_2(tmp_path, capsys, item, message):
    from vibrofmu.cli import main

    assert main(["study", "response-map", "--quick", "--set", item, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0], err


def test_the_cusp_test_does_not_change_the_studys_identity():
    """--resume of a finished map with --set cusp_test=1 must find the same study on disk."""
    plain = build_spec("response-map", quick=True)
    tested = build_spec("response-map", sets=["cusp_test=1", "cusp_test_periods=9000"], quick=True)
    assert plain.digest() == tested.digest()


def test_ghost_wait_outside_the_band_only_and_its_square_root_law():
    """No ghost wait inside the slow flow's bistable band; outside, the passage pi / sqrt(|a b| d_omega) grows
    as d_omega^(-1/2): four times closer to the fold, twice as long. Checked against a direct run of the slow
    flow: started on the high branch just past the fold, it leaves that branch (r drops below the middle of
    the two branches' amplitudes at the fold) within the ghost wait, and not within a tenth of it."""
    from scipy.integrate import solve_ivp

    from vibromodel import averaging as av

    scene = Scene(mu=0.002, Delta=0.0007)
    model = av.averaged(scene)
    lo, hi = (f.omega for f in av.folds(model, samples=400))
    assert cusp.ghost_periods(scene.with_values(omega=0.5 * (lo + hi))) == 0.0
    # in tau (periods times 2 pi / omega): the square-root law exactly, to rounding
    near, far = (cusp.ghost_periods(scene.with_values(omega=lo - d)) * 2 * math.pi / (lo - d) for d in (2.5e-6, 1e-5))
    assert near / far == pytest.approx(2.0, rel=1e-9)
    # the slow flow past the low-frequency fold, from the fold's state (the vanished high branch)
    omega = lo - 1e-5
    fold = min(av.folds(model, samples=400), key=lambda f: abs(f.omega - lo))
    state = av.steady_state(model.flow(lo), fold.r)
    low = min(s.r for s in av.steady_states(model.flow(omega), model.r_max) if s.stable)
    flow = model.flow(omega)
    wait = far  # tau
    sol = solve_ivp(lambda t, z: flow.rhs(*z), (0.0, wait), [state.A, state.B], rtol=1e-9, atol=1e-12,
                    dense_output=True)
    t = np.linspace(0.0, wait, 4000)
    r = np.hypot(*sol.sol(t))
    left = t[np.argmax(r < 0.5 * (fold.r + low))]
    assert r[-1] < 0.5 * (fold.r + low)  # it left within the ghost wait (two passages)
    assert left > 0.1 * wait  # and the wait is not a gross overestimate
