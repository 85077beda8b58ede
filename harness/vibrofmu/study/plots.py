"""The study's plots (PNG in the output folder), each with the averaged prediction drawn on top."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from vibrofmu.output import export  # noqa: E402
from vibrofmu.study.spec import Spec  # noqa: E402


def plot(spec: Spec, table, result: dict, out: Path) -> list[Path]:
    data = {name: np.asarray(table.column(name).to_pylist()) for name in table.column_names}
    if spec.kind == "monte-carlo":
        return [monte_carlo(data, result, out / "monte_carlo.png")]
    if spec.kind == "basins":
        return [basins(spec, data, result, out / "basins.png")]
    return [response_map(result, out / "response_map.png")]


def monte_carlo(d: dict, result: dict, path: Path) -> Path:
    summary = result["summary"]
    ok = ~(d["pull_in"] | d["failed"]) & d["settled"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    r, predicted = d["r"][ok], result["predicted_r"][ok]
    bins = np.histogram_bin_edges(np.concatenate([r, predicted[np.isfinite(predicted)]]), bins=30)
    axes[0].hist(r, bins=bins, alpha=0.7, label=f"runs ({len(r)} settled)")
    axes[0].hist(predicted[np.isfinite(predicted)], bins=bins, histtype="step", lw=1.5, color="k",
                 label="slow flow at the same samples")
    lo, hi = summary["amplitude"]["mean_ci95"]
    axes[0].axvspan(lo, hi, color="C1", alpha=0.3, label="95 % CI of the mean")
    axes[0].set_xlabel("settled amplitude $r$ (first harmonic)")
    axes[0].set_ylabel("samples")
    axes[0].yaxis.set_major_locator(MaxNLocator(integer=True))  # counts: no half-integer ticks
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"amplitude; agreement with the slow flow {summary['agreement']['fraction']:.3f}")
    labels, values, errors = [], [], []
    for key in ("contact_loss", "pull_in"):
        p, (lo, hi) = summary[key]["probability"], summary[key]["ci95_wilson"]
        labels.append(key.replace("_", " "))
        values.append(p)
        errors.append([max(0.0, p - lo), max(0.0, hi - p)])
    axes[1].bar(labels, values, yerr=np.array(errors).T, capsize=8, color=["C2", "C3"])
    n = len(d["case"])
    for k, p in enumerate(values):  # the count, so that a probability of 0 (no bar) is read as "0 of n"
        axes[1].annotate(f"{p:.3g} ({round(p * n)}/{n})", (k, p), textcoords="offset points", xytext=(12, 4),
                         fontsize=9)
    axes[1].set_ylabel("probability (95 % Wilson interval)")
    axes[1].set_ylim(0, max(0.05, max(hi for _, hi in (summary[k]["ci95_wilson"] for k in ("contact_loss", "pull_in"))) * 1.2))
    axes[1].set_title(f"{len(d['case'])} samples")
    fig.tight_layout()
    export.save_figure(fig, path, dpi=110)  # atomic: never a half-written png
    return path


def basins(spec: Spec, d: dict, result: dict, path: Path) -> Path:
    x0, v0 = np.array(spec.axis("x0")), np.array(spec.axis("v0"))
    grid = np.full((len(x0), len(v0)), np.nan)
    grid[d["i"], d["j"]] = result["measured"]
    fig, ax = plt.subplots(figsize=(8, 7.5), layout="constrained")
    cmap = matplotlib.colors.ListedColormap(["0.6", "C0", "C3"])
    dx, dv = (x0[1] - x0[0] if len(x0) > 1 else 1) / 2, (v0[1] - v0[0] if len(v0) > 1 else 1) / 2
    ax.imshow(grid.T, origin="lower", extent=[x0[0] - dx, x0[-1] + dx, v0[0] - dv, v0[-1] + dv], cmap=cmap,
              vmin=-1.5, vmax=1.5, aspect="auto", interpolation="nearest")
    agreement = result["summary"]["agreement"]
    margin = agreement["margin"]
    wrong = (result["measured"] != result["predicted"])
    far = np.asarray(result["distance"]) > margin
    ax.plot(d["x_start"][wrong & far], d["v_start"][wrong & far], "kx", ms=6, mew=1.5,
            label=(f"run differs from the averaged prediction (counted: farther than {margin:g} from the boundary)"
                   if np.any(wrong & far) else None))
    ax.plot(d["x_start"][wrong & ~far], d["v_start"][wrong & ~far], "P", mfc="w", mec="k", ms=9, mew=0.8,
            label=f"run differs, within {margin:g} of the boundary (not counted)" if np.any(wrong & ~far) else None)
    for k, branch in enumerate(result["boundary"]):
        ax.plot(branch[:, 0], branch[:, 1], "k-", lw=1.2, label="predicted boundary (saddle's stable manifold)" if k == 0 else None)
    stable = result["stable"]
    names = ["low-amplitude vibration", "high-amplitude vibration"]
    for k, colour in enumerate(("C0", "C3")):  # legend entries for the colours the map shows (gid: the value)
        if k < len(stable) and np.any(result["measured"] == k):
            ax.plot([], [], "s", color=colour, label=f"runs reach {names[k]} ($r$ = {stable[k].r:.3f})",
                    gid=f"image value {k}")
    if np.any(result["measured"] == -1):
        ax.plot([], [], "s", color="0.6", label="unsettled / other", gid="image value -1")
    ax.set_xlim(x0[0] - dx, x0[-1] + dx)
    ax.set_ylim(v0[0] - dv, v0[-1] + dv)
    ax.set_xlabel(r"initial displacement $x_0$")
    ax.set_ylabel(r"initial velocity $v_0$")
    everywhere = agreement.get("by_margin", {}).get("0") or {}
    overall = (f"all points: {everywhere['agreeing']}/{everywhere['compared']} agree"
               if everywhere else "")
    ax.set_title(f"basins at $\\omega$ = {result['omega']:.6f}, $\\mu$ = {spec.base_scene().mu:g}\n"
                 f"{overall}; farther than {margin:g} from the predicted boundary: "
                 f"{agreement['agreeing']}/{agreement['compared']} agree ({agreement['fraction']:.3f})", fontsize=9)
    fig.legend(*ax.get_legend_handles_labels(), fontsize=7, loc="outside lower center", ncols=2, frameon=False)
    export.save_figure(fig, path, dpi=110)  # atomic: never a half-written png
    return path


def response_map(result: dict, path: Path) -> Path:
    omegas, deltas = result["omegas"], result["deltas"]
    fig, axes = plt.subplots(1, 3, figsize=(16, 5), sharey=True, layout="constrained")
    dw = (omegas[1] - omegas[0]) / 2 if len(omegas) > 1 else 1e-4
    dd = (deltas[1] - deltas[0]) / 2 if len(deltas) > 1 else 1e-5
    extent = [omegas[0] - dw, omegas[-1] + dw, deltas[0] - dd, deltas[-1] + dd]
    vmax = np.nanmax([np.nanmax(result["r"]["up"]), np.nanmax(result["r"]["down"])])
    for ax, direction in zip(axes[:2], ("up", "down")):
        image = ax.imshow(result["r"][direction], origin="lower", extent=extent, aspect="auto", vmin=0, vmax=vmax,
                          interpolation="nearest", cmap="viridis")
        ax.set_title(f"settled amplitude $r$, sweep {direction}")
    fig.colorbar(image, ax=axes[:2], shrink=0.85, label="$r$")
    code = np.where(result["measured"], 1.0, 0.0) + np.where(result["predicted"], 2.0, 0.0)
    cmap = matplotlib.colors.ListedColormap(["white", "C1", "C0", "C2"])
    axes[2].imshow(code, origin="lower", extent=extent, aspect="auto", cmap=cmap, vmin=-0.5, vmax=3.5,
                   interpolation="nearest")
    if result.get("test_mask") is not None:
        kept = np.argwhere(result["test_mask"])
        axes[2].plot(omegas[kept[:, 1]], deltas[kept[:, 0]], "k+", ms=5, label="bistable by the two-start test")
    near = np.argwhere(result["near"])
    axes[2].plot(omegas[near[:, 1]], deltas[near[:, 0]], ".", color="0.5", ms=3,
                 label="within the fold margin (not counted)")
    for value, label, colour in ((1, "bistable: runs only", "C1"), (2, "bistable: slow flow only", "C0"),
                                 (3, "bistable: both", "C2")):
        if np.any(code == value):  # a legend entry for the colours the map shows (gid: the image value it names)
            axes[2].plot([], [], "s", color=colour, label=label, gid=f"image value {value}")
    axes[2].set_title("bistability: runs vs slow flow")
    for ax in axes:
        for side, style in ((0, "w--"), (-1, "w-")):
            points = [(f[side].omega, delta) for f, delta in zip(result["folds"], deltas) if len(f) >= 2]
            if points:
                w, dl = zip(*points)
                ax.plot(w, dl, style if ax is not axes[2] else style.replace("w", "k"), lw=1.2,
                        label="slow-flow folds" if side == 0 else None)
        if result["cusp"]:
            ax.plot(result["cusp"]["omega"], result["cusp"]["Delta"], "r*", ms=12, label="cusp (slow flow)")
        if result["run_cusp"]:
            ax.plot(result["run_cusp"]["omega"], result["run_cusp"]["first_bistable_Delta"], "mP", ms=9,
                    label="first bistable row (runs)")
        extrapolation = result.get("extrapolation") or {}
        for key, style, label in (("runs_sweeps", "ms", "cusp extrapolated (runs' sweeps)"),
                                  ("runs_two_start_test", "kD", "cusp extrapolated (two-start test)")):
            e = extrapolation.get(key)
            if e:
                ax.errorbar(e["omega"], e["Delta"], xerr=e["omega_stderr"], yerr=e["Delta_stderr"], fmt=style,
                            ms=6, mfc="none", capsize=3, label=label)
        ax.set_xlabel(r"forcing frequency $\omega$")
        ax.xaxis.set_major_locator(MaxNLocator(nbins=4))  # labels like 0.9975 need room: four at most per panel
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
    axes[0].set_ylabel(r"load amplitude $\Delta$")
    axes[2].legend(fontsize=7, loc="lower left")
    agreement = result["summary"]["agreement"]
    # the cells shown that differ but are not counted (within the margin, or a sweep that did not settle): said in
    # the title, so that a "runs only" cell never sits under an agreement of 1.000 unexplained
    uncounted = int(np.sum((result["measured"] != result["predicted"]) & result["near"]))
    fig.suptitle(f"response map: bistability agreement {agreement['fraction']:.3f} "
                 f"({agreement['agreeing']}/{agreement['compared']} points off the folds' margin"
                 + (f"; {uncounted} within the margin differ, not counted)" if uncounted else ")"))
    export.save_figure(fig, path, dpi=110)  # atomic: never a half-written png
    return path
