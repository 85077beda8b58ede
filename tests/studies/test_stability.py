"""Issue 4 acceptance: slow-flow predictions against shooting/Floquet and against FMU sweeps."""
import json
import shutil

import numpy as np
import pytest
from fmpy import extract

from vibromodel import averaging as av
from vibromodel.parameters import Scene
from vibromodel.plant import Settings
from vibrofmu.analyses import shooting
from vibrofmu.cli import main
from vibrofmu.analyses.stability import fold_agreement, shoot_predictions, stability_study
from vibrofmu.analyses.sweep import MAX_PERIODS, Sweep, SweepPoint, hysteresis_jumps, settle, sweep

STRONG = Scene(mu=0.002)  # mu = 0.002, Delta = 0.0007, the rest as the paper example


@pytest.fixture(scope="module")
def strong_study():
    return stability_study(STRONG, n=201)


def test_three_branches_match_shooting_and_floquet_at_sigma_minus_0_0024():
    model = av.averaged(STRONG)
    point = shoot_predictions(model, shooting.PeriodicModel(STRONG), model.omega_e - 0.0024)
    assert [s.kind for s in point.slow] == ["stable focus", "saddle", "stable focus"]
    assert [o.kind for o in point.orbits] == ["stable", "saddle", "stable"]
    for state, orbit in zip(point.slow, point.orbits):
        assert abs(state.r - orbit.r) <= 0.003 * orbit.r  # acceptance 1: r within 0.3 %
        predicted = sorted(state.multipliers(point.omega), key=lambda z: (abs(z), z.imag))
        measured = sorted(orbit.multipliers, key=lambda z: (abs(z), z.imag))
        assert max(abs(a - b) for a, b in zip(predicted, measured)) <= 1e-3  # exp(lambda T) vs Floquet
        assert orbit.liouville_error <= 1e-9  # rho1 rho2 = exp(-mu T), from rtol 1e-11 of the period map


@pytest.mark.long  # the strong study: shooting and Floquet on 201 frequencies
def test_classification_agrees_with_floquet_on_201_frequencies(strong_study):
    agreement = strong_study["summary"]["classification_agreement"]
    assert agreement["points_compared"] >= 190  # only points next to the two folds are left out
    assert agreement["fraction"] >= 0.98  # acceptance 2


@pytest.mark.long  # the strong study: shooting and Floquet on 201 frequencies
def test_fold_frequencies_of_slow_flow_and_continuation_agree(strong_study):
    rows = strong_study["summary"]["fold_frequencies"]["folds"]
    assert len(rows) == 2
    omega_e = strong_study["model"].omega_e
    for row in rows:
        sigma = row["slow_flow"] - omega_e
        # the slow flow's detuning (w^2 - k1)/(2w) differs from w - w_e by sigma^2/(2w) (docs/model.md, Averaging and slow flow); the
        # Lindstedt backbone itself is good to ~2e-7 (test_averaging): twice the first plus the second
        assert abs(row["continuation_minus_slow_flow"]) <= 2 * sigma**2 / 2 + 2e-7


def test_fmu_sweeps_jump_at_the_folds(plant_fmu, strong_study):
    """Up and down sweeps over 9 frequencies across the hysteresis interval (grid placed from the continuation's
    folds, step = width/4): the FMU jumps within one step plus the ghost margin of the continuation's folds."""
    continuation = sorted(strong_study["response"].folds, key=lambda fold: fold.omega)
    lo, hi = continuation[0].omega, continuation[1].omega
    grid = np.linspace(lo - (hi - lo), hi + (hi - lo), 9)
    sweeps = [sweep(plant_fmu, STRONG.with_values(omega=order[0]), order) for order in (grid, grid[::-1])]
    assert all(s.stop_reason is None for s in sweeps)
    result = fold_agreement(strong_study["model"], av.folds(strong_study["model"]), continuation, sweeps,
                            grid[1] - grid[0])
    assert [j["sweep"] for j in result["sweep_jumps"]] == ["down", "up"]
    assert result["sweep_folds_within_tolerance"]


def test_hysteresis_jumps_from_synthetic_sweeps():
    def make(direction, omegas, rs, settled=(True,) * 6):
        return Sweep(direction, [SweepPoint(w, r, 0.0, ok, 10, (0.0, 0.0)) for w, r, ok in zip(omegas, rs, settled)])

    omegas = np.arange(6.0)
    up = make("up", omegas, [1, 1, 1, 1, 3, 3])  # jumps up between 3 and 4
    down = make("down", omegas[::-1], [3, 3, 3, 3, 1, 1])  # on the upper branch down to 2, jumps between 2 and 1
    jumps = hysteresis_jumps(up, down)
    assert [(j["sweep"], j["omega"]) for j in jumps] == [("down", 1.5), ("up", 3.5)]
    assert hysteresis_jumps(up, make("down", omegas[::-1], [3, 3, 1, 1, 1, 1])) == []  # no bistability
    in_transit = make("down", omegas[::-1], [3, 3, 3, 3, 2, 1], settled=(True,) * 4 + (False, True))
    assert [j["omega"] for j in hysteresis_jumps(up, in_transit)] == [1.5, 3.5]  # the point at 1 is in transit


def test_ghost_margin_shrinks_with_the_square_of_the_wait():
    model = av.averaged(STRONG)
    lower, upper = av.folds(model)
    wait = MAX_PERIODS * 2 * np.pi / lower.omega  # the sweeps' longest wait
    margin, halved = (av.ghost_margin(model, lower, t) for t in (wait, 2 * wait))
    assert margin / halved == pytest.approx(4.0, rel=1e-12)  # passage time ~ d omega^(-1/2)
    assert 0 < margin < upper.omega - lower.omega  # the sweeps can resolve the hysteresis interval


def test_paper_example_single_stable_branch_and_fmu_amplitude_within_one_percent(plant_fmu):
    """Acceptance 3: mu = 0.1; three frequencies across the resonance, each settled from rest."""
    model = av.averaged(Scene())
    unzip_dir = extract(str(plant_fmu))
    try:
        for omega in (model.omega_e - 0.1, Scene().omega, model.omega_e + 0.1):
            (state,) = av.steady_states(model.flow(omega), model.r_max)
            assert state.stable
            measured = settle(plant_fmu, unzip_dir, Scene(omega=omega), Settings())
            assert measured.settled
            assert abs(measured.r - state.r) <= 0.01 * state.r
    finally:
        shutil.rmtree(unzip_dir, ignore_errors=True)


@pytest.mark.long  # a stability study and its plot
def test_cli_writes_summary_and_plot(tmp_path):
    out = tmp_path / "stability"
    omega_e = av.averaged(Scene()).omega_e
    code = main(["stability", "--no-fmu", "--omega-range", str(omega_e - 0.2), str(omega_e + 0.2), "11",
                 "--out", str(out)])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["classification_agreement"]["fraction"] == 1.0
    assert summary["paper_mode"]["trace_J"] == {"printed_eq68": 0.1, "corrected": -0.1}
    assert (out / "frequency_response.png").stat().st_size > 0


def test_cli_refuses_a_bad_range(tmp_path, capsys):
    assert main(["stability", "--no-fmu", "--omega-range", "1.2", "0.8", "11", "--out", str(tmp_path)]) == 2
    assert "omega-range" in capsys.readouterr().err


def test_a_sweep_that_hits_pull_in_says_why(plant_fmu):
    """R = 0.2 puts the electrode at x = 0.3: the forced vibration from x_start = 0.29 pulls in at once."""
    scene = Scene(R=0.2, x_start=0.29)
    result = sweep(plant_fmu, scene, [scene.omega, scene.omega + 0.01])
    assert result.points == [] and "pull-in" in result.stop_reason
