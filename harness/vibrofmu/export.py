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
