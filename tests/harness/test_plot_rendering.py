"""Every plot the commands write, rendered from small inputs and checked as a reader would look at it: axes
labelled (omega and Delta as symbols), no two tick labels of an axis overlapping (renderer bounding boxes), count
axes with integer ticks only, every legend entry naming something that is drawn, no empty axes, and the plot
saying what the numbers mean (a stopped run marked where it stopped, the basins' count within the margin).

The inputs are synthetic (shapes and ranges of the real studies' records: the default response-map grid, the
quick basins grid, a ladder with the real rung names and the ratios of a measured bench): the checks are about
the drawing, not the numbers; the commands' own tests check the numbers."""
from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.collections import Collection
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from vibrofmu.output import export
from vibrofmu.speed import ladder as ladder_module
from vibrofmu.study import plots as study_plots
from vibrofmu.study.spec import build_spec


# -- checks ----------------------------------------------------------------------------------------------
def _drawn_tick_labels(ax, axis):
    """The tick labels of `axis` that are drawn: visible, with text, inside the view interval."""
    low, high = sorted(axis.get_view_interval())
    index = 0 if axis is ax.xaxis else 1
    return [label for label in axis.get_ticklabels(which="both")
            if label.get_visible() and label.get_text().strip()
            and low - 1e-12 * abs(low) <= label.get_position()[index] <= high + 1e-12 * abs(high)]


def assert_tick_labels_do_not_overlap(fig):
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            boxes = [(label.get_text(), label.get_window_extent(renderer)) for label in _drawn_tick_labels(ax, axis)]
            for k, (text, box) in enumerate(boxes):
                for other, other_box in boxes[k + 1:]:
                    # touching boxes (a shared edge, rounding of a pixel) are no overlap: shrink by half a pixel
                    assert not box.shrunk(1, 1).padded(-0.5).overlaps(other_box.padded(-0.5)), \
                        f"tick labels {text!r} and {other!r} overlap ({ax.get_title() or ax.get_ylabel()})"


def _draws_something(artist):
    gid = artist.get_gid() or "" if hasattr(artist, "get_gid") else ""
    if gid.startswith("image value "):  # a legend proxy for a colour of an image: that value must be in the image
        value = float(gid.split()[-1])
        return any(np.any(np.asarray(image.get_array()) == value) for image in artist.axes.get_images())
    if isinstance(artist, Line2D):
        x, y = (np.asarray(a, dtype=float) for a in artist.get_data())
        return bool(np.any(np.isfinite(x) & np.isfinite(y)))
    if isinstance(artist, Collection):
        return len(artist.get_offsets()) > 0 or len(artist.get_paths()) > 0
    return isinstance(artist, Patch) or hasattr(artist, "get_children")


def _artists(fig):
    for ax in fig.axes:
        yield from ax.get_children()
        for container in ax.containers:
            yield container


def assert_legend_entries_are_drawn(fig):
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    labelled = {}
    for artist in _artists(fig):
        label = artist.get_label() if hasattr(artist, "get_label") else None
        if isinstance(label, str) and label and not label.startswith("_"):
            labelled.setdefault(label, []).append(artist)
    for legend in legends:
        for text in legend.get_texts():
            name = text.get_text()
            assert name in labelled, f"legend entry {name!r} names no artist"
            assert any(_draws_something(a) for a in labelled[name]), f"legend entry {name!r}: nothing drawn"


def assert_no_empty_axes(fig):
    for ax in fig.axes:
        if ax.axison and not hasattr(ax, "_colorbar"):
            assert ax.has_data(), f"empty axes: {ax.get_title()!r}"


def assert_readable(fig):
    assert_tick_labels_do_not_overlap(fig)
    assert_legend_entries_are_drawn(fig)
    assert_no_empty_axes(fig)


@pytest.fixture
def captured(monkeypatch):
    """The figures the plot functions close after saving (plt.close kept from closing them)."""
    figures = []
    monkeypatch.setattr(plt, "close", lambda fig=None: figures.append(fig))
    yield figures
    monkeypatch.undo()
    plt.close("all")


# -- x.png ----------------------------------------------------------------------------------------------
def test_x_plot_puts_the_error_in_its_own_panel_below():
    time = np.linspace(0.0, 50.0, 501)
    x = 0.04 * np.exp(-0.05 * time) * np.cos(time)
    error = 1e-10 * (1.0 + np.sin(3 * time) ** 2)
    error[0] = 0.0  # the start value agrees exactly: a gap, not a point 8 decades down
    fig = export.figure_x(time, x, "HertzEAOscillator: fidelity exact", reference_x=x + error)
    top, below = fig.axes
    renderer = (fig.canvas.draw(), fig.canvas.get_renderer())[1]
    # the error's axes lies wholly below the x curves' axes: it covers none of them
    assert below.get_window_extent(renderer).y1 <= top.get_window_extent(renderer).y0
    assert below.get_yscale() == "log" and "x_" in below.get_ylabel() and below.get_xlabel() == export.TAU
    assert below.get_ylim()[0] > 1e-12  # the axis spans the errors (~1e-10), not a floor value
    assert_readable(fig)


def test_x_plot_marks_the_pull_in_where_the_fmu_says_it_happened():
    time = np.arange(20) * 0.1
    x = 0.2 + 0.005 * np.exp(2 * time)
    reason = ("fmi2DoStep failed with status 3 (error): [error] simulation stopped: pull-in: upper gap 1 - 2x/(3R) "
              "below 0.001 at tau = 1.919528264, x = 0.2997")
    fig = export.figure_x(time, x, "pull-in", stop=(time[-1], reason))
    ax = fig.axes[0]
    marks = [line for line in ax.get_lines() if line.get_label().startswith("pull-in at")]
    assert len(marks) == 1 and marks[0].get_xdata()[0] == pytest.approx(1.919528264)
    assert "1.91953" in marks[0].get_label()
    assert ax.get_xlim()[1] > 1.919528264  # the mark is inside the axes, not on its frame
    assert_readable(fig)


def test_x_plot_title_names_only_the_settings_the_run_reads():
    """The analytic fidelity has no solver and no rtol; RK4 has a step, not an rtol."""
    from vibromodel.plant import Settings

    from vibrofmu.analyses.simulate import FIDELITIES, SOLVERS, run_title

    analytic = run_title(Settings(fidelity=FIDELITIES["analytic"]), 0.1)
    assert "solver" not in analytic and "rtol" not in analytic and "OAFM harmonic basis, order 3" in analytic
    rk4 = run_title(Settings(solver=SOLVERS["rk4"], max_step=5.0), 0.1)
    assert "solver rk4, step 0.1" in rk4 and "rtol" not in rk4
    assert run_title(Settings(rtol=1e-6), 0.1).endswith("fidelity exact, solver adaptive, rtol 1e-06")
    assert run_title(Settings(fidelity=FIDELITIES["averaged"]), 0.1).endswith("averaged, slow-flow rtol 1e-08")


def test_the_pull_in_marker_is_not_clipped_by_the_axes():
    """The marker sits on the last point, often the top of the curve: drawn whole, over the axes' edge."""
    time = np.arange(20) * 0.1
    fig = export.figure_x(time, 0.2 + 0.005 * np.exp(2 * time), "pull-in", stop=(time[-1], "pull-in at tau = 1.9"))
    marker = next(line for line in fig.axes[0].get_lines() if line.get_marker() == "X")
    assert not marker.get_clip_on()


def test_the_response_map_title_counts_the_differing_cells_it_does_not_count(tmp_path, captured):
    """A "runs only" cell within the fold margin is drawn, but not counted: the title says so beside 1.000."""
    _, result = _response_map_result()
    cell = tuple(np.argwhere(result["near"])[0])
    result["measured"] = result["measured"].copy()
    result["measured"][cell] = True  # bistable by the runs only, within the margin
    study_plots.response_map(result, tmp_path / "response_map.png")
    title = captured[-1]._suptitle.get_text()
    assert "agreement 1.000" in title and "1 within the margin differ, not counted" in title


def test_diagram_labels_write_symbols_in_mathtext(tmp_path, captured):
    """No ASCII Greek beside mathtext: the convergence plot's axis is $\\lambda_1$, its legend $\\omega$ = ...,
    and titles list the scene in the same symbols."""
    from vibrofmu.analyses import diagram

    estimate = SimpleNamespace(running=list(-0.05 + 0.1 / np.arange(1, 30)), value=0.9, largest=-0.05)
    diagram.plot_convergence(SimpleNamespace(name="omega", exponents={"up": [estimate]}), tmp_path / "c.png")
    ax = captured[-1].axes[0]
    assert ax.get_ylabel() == r"running estimate of $\lambda_1$"
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [r"$\omega$ = 0.9"]
    assert export.scene_text({"mu": 0.1, "omega": 2.0, "R": 3.0}) == r"$\mu$ = 0.1, $\omega$ = 2, $R$ = 3"


# -- frequency_response.png -----------------------------------------------------------------------------
def _resonance(omega):
    return 0.007 / np.sqrt(1.0 + 400.0 * (omega - 1.0) ** 2)


def test_frequency_response_legend_lists_only_what_is_drawn():
    """The default scene has one stable branch and no fold: the legend must not list an unstable branch or folds."""
    omega = np.linspace(0.7, 1.3, 120)
    r = _resonance(omega)
    sweeps = [SimpleNamespace(omega=omega[::10], r=r[::10], direction=d) for d in ("up", "down")]
    fig = export.figure_frequency_response((omega, r, np.ones_like(omega, bool)),
                                           (omega[::2], r[::2], np.ones(60, bool)), sweeps, [], (0.7, 1.3), "default")
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert not any("unstable" in t or "fold" in t for t in texts), texts
    assert "slow flow, stable" in texts and "FMU sweep up" in texts
    assert_readable(fig)


def test_frequency_response_with_folds_lists_them():
    omega = np.concatenate([np.linspace(0.95, 1.0, 40), np.linspace(1.0, 0.99, 10), np.linspace(0.99, 1.05, 40)])
    r = np.concatenate([np.linspace(0.001, 0.01, 40), np.linspace(0.01, 0.005, 10), np.linspace(0.005, 0.001, 40)])
    stable = np.ones(90, bool)
    stable[40:50] = False
    fig = export.figure_frequency_response((omega, r, stable), (omega, r, stable), [], [0.99, 1.0], (0.95, 1.05),
                                           "folds")
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "slow flow, unstable" in texts and "fold (slow flow)" in texts and "shooting, unstable (Floquet)" in texts
    assert_readable(fig)


# -- closed loop: lyapunov.png and the others ------------------------------------------------------------
def test_closed_loop_figures_are_readable():
    time = np.linspace(0.0, 200.0, 401)
    series = {"x": np.sin(time), "x_ref": np.sin(time), "e1": 1e-4 * np.sin(time), "e2": 1e-4 * np.cos(time),
              "V": 8.4e-3 + 1.6e-3 * np.exp(-time), "mu_hat": np.full_like(time, 0.05),
              "Delta_hat": np.full_like(time, 6e-4)}
    for name, fig in export.figures_closed_loop(time, series, {"mu": 0.1, "Delta": 7e-4}, "closed loop").items():
        if name == "lyapunov.png":
            assert fig.axes[0].get_yscale() == "log"
        assert_tick_labels_do_not_overlap(fig)
        assert_legend_entries_are_drawn(fig)


# -- ladder.png -----------------------------------------------------------------------------------------
RUNGS = [("exact f0", 4.3e-7, 6.9e-10, 4400), ("polynomial f1", 4.0e-7, 6.9e-10, 4100),
         ("averaged f3", 1.2e-7, 3.9e-4, 1200), ("analytic f4", 1.7e-7, 3.0e-9, 2600),
         ("RK4 h = 0.01", 1.1e-6, 2.5e-11, 12000), ("closed loop", 1.2e-6, 6.9e-10, 16000)]


def _ladder_record():
    columns = [("C host", 0.1, 1.0), ("C host", 1.0, 7.0), ("FMPy", 1.0, 15.0)]
    rungs = [{"rung": name, "columns": [{"host": h, "interval": i, "cpu_per_output_seconds": cost * scale,
                                          "linf_x": error} for h, i, scale in columns],
              "instructions": [{"interval": i, "instructions_per_output": count * (1 + 5 * (i == 1.0))}
                               for i in (0.1, 1.0)]}
             for name, cost, error, count in RUNGS]
    exact = RUNGS[0]
    acceptance = [{"rung": name, "host": h, "interval": i, "ratio": cost / exact[1]}
                  for name, cost, _, _ in RUNGS[2:] for h, i in (("C host", 0.1), ("FMPy", 1.0))]
    acceptance_instructions = [{"rung": name, "interval": i, "ratio": count / exact[3]}
                               for name, _, _, count in RUNGS[2:] for i in (0.1, 1.0)]
    return {"rungs": rungs, "instructions": {"measured": True, "intervals": [0.1, 1.0]}, "acceptance": acceptance,
            "acceptance_instructions": acceptance_instructions, "fmpy_floor": [{"interval": 1.0,
                                                                              "lowest_reachable_ratio": 0.5}],
            "stop_time": 200.0, "rounds": 3}


def test_ladder_ticks_do_not_overlap_and_the_ratio_axis_fits_the_bars(tmp_path, captured):
    record = _ladder_record()
    ladder_module.plot_ladder(tmp_path / "ladder.png", record)
    fig = captured[-1]
    ratio_ax = next(ax for ax in fig.axes if ax.get_title().startswith("ratios"))
    tallest = max(max(a["ratio"] for a in record["acceptance"]), max(ladder_module.LIMITS.values()))
    # the axis ends within a factor 2 of the tallest bar or limit (it ran to 10^2 for bars of 4)
    assert tallest < ratio_ax.get_ylim()[1] < 2 * tallest
    assert ratio_ax.get_legend() is not None
    renderer = (fig.canvas.draw(), fig.canvas.get_renderer())[1]
    assert ratio_ax.get_legend().get_window_extent(renderer).y1 <= ratio_ax.get_window_extent(renderer).y0  # below
    assert_tick_labels_do_not_overlap(fig)
    assert_legend_entries_are_drawn(fig)
    assert len(_drawn_tick_labels(ratio_ax, ratio_ax.yaxis)) >= 2  # a ratio can be read off the axis
    assert r"$\tau$ in [0, " in fig._suptitle.get_text()  # the symbol as every other plot writes it


# -- study plots ----------------------------------------------------------------------------------------
def _response_map_result():
    spec = build_spec("response-map")
    omegas = 0.99873 + np.array(spec.axis("omega_offset"))
    deltas = np.array(spec.axis("Delta"))
    grid = np.add.outer(deltas / deltas.max(), 1.0 - np.abs(omegas - omegas.mean()) / np.ptp(omegas))
    bistable = grid > 1.3
    fold = SimpleNamespace
    return spec, {"omegas": omegas, "deltas": deltas, "r": {"up": 0.01 * grid, "down": 0.009 * grid},
                  "measured": bistable, "predicted": bistable, "test_mask": None, "near": ~bistable & (grid > 1.2),
                  "folds": [[fold(omega=omegas[5]), fold(omega=omegas[9])] if d > 5e-4 else [] for d in deltas],
                  "cusp": {"omega": omegas[7], "Delta": 5.5e-4}, "run_cusp": None, "extrapolation": {},
                  "summary": {"agreement": {"fraction": 1.0, "agreeing": 120, "compared": 120}}}


def test_response_map_labels_are_symbols_and_do_not_run_together(tmp_path, captured):
    _, result = _response_map_result()
    study_plots.response_map(result, tmp_path / "response_map.png")
    fig = captured[-1]
    maps = [ax for ax in fig.axes if ax.get_title()]
    assert len(maps) == 3
    for ax in maps:
        assert r"$\omega$" in ax.get_xlabel() and "omega" not in ax.get_xlabel().replace(r"$\omega$", "")
    assert r"$\Delta$" in maps[0].get_ylabel()
    assert_readable(fig)


def test_basins_title_counts_the_disagreements_within_the_margin(tmp_path, captured):
    spec = build_spec("basins", quick=True)
    x0, v0 = np.array(spec.axis("x0")), np.array(spec.axis("v0"))
    i, j = (a.ravel() for a in np.meshgrid(range(len(x0)), range(len(v0)), indexing="ij"))
    predicted = (x0[i] + v0[j] > 0).astype(int)
    distance = np.abs(x0[i] + v0[j]) / np.sqrt(2)
    measured = predicted.copy()
    near = np.flatnonzero(distance < 0.03)[:5]  # five disagreements, all within the margin
    measured[near] = 1 - measured[near]
    margin = 0.03
    far = distance > margin
    agreement = {"fraction": 1.0, "compared": int(far.sum()), "agreeing": int(far.sum()), "margin": margin,
                 "by_margin": {"0": {"compared": len(i), "agreeing": len(i) - len(near)}}}
    line = np.array([[-0.6, 0.6], [0.6, -0.6]])
    result = {"measured": measured, "predicted": predicted, "distance": distance, "boundary": [line],
              "stable": [SimpleNamespace(r=0.004), SimpleNamespace(r=0.02)], "omega": 0.9975,
              "summary": {"agreement": agreement}}
    study_plots.basins(spec, {"i": i, "j": j, "x_start": x0[i], "v_start": v0[j]}, result, tmp_path / "b.png")
    fig = captured[-1]
    title = fig.axes[0].get_title()
    assert f"{len(i) - len(near)}/{len(i)}" in title  # the disagreements are in the title's count
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any("not counted" in t for t in texts)
    assert r"$x_0$" in fig.axes[0].get_xlabel() and r"$v_0$" in fig.axes[0].get_ylabel()
    assert_readable(fig)


def test_monte_carlo_counts_have_integer_ticks(tmp_path, captured):
    rng = np.random.default_rng(1)
    n = 12  # few samples: a count axis up to ~3, where the default ticks are 0.5 apart
    r = rng.normal(0.005, 0.0003, n)
    d = {"pull_in": np.zeros(n, bool), "failed": np.zeros(n, bool), "settled": np.ones(n, bool), "r": r,
         "case": np.arange(n)}
    summary = {"amplitude": {"mean_ci95": [0.0049, 0.0051]}, "agreement": {"fraction": 1.0},
               "contact_loss": {"probability": 0.0, "ci95_wilson": [0.0, 0.24]},
               "pull_in": {"probability": 0.0, "ci95_wilson": [0.0, 0.24]}}
    study_plots.monte_carlo(d, {"summary": summary, "predicted_r": r * 1.001}, tmp_path / "mc.png")
    fig = captured[-1]
    counts = fig.axes[0]
    fig.canvas.draw()
    ticks = [t for t in counts.get_yticks() if counts.get_ylim()[0] <= t <= counts.get_ylim()[1]]
    assert len(ticks) >= 2 and all(float(t).is_integer() for t in ticks), ticks
    assert_readable(fig)


def test_basins_headline_says_what_the_margin_leaves_out():
    from vibrofmu.study.analysis import headline

    summary = {"kind": "basins", "cases": 64, "cases_in_study": 64, "computed_this_run": 64, "workers": 2,
               "wall_s": 79.0, "agreement": {"fraction": 1.0, "agreeing": 56, "compared": 56, "margin": 0.03,
                                             "by_margin": {"0": {"agreeing": 59, "compared": 64}}}}
    assert ("agreement with the averaged prediction 1.000 (56/56) farther than 0.03 from the predicted boundary; "
            "all points 59/64") in headline(summary)


def test_parameter_axes_name_the_symbol():
    """branch.png and diagram.png label their parameter axis as the other plots do (forcing frequency ω, load
    amplitude Δ); a name without a symbol is shown as it is."""
    from vibrofmu.output.export import parameter_label

    assert parameter_label("omega") == r"forcing frequency $\omega$"
    assert parameter_label("Delta") == r"load amplitude $\Delta$"
    assert parameter_label("V_bias") == "V_bias"
