"""Results a person can read: CSV of every output, a JSON summary, plots.

Plot conventions (every figure): constrained layout; the axes labelled with the model's dimensionless symbols
(time tau, displacement x, ...); a title wrapped to the figure's width so it is never clipped; legends outside
the axes (below them), so they cover no data; one curve alone gets no legend (its axis label names it).
"""
from __future__ import annotations

import contextlib
import json
import os
import textwrap
import uuid
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogFormatterSciNotation, LogLocator, NullFormatter  # noqa: E402

TAU = r"time $\tau$"
DPI = 110


CSV_CHUNK = 65536  # rows formatted at a time (a long run's CSV never exists whole as text in memory)


@contextlib.contextmanager
def atomic(path: Path):
    """Yield a temporary name next to `path` (hidden, ending in .tmp) to write to; when the block ends normally it
    replaces `path` (os.replace: atomic on POSIX); on an exception or Ctrl-C it is removed. So a file under its
    final name is always complete: an old one or the new one, never half of one."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_text(path: Path, text: str) -> None:
    """`text` into `path`, atomically (see atomic)."""
    with atomic(path) as tmp:
        tmp.write_text(text)


def write_csv(path: Path, time: np.ndarray, columns: dict[str, np.ndarray]) -> None:
    """time and the columns as CSV (17 significant digits), atomically, formatted CSV_CHUNK rows at a time."""
    names = ["time"] + list(columns)
    arrays = [np.asarray(time)] + [np.asarray(columns[n]) for n in columns]
    with atomic(path) as tmp, open(tmp, "w") as file:
        file.write(",".join(names) + "\n")
        for start in range(0, len(arrays[0]), CSV_CHUNK):
            data = np.column_stack([a[start:start + CSV_CHUNK] for a in arrays])
            np.savetxt(file, data, delimiter=",", fmt="%.17g")


def json_safe(value):
    """`value` with every non-finite number (NaN, +-inf) replaced by None (JSON null) and NumPy values made plain
    Python: JSON has no NaN or Infinity, and a file with such tokens is not JSON (most readers refuse it)."""
    if isinstance(value, dict):
        return {str(key): json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(item) for item in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value


def write_json(path: Path, data: dict) -> None:
    """`data` as JSON, atomically, non-finite numbers written as null (json_safe): always valid JSON (allow_nan=False)."""
    write_text(path, json.dumps(json_safe(data), indent=2, default=float, allow_nan=False) + "\n")


def write_parquet(table, path: Path) -> None:
    """A pyarrow Table to `path` as Parquet with page checksums (a reader with page_checksum_verification=True
    detects a damaged page), atomically (see atomic)."""
    import pyarrow.parquet as pq

    with atomic(path) as tmp:
        pq.write_table(table, tmp, write_page_checksum=True)


def save_figure(fig, path: Path, close: bool = True, **options) -> None:
    """fig.savefig to `path` atomically (the format from path's suffix), then closed (unless close is False and
    the write succeeded: another format follows)."""
    path = Path(path)
    try:
        with atomic(path) as tmp:
            fig.savefig(tmp, format=path.suffix.lstrip(".") or None, **options)
    except BaseException:
        plt.close(fig)
        raise
    if close:
        plt.close(fig)


def wrapped(title: str, width_inches: float, fontsize: float) -> str:
    """`title` broken into lines that fit `width_inches` at `fontsize` points (an average character of
    DejaVu Sans is about 0.6 em wide; 0.9 of the width leaves the margins)."""
    width = max(20, int(0.9 * width_inches * 72 / (0.6 * fontsize)))
    lines = []  # break between the ", "-separated items where possible, so "beta = 0.0001" stays whole
    for item in title.split(", "):
        if lines and len(lines[-1]) + 2 + len(item) <= width:
            lines[-1] += ", " + item
        else:
            if lines:
                lines[-1] += ","
            lines.extend(textwrap.wrap(item, width) or [""])
    return "\n".join(lines)


def _title(fig, ax, title: str, fontsize: float = 11) -> None:
    ax.set_title(wrapped(title, fig.get_figwidth() * ax.get_position().width, fontsize), fontsize=fontsize)


def legend_below(fig, axes, columns: int = 4) -> None:
    """One legend for the figure, outside and below the axes: the handles of every axes in `axes`."""
    handles, labels = [], []
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            if label not in labels:
                handles.append(handle)
                labels.append(label)
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncols=min(columns, len(handles)), fontsize=9,
                   frameon=False)


def save_plot(fig, path: Path, vector: bool = False) -> None:
    """fig as a PNG at `path` (DPI) and, with `vector`, as a PDF beside it (path with .pdf), each written
    atomically (save_figure); then closed."""
    if vector:
        save_figure(fig, Path(path).with_suffix(".pdf"), close=False)
    save_figure(fig, path, dpi=DPI)


def contact_loss_intervals(time, in_contact) -> list[tuple[float, float]]:
    """The intervals where the contact is open, from the sampled in_contact flag: each run of open samples
    t_i..t_j widened to the midpoints (t_(i-1) + t_i)/2 and (t_j + t_(j+1))/2 (the flag is known at the
    output points only: the interval is resolved to one output interval)."""
    time = np.asarray(time, dtype=float)
    open_ = ~np.asarray(in_contact, dtype=bool)
    if not open_.any():
        return []
    edges = np.diff(np.concatenate(([0], open_.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1

    def mid(i, j):
        return 0.5 * (time[i] + time[j])

    return [(mid(i - 1, i) if i > 0 else time[0], mid(j, j + 1) if j + 1 < len(time) else time[-1])
            for i, j in zip(starts, ends)]


def figure_x(time, x, title: str, reference_x=None, in_contact=None, stop=None):
    """x(tau), the contact-loss intervals shaded; with a reference, the reference dashed and |x - x_ref| on a log
    axis in a panel of its own below (so it covers no x curve); `stop` = (tau, reason) of a run that stopped early
    (pull-in, a failing FMU): a vertical line and a marker at the last point, labelled with the reason."""
    if reference_x is None:
        fig, ax = plt.subplots(figsize=(10, 5), layout="constrained")
        below = None
    else:
        fig, (ax, below) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, height_ratios=[3, 1.4],
                                        layout="constrained")
    for k, (start, end) in enumerate(contact_loss_intervals(time, in_contact) if in_contact is not None else ()):
        ax.axvspan(start, end, color="0.85", lw=0, label=r"contact lost ($1 + 2x/3 \leq 0$)" if k == 0 else None)
    ax.plot(time, x, lw=1.0, color="tab:blue", label="FMU")
    ax.set_ylabel(r"displacement $x$")
    if reference_x is not None:
        ax.plot(time, reference_x, "--", lw=1.0, color="tab:orange", label="reference (DOP853, rtol 1e-12)")
        err = np.abs(np.asarray(x, dtype=float) - np.asarray(reference_x, dtype=float))
        # exact agreement (the start value) leaves a gap: a floor value would stretch the axis by decades
        below.semilogy(time, np.where(err > 0, err, np.nan), color="tab:red", lw=0.6)
        below.set_ylabel(r"$|x - x_\mathrm{ref}|$")
        below.grid(True, which="major", alpha=0.3)
    end = time[-1] if len(time) else 0.0
    if stop is not None and len(time):
        tau, x_stop, what = stop_point(*stop)
        tau = end if tau is None else tau  # the FMU's message names no time: the last output
        end = max(end, tau)
        for panel in (ax, below) if below is not None else (ax,):
            panel.axvline(tau, color="k", lw=1.0, ls="--", label=f"{what} at $\\tau$ = {tau:.6g}" if panel is ax
                          else None)
        # not clipped: the last point is often the top of the curve, on the axes' edge
        ax.plot(tau, x[-1] if x_stop is None else x_stop, "X", ms=10, color="k", zorder=5, clip_on=False)
    (below if below is not None else ax).set_xlabel(TAU)
    if len(time) > 1:  # a stopped run: room after its end, so that the line marking the stop is not the frame
        ax.set_xlim(time[0], end + (0.03 * (end - time[0]) if stop is not None else 0.0))
    _title(fig, ax, title)
    legend_below(fig, [ax])
    return fig


def stop_point(end_time: float, reason: str | None) -> tuple[float | None, float | None, str]:
    """(tau, x, what) of an early stop from the FMU's message ("pull-in: ... at tau = 0.1346, x = 0.2997"): the
    time and displacement it names (None where it names none) and "pull-in" or "run stopped"."""
    import re

    reason = reason or ""
    tau = re.search(r"at tau = ([-+0-9.eE]+)", reason)
    x = re.search(r"\bx = ([-+0-9.eE]+)", reason)
    what = "pull-in" if "pull-in" in reason else "run stopped"
    return (float(tau[1]) if tau else None), (float(x[1]) if x else None), what


def plot_x(path: Path, time, x, title: str, reference_x=None, in_contact=None, stop=None) -> None:
    save_plot(figure_x(time, x, title, reference_x, in_contact, stop), path)


def plot_analytic(path: Path, tau, x, x_ref, boundaries, title: str) -> None:
    """Analytic and numerical x(tau) on top, |error| on a log axis below; domain boundaries marked."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, height_ratios=[3, 2],
                                      layout="constrained")
    top.plot(tau, x_ref, lw=1.6, color="0.6", label="numerical (DOP853, rtol 1e-12)")
    top.plot(tau, x, "--", lw=0.9, color="tab:blue", label=r"analytic (OAFM) $\tilde x$")
    top.set_ylabel(r"displacement $x$")
    _title(fig, top, title)
    bottom.semilogy(tau, np.maximum(np.abs(np.asarray(x) - np.asarray(x_ref)), 1e-18), lw=0.6, color="tab:red")
    bottom.set_ylabel(r"$|\tilde x - x_\mathrm{num}|$")
    bottom.set_xlabel(TAU)
    for ax in (top, bottom):
        for boundary in boundaries:
            ax.axvline(boundary, color="k", lw=0.6, ls=":")
        ax.grid(True, which="major", alpha=0.3)
    for boundary, name in zip(boundaries, (r"$\tau^*$", "fit ends")):
        top.annotate(name, (boundary, 1.0), xycoords=("data", "axes fraction"), fontsize=8, ha="left", va="top")
    legend_below(fig, [top])
    save_plot(fig, path)


def plot_convergence(path: Path, rows: list[dict]) -> None:
    """Error and residual against the number of convergence-control parameters, one line per domain."""
    fig, ax = plt.subplots(figsize=(7, 5), layout="constrained")
    for domain, marker in ((0, "o"), (1, "s")):
        n = [r["unknowns"][domain] for r in rows]
        ax.loglog(n, [r["max_abs_error"][domain] for r in rows], marker + "-",
                  label=rf"max $|\tilde x - x_\mathrm{{num}}|$, domain {domain + 1}")
        ax.loglog(n, [r["residual_rms"][domain] for r in rows], marker + "--", alpha=0.6,
                  label=f"RMS residual, domain {domain + 1}")
        for r, count in zip(rows, n):
            ax.annotate(f"{r['order']}", (count, r["max_abs_error"][domain]), fontsize=7,
                        textcoords="offset points", xytext=(3, 3))
    ax.set_xlabel(r"number of convergence-control parameters $C_i$ (labels: basis order)")
    ax.set_ylabel("error, residual")
    _title(fig, ax, "OAFM harmonic basis: convergence with the order")
    ax.grid(True, which="both", alpha=0.3)
    legend_below(fig, [ax], columns=2)
    save_plot(fig, path)


def figure_frequency_response(curve, continuation, sweeps, folds, omega_range, title: str):
    """Amplitude r against omega: the slow flow's curve (stable solid, unstable dashed), the shooting
    continuation (Floquet: filled stable, open unstable), FMU sweeps up/down, and the folds (dotted).
    With folds, a second panel zooms onto the hysteresis interval."""
    panels = [omega_range]
    if len(folds) >= 2:
        width = folds[-1] - folds[0]
        panels.append((folds[0] - 1.5 * width, folds[-1] + 1.5 * width))
    fig, axes = plt.subplots(1, len(panels), figsize=(7 * len(panels), 6), squeeze=False, layout="constrained")
    omega, r, stable = (np.asarray(a) for a in curve)
    c_omega, c_r, c_stable = (np.asarray(a) for a in continuation)
    def label(text, shown):  # a legend entry only for what is drawn (an empty branch gets none)
        return text if np.any(shown) else None

    for ax, (lo, hi) in zip(axes[0], panels):
        ax.plot(omega, np.where(stable, r, np.nan), "-", color="tab:blue", lw=1.6,
                label=label("slow flow, stable", stable & (omega >= lo) & (omega <= hi)))
        ax.plot(omega, np.where(stable, np.nan, r), "--", color="tab:blue", lw=1.2,
                label=label("slow flow, unstable", ~stable & (omega >= lo) & (omega <= hi)))
        shown = (c_omega >= lo) & (c_omega <= hi)
        ax.plot(c_omega[c_stable], c_r[c_stable], "o", ms=3, color="k",
                label=label("shooting, stable (Floquet)", c_stable & shown))
        ax.plot(c_omega[~c_stable], c_r[~c_stable], "o", ms=3, mfc="none", color="k",
                label=label("shooting, unstable (Floquet)", ~c_stable & shown))
        for sweep, marker, color in zip(sweeps, ("^", "v"), ("tab:red", "tab:green")):
            ax.plot(sweep.omega, sweep.r, marker, ms=7, mfc="none", color=color, label=f"FMU sweep {sweep.direction}")
        inside_folds = [fold for fold in folds if lo <= fold <= hi]
        for k, fold in enumerate(inside_folds):
            ax.axvline(fold, color="0.5", lw=0.7, ls=":", label="fold (slow flow)" if k == 0 else None)
        inside = (omega >= lo) & (omega <= hi)
        top = max(np.max(r[inside], initial=0.0), np.max(c_r, initial=0.0))
        ax.set_xlim(lo, hi)
        ax.set_ylim(0.0, 1.08 * top)
        ax.set_xlabel(r"forcing frequency $\omega$")
        ax.set_ylabel(r"first-harmonic amplitude $r$")
        ax.grid(True, alpha=0.3)
    if len(panels) > 1:
        axes[0][1].set_title("zoom: hysteresis interval", fontsize=10)
    fig.suptitle(wrapped(title, fig.get_figwidth(), 11), fontsize=11)
    legend_below(fig, axes[0], columns=2 * len(panels))  # the entries of every panel; two fit in 7 inches
    return fig


def plot_frequency_response(path: Path, curve, continuation, sweeps, folds, omega_range, title: str) -> None:
    save_plot(figure_frequency_response(curve, continuation, sweeps, folds, omega_range, title), path)


ESTIMATE_SYMBOLS = {"mu": r"\mu", "Delta": r"\Delta", "beta": r"\beta", "gamma": r"\gamma"}
PARAMETER_LABELS = {"omega": r"forcing frequency $\omega$", "Omega": r"AC frequency $\Omega$",
                    "Delta": r"load amplitude $\Delta$", "mu": r"damping $\mu$", "alpha": r"$\alpha$",
                    "beta": r"$\beta$", "gamma": r"$\gamma$", "R": "electrode gap R"}


SYMBOLS = {"omega": r"$\omega$", "Omega": r"$\Omega$", "Delta": r"$\Delta$", "mu": r"$\mu$", "alpha": r"$\alpha$",
           "beta": r"$\beta$", "gamma": r"$\gamma$", "R": "$R$", "x_start": "$x_0$", "v_start": "$v_0$",
           "tau": r"$\tau$"}


def symbol(name: str) -> str:
    """A scene parameter as mathtext (omega -> $\\omega$), as the axis labels write it; else the name itself."""
    return SYMBOLS.get(name, name)


def scene_text(values: dict) -> str:
    """"$\\mu$ = 0.1, $\\Delta$ = 0.05, ...": scene values for a title, in the symbols of the labels."""
    return ", ".join(f"{symbol(name)} = {value:g}" for name, value in values.items())


def parameter_label(name: str) -> str:
    """An axis label for a scene parameter: its symbol (omega -> forcing frequency ω), else the name itself."""
    return PARAMETER_LABELS.get(name, name)


def figures_closed_loop(time, series: dict, theta: dict, title: str) -> dict:
    """Closed loop: x against the reference, e1 and e2, V, each estimate against its true value (dashed)."""
    figures = {}
    fig, ax = plt.subplots(figsize=(10, 5), layout="constrained")
    ax.plot(time, series["x"], lw=1.0, label=r"plant $x$")
    ax.plot(time, series["x_ref"], "--", lw=1.0, label=r"reference $\tilde x$")
    _finish(fig, ax, title, r"displacement $x$")
    figures["tracking.png"] = fig
    fig, ax = plt.subplots(figsize=(10, 5), layout="constrained")
    ax.plot(time, series["e1"], lw=0.8, label=r"$e_1 = x - \tilde x$")
    ax.plot(time, series["e2"], lw=0.8, label=r"$e_2 = x' - \tilde x' + c\,e_1$")
    ax.set_yscale("symlog", linthresh=1e-6)
    _finish(fig, ax, title, r"tracking errors $e_1$, $e_2$ (linear within $\pm 10^{-6}$)")
    figures["errors.png"] = fig
    fig, ax = plt.subplots(figsize=(10, 5), layout="constrained")
    V = np.asarray(series["V"], dtype=float)
    ax.semilogy(time, np.where(V > 0, V, np.nan), lw=1.0)  # V >= 0 decays: a log axis shows its decay rate
    positive = V[np.isfinite(V) & (V > 0)]
    if positive.size and positive.max() < 10 * positive.min():  # within a decade: ticks at 1, 1.5, 2, ... x 10^k
        ax.yaxis.set_major_locator(LogLocator(subs=np.arange(1.0, 10.0, 0.5)))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:.3g}"))
        ax.yaxis.set_minor_formatter(NullFormatter())
    elif positive.size and positive.max() < 100 * positive.min():  # within two decades: label the minor ticks
        ax.yaxis.set_minor_formatter(LogFormatterSciNotation(labelOnlyBase=False, minor_thresholds=(2, 2)))
    _finish(fig, ax, title, r"Lyapunov function $V$")
    figures["lyapunov.png"] = fig
    fig, axes = plt.subplots(3, 3, figsize=(12, 8.5), sharex=True, layout="constrained")
    for ax, (name, true) in zip(axes.flat, theta.items()):
        symbol = ESTIMATE_SYMBOLS.get(name, name[0] + "_" + name[1:] if name[1:].isdigit() else name)
        ax.plot(time, series[f"{name}_hat"], lw=1.0, label=r"estimate $\hat\theta_i$")
        ax.axhline(true, color="k", ls="--", lw=0.8, label=r"true $\theta_i$")
        ax.set_ylabel(rf"$\hat {symbol}$")
        ax.grid(True, alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel(TAU)
    fig.suptitle(wrapped(f"{title}: parameter estimates", fig.get_figwidth(), 11), fontsize=11)
    legend_below(fig, axes.flat[:1])
    figures["estimates.png"] = fig
    return figures


def plot_closed_loop(out_dir: Path, time, series: dict, theta: dict, title: str) -> list[Path]:
    paths = []
    for name, fig in figures_closed_loop(time, series, theta, title).items():
        save_plot(fig, out_dir / name)
        paths.append(out_dir / name)
    return paths


def _finish(fig, ax, title: str, ylabel: str) -> None:
    ax.set_xlabel(TAU)
    ax.set_ylabel(ylabel)
    _title(fig, ax, title)
    ax.grid(True, alpha=0.3)
    legend_below(fig, [ax])
