"""The campaigns of issue 25 (vibrofmu.analyses.domains): a small subset in the default suite, the whole grids slow."""
import pytest

from vibrofmu.analyses import domains


def assert_clean(summary):
    """0 crashes, 0 hangs, 0 outputs outside the domain with fmi2OK, every refusal at initialisation naming a
    parameter (issue 25's acceptance). The set-up times (slow_setups_not_refused, slowest_init_seconds) are measured
    and reported by the campaign, not asserted: the project times nothing in tests."""
    assert summary["crashes"] == 0 and summary["hangs"] == 0, summary
    assert summary["outside_the_domain_with_fmi2OK"] == 0, summary
    assert summary["refusals_naming_no_parameter"] == 0, summary


@pytest.mark.fmu
def test_extreme_inputs_subset(plant_fmu):
    """Delta = 1e4 (huge forcing) x fidelities 0-4, each in its own process: refused or right (pull-in at fidelities
    0-2 after the first output; fidelities 3 and 4 refused at initialisation naming Delta)."""
    result = domains.extreme_grid(plant_fmu, stop=5.0, parameters=("Delta",), values=(1e4,))
    assert result["summary"]["cases"] == 5 and result["summary"]["refused_at_initialisation"] == 2
    assert_clean(result["summary"])


@pytest.mark.fmu
@pytest.mark.slow
def test_extreme_input_grid(plant_fmu):
    """Every scene parameter, rtol and max_step at NaN, +-inf, 0, -1, 1e308, 1e-308, 1e4 x fidelities 0-4."""
    result = domains.extreme_grid(plant_fmu)
    assert result["summary"]["cases"] == 5 * len(domains.EXTREME_PARAMETERS) * len(domains.EXTREME_VALUES)
    assert_clean(result["summary"])


@pytest.mark.slow
def test_long_lightly_damped_grazing_runs_are_within_100_rtol_max_x(capsys):
    """217 runs (tau up to 5,000, mu down to 1e-3), as many as the campaign that found issue 25's 13 failures: the
    issue's acceptance, at least 99 % within 100 rtol max|x| with the defaults (the drive's step ceiling and the
    tolerance factor), and fewer within with the solver at the rtol asked (the factor off), so that the count could
    fail. Measured with seed 0: 217 with the defaults (worst 0.24 of the bound), 217 without the ceiling, 215 with
    the rtol asked (worst 1.22; docs/rungs.md, Domains); before DOP853's PI step controller 217, 217 and 211 (the 6
    left at mu <= 2.1e-3, 1.1 ... 2.3 times the bound)."""
    result = domains.graze_campaign(217, 0)
    summary = result["summary"]
    with capsys.disabled():
        print(f"\ngrazing runs within 100 rtol max|x|: {summary['within_100_rtol_max_x_with_ceiling']} of 217 with the "
              f"defaults, {summary['within_100_rtol_max_x_without']} without the ceiling, "
              f"{summary['within_100_rtol_max_x_rtol_as_asked']} at the rtol asked")
    assert summary["within_100_rtol_max_x_with_ceiling"] >= 0.99 * 217
    assert summary["within_100_rtol_max_x_rtol_as_asked"] < summary["within_100_rtol_max_x_with_ceiling"]


@pytest.mark.slow
def test_fidelities_3_and_4_accept_only_what_they_can_answer():
    """The rung grid: every fidelity 3 or 4 answer given without a warning is within 5 % of fidelity 0's amplitude
    (the averaged model's first-order error on the paper scene is ~1 %: docs/rungs.md), and fidelity 0 ran to the end
    wherever they answered (set-up times are reported by the campaign, not asserted)."""
    result = domains.rung_grid()
    for row in result["rows"]:
        if row["outcome"] == "accepted":
            assert row["relative_error"] <= 0.05 and row["fidelity_0_stop"] is None, row


@pytest.mark.slow
def test_the_drive_ceiling_turn_keeps_every_run_within_100_rtol_max_x():
    """The turn study (domains.turn_campaign, the evidence of models.DRIVE_STEP_TURN) reduced to 20 runs of each kind
    (contact loss, drives up to 100, long lightly damped grazes; seed 0): at the model's turn every run within 100
    rtol max|x| of its reference and stopping where it does, and on the contact-loss kinds every contact change along
    the output grid the reference's (a step that lost or invented an impact would change their count; on the
    grazes an output point within rounding of the contact edge can flip the count at any turn, the full study's one
    such run included)."""
    from vibromodel.models import DRIVE_STEP_TURN

    summary = domains.turn_campaign(20, 0, turns=(DRIVE_STEP_TURN,))["summary"]
    for kind in ("contact loss", "fast drive", "graze"):
        cell = summary[f"{kind}, turn {DRIVE_STEP_TURN:g}"]
        assert cell["runs"] == 20 and cell["within_100_rtol_max_x"] == 20, (kind, cell)
        if kind != "graze":
            assert cell["contact_changes_differing"] == 0, (kind, cell)
