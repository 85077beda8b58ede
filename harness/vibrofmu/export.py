"""Results a person can read: CSV of every output, a JSON summary, a plot of x."""
from __future__ import annotations

import json
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def write_csv(path: Path, time: np.ndarray, columns: dict[str, np.ndarray]) -> None:
    names = ["time"] + list(columns)
    data = np.column_stack([time] + [columns[n] for n in columns])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")


def write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2, default=float) + "\n")


def plot_x(path: Path, time, x, title: str, reference_x=None) -> None:
    """x(tau); with a reference, the reference dashed and |error| on a log second axis."""
    fig, ax = plt.subplots(figsize=(10, 4.5))
    ax.plot(time, x, lw=1.0, label="FMU")
    ax.set_xlabel("tau")
    ax.set_ylabel("x")
    if reference_x is not None:
        ax.plot(time, reference_x, "--", lw=1.0, label="reference (DOP853, rtol 1e-12)")
        err = np.abs(np.asarray(x) - np.asarray(reference_x))
        ax2 = ax.twinx()
        ax2.semilogy(time, np.maximum(err, 1e-18), color="tab:red", lw=0.5, alpha=0.5, label="|x - x_ref|")
        ax2.set_ylabel("|x - x_ref|", color="tab:red")
        ax2.legend(loc="lower right")
        ax.set_zorder(ax2.get_zorder() + 1)  # the solution in front of the error
        ax.patch.set_visible(False)
    ax.legend(loc="upper right")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_analytic(path: Path, tau, x, x_ref, boundaries, title: str) -> None:
    """Analytic and numerical x(tau) on top, |error| on a log axis below; domain boundaries marked."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, height_ratios=[3, 2])
    top.plot(tau, x_ref, lw=1.6, color="0.6", label="numerical (DOP853, rtol 1e-12)")
    top.plot(tau, x, "--", lw=0.9, color="tab:blue", label="analytic (OAFM)")
    top.set_ylabel("x")
    top.legend(loc="upper right")
    top.set_title(title)
    bottom.semilogy(tau, np.maximum(np.abs(np.asarray(x) - np.asarray(x_ref)), 1e-18), lw=0.6, color="tab:red")
    bottom.set_ylabel("|x_oafm - x_num|")
    bottom.set_xlabel("tau")
    for ax in (top, bottom):
        for boundary in boundaries:
            ax.axvline(boundary, color="k", lw=0.6, ls=":")
        ax.grid(True, which="major", alpha=0.3)
    for boundary, name in zip(boundaries, ("tau*", "fit ends")):
        top.annotate(name, (boundary, 1.0), xycoords=("data", "axes fraction"), fontsize=8, ha="left", va="top")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_convergence(path: Path, rows: list[dict]) -> None:
    """Error and residual against the number of convergence-control parameters, one line per domain."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for domain, marker in ((0, "o"), (1, "s")):
        n = [r["unknowns"][domain] for r in rows]
        ax.loglog(n, [r["max_abs_error"][domain] for r in rows], marker + "-", label=f"max |error|, domain {domain + 1}")
        ax.loglog(n, [r["residual_rms"][domain] for r in rows], marker + "--", alpha=0.6,
                  label=f"RMS residual, domain {domain + 1}")
        for r, count in zip(rows, n):
            ax.annotate(f"{r['order']}", (count, r["max_abs_error"][domain]), fontsize=7,
                        textcoords="offset points", xytext=(3, 3))
    ax.set_xlabel("number of convergence-control parameters C_i (labels: order)")
    ax.set_ylabel("error / residual")
    ax.set_title("OAFM harmonic basis: convergence")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_frequency_response(path: Path, curve, continuation, sweeps, folds, omega_range, title: str) -> None:
    """Amplitude r against omega: the slow flow's curve (stable solid, unstable dashed), the shooting
    continuation (Floquet: filled stable, open unstable), FMU sweeps up/down, and the folds (dotted).
    With folds, a second panel zooms onto the hysteresis interval."""
    panels = [omega_range]
    if len(folds) >= 2:
        width = folds[-1] - folds[0]
        panels.append((folds[0] - 1.5 * width, folds[-1] + 1.5 * width))
    fig, axes = plt.subplots(1, len(panels), figsize=(7 * len(panels), 5.5), squeeze=False)
    omega, r, stable = (np.asarray(a) for a in curve)
    c_omega, c_r, c_stable = (np.asarray(a) for a in continuation)
    for ax, (lo, hi) in zip(axes[0], panels):
        ax.plot(omega, np.where(stable, r, np.nan), "-", color="tab:blue", lw=1.6, label="slow flow, stable")
        ax.plot(omega, np.where(stable, np.nan, r), "--", color="tab:blue", lw=1.2, label="slow flow, unstable")
        ax.plot(c_omega[c_stable], c_r[c_stable], "o", ms=3, color="k", label="shooting, stable (Floquet)")
        ax.plot(c_omega[~c_stable], c_r[~c_stable], "o", ms=3, mfc="none", color="k",
                label="shooting, unstable (Floquet)")
        for sweep, marker, color in zip(sweeps, ("^", "v"), ("tab:red", "tab:green")):
            ax.plot(sweep.omega, sweep.r, marker, ms=7, mfc="none", color=color, label=f"FMU sweep {sweep.direction}")
        for fold in folds:
            ax.axvline(fold, color="0.5", lw=0.7, ls=":")
        inside = (omega >= lo) & (omega <= hi)
        top = max(np.max(r[inside], initial=0.0), np.max(c_r, initial=0.0))
        ax.set_xlim(lo, hi)
        ax.set_ylim(0.0, 1.08 * top)
        ax.set_xlabel("forcing frequency omega")
        ax.set_ylabel("first-harmonic amplitude r")
        ax.grid(True, alpha=0.3)
    axes[0][0].legend(fontsize=8, loc="upper left")
    if len(panels) > 1:
        axes[0][1].set_title("hysteresis interval (folds dotted)", fontsize=10)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_closed_loop(out_dir: Path, time, series: dict, theta: dict, title: str) -> list[Path]:
    """Closed loop: x vs x_ref, e1 and e2, V on a log axis, each estimate against its true value (dashed)."""
    paths = [out_dir / name for name in ("tracking.png", "errors.png", "lyapunov.png", "estimates.png")]
    fig, ax = plt.subplots(figsize=(10, 4.5))
    ax.plot(time, series["x"], lw=1.0, label="x (plant)")
    ax.plot(time, series["x_ref"], "--", lw=1.0, label="x_ref")
    _finish(fig, ax, paths[0], title, "x")
    fig, ax = plt.subplots(figsize=(10, 4.5))
    for name in ("e1", "e2"):
        ax.plot(time, series[name], lw=0.8, label=name)
    ax.set_yscale("symlog", linthresh=1e-6)
    _finish(fig, ax, paths[1], title, "tracking error (symlog)")
    fig, ax = plt.subplots(figsize=(10, 4.5))
    ax.semilogy(time, series["V"], lw=1.0, label="V")
    _finish(fig, ax, paths[2], title, "Lyapunov function V")
    fig, axes = plt.subplots(3, 3, figsize=(12, 8), sharex=True)
    for ax, (name, true) in zip(axes.flat, theta.items()):
        ax.plot(time, series[f"{name}_hat"], lw=1.0, label="estimate")
        ax.axhline(true, color="k", ls="--", lw=0.8, label="true")
        ax.set_title(name, fontsize=9)
    axes.flat[0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("tau")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(paths[3], dpi=100)
    plt.close(fig)
    return paths


def _finish(fig, ax, path: Path, title: str, ylabel: str) -> None:
    ax.set_xlabel("tau")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
