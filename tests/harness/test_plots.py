"""Plots: titles fit the figure, legends lie outside every axes (they cover no data), contact-loss intervals are
shaded where the flag says the contact is open, V's axis is logarithmic only when V spans two decades."""
from types import SimpleNamespace

import numpy as np
import pytest

from vibrofmu.output import export


def _inside_figure(fig, artist):
    renderer = fig.canvas.get_renderer()
    box, frame = artist.get_window_extent(renderer), fig.get_window_extent(renderer)
    return box.x0 >= frame.x0 - 0.5 and box.x1 <= frame.x1 + 0.5 and box.y1 <= frame.y1 + 0.5


def _legends_cover_no_axes(fig):
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    assert fig.legends, "the figure has a legend"
    for legend in fig.legends:
        box = legend.get_window_extent(renderer)
        assert _inside_figure(fig, legend)
        for ax in fig.axes:
            assert not box.overlaps(ax.get_window_extent(renderer))


def test_contact_loss_intervals_are_widened_to_the_midpoints():
    time = np.arange(10) * 0.5
    flags = np.array([1, 1, 0, 0, 1, 1, 1, 0, 1, 0], dtype=bool)
    # open samples 2..3 -> (0.75, 1.75); sample 7 -> (3.25, 3.75); sample 9 (last) -> (4.25, 4.5)
    assert export.contact_loss_intervals(time, flags) == [(0.75, 1.75), (3.25, 3.75), (4.25, 4.5)]
    assert export.contact_loss_intervals(time, np.ones(10, bool)) == []


def test_x_plot_shades_each_contact_loss_and_keeps_legend_and_title_clear():
    time = np.linspace(0.0, 20.0, 201)
    x = -1.6 * np.cos(time)
    in_contact = 1.0 + 2.0 * x / 3.0 > 0.0
    fig = export.figure_x(time, x, "HertzEAOscillator: fidelity exact, solver adaptive, rtol 1e-10",
                          reference_x=x + 1e-9, in_contact=in_contact)
    ax = fig.axes[0]
    spans = [p for p in ax.patches if p.get_label() != "_nolegend_"]
    intervals = export.contact_loss_intervals(time, in_contact)
    assert len(intervals) == 4  # cos(tau) > 15/16 around tau = 0 (the start), 2 pi, 4 pi, 6 pi
    assert len(spans) == len(intervals)
    for span, (start, end) in zip(spans, intervals):
        # the span is drawn from the interval's own ends (x + width rounds once); approx's default rel 1e-6 checks
        # the placement, which a wrong interval misses by a grid step (0.1 / 6.3 = 1.6e-2 relative or more)
        assert span.get_x() == pytest.approx(start) and span.get_x() + span.get_width() == pytest.approx(end)
    _legends_cover_no_axes(fig)
    assert _inside_figure(fig, ax.title)
    assert fig.axes[-1].get_xlabel() == export.TAU and "x" in ax.get_ylabel()  # tau under the lowest panel


def test_frequency_response_title_fits():
    omega = np.linspace(0.9, 1.1, 50)
    r = 0.1 / (1.0 + 100 * (omega - 1.0) ** 2)
    sweep = SimpleNamespace(omega=omega[::5], r=r[::5], direction="up")
    title = ("frequency response: mu = 0.1, Delta = 0.0007, alpha = 0.001, beta = 0.0001, gamma = 0.0002, "
             "Omega = 2")
    fig = export.figure_frequency_response((omega, r, r > 0), (omega[::3], r[::3], r[::3] > 0), [sweep], [],
                                           (0.9, 1.1), title)
    fig.canvas.draw()
    assert _inside_figure(fig, fig._suptitle)
    _legends_cover_no_axes(fig)


@pytest.mark.parametrize("V_end", [8.4e-3, 1e-6])
def test_lyapunov_axis_is_log_and_labelled_within_two_decades(V_end):
    time = np.linspace(0.0, 200.0, 401)
    V = V_end + (1.0e-2 - V_end) * np.exp(-time)
    series = {"x": np.sin(time), "x_ref": np.sin(time), "e1": 1e-4 * np.sin(time), "e2": 1e-4 * np.cos(time),
              "V": V, "mu_hat": np.full_like(time, 0.05)}
    figures = export.figures_closed_loop(time, series, {"mu": 0.1}, "closed loop")
    ax = figures["lyapunov.png"].axes[0]
    assert ax.get_yscale() == "log"  # as docs/cosimulation.md says
    figures["lyapunov.png"].canvas.draw()
    labels = [t for t in ax.yaxis.get_majorticklabels() + ax.yaxis.get_minorticklabels()
              if t.get_text() and ax.get_ylim()[0] <= t.get_position()[1] <= ax.get_ylim()[1]]
    assert len(labels) >= 3  # values can be read off the axis (V within a decade: ticks at 1, 1.5, 2, ... x 10^k)
    assert not figures["lyapunov.png"].legends  # one curve: its axis label names it
    for name in ("tracking.png", "errors.png", "estimates.png"):
        _legends_cover_no_axes(figures[name])


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    import matplotlib.pyplot as plt

    plt.close("all")
