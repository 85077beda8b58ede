"""What `vibrofmu continuation` writes: branch.parquet, branch.png, and the two-parameter chart (chart.parquet,
chart.png, the slow-flow vs exact fold table) of docs/continuation.md."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Callable

import numpy as np
import pyarrow as pa
from scipy.optimize import brentq

from vibromodel import averaging as av
from vibromodel.parameters import Scene

from vibrofmu.analyses import continuation as cont
from vibrofmu.analyses import curves as two
from vibrofmu.output.export import legend_below, save_plot, parameter_label, plt, write_json, write_parquet, wrapped

EVENT_MARKERS = {"fold": ("s", "tab:red"), "period-doubling": ("D", "tab:purple"),
                 "neimark-sacker": ("*", "tab:olive"), "grazing": ("o", "tab:orange")}


def write_branch(path: Path, result: cont.Branch) -> None:
    """branch.parquet: one row per orbit (continuation.COLUMNS); in the schema's metadata (key b'vibrofmu', JSON)
    the fixed parameters ("scene", without the continued one), the continued one ("param", and "continued":
    its name and range as run) and why each branch stopped."""
    table = pa.Table.from_pylist(cont.rows(result))
    param = result.problem.param
    values = [pt.p for pt in result.points]
    fixed = {k: v for k, v in result.problem.scene.as_dict().items() if k != param}
    meta = {"scene": fixed, "param": param,
            "continued": {"param": param, "from": values[0] if values else None,
                          "to": values[-1] if values else None},
            "stop_reasons": [br.stop_reason for br in [result, *result.doubled]],
            "columns": "see docs/continuation.md, branch.parquet"}
    table = table.replace_schema_metadata({b"vibrofmu": json.dumps(meta).encode()})
    write_parquet(table, path)


def _segments(values, flags):
    """Runs of consecutive equal flags: (start, stop, flag), stop exclusive, each run sharing its end point
    with the next so that the line is unbroken."""
    runs, start = [], 0
    for i in range(1, len(flags) + 1):
        if i == len(flags) or flags[i] != flags[start]:
            runs.append((start, min(i + 1, len(values)), flags[start]))
            start = i
    return runs


# one colour per branch along a cascade (T, 2T, ..., 64T and more), none the event markers' (purple, orange)
BRANCH_COLOURS = ["k", "tab:blue", "tab:green", "tab:cyan", "tab:brown", "tab:olive", "tab:pink", "tab:gray", "tab:red"]


def plot_branch(path: Path, result: cont.Branch, title: str) -> None:
    """Amplitude (x_max - x_min)/2, x_min and the Floquet multipliers' moduli against the parameter: stable
    solid, unstable dashed, events marked (one marker per kind, in the legend), doubled branches in their own
    colour, the contact edge x = -3/2 drawn on the x_min panel, the unit circle |rho| = 1 on the multiplier
    panel, a branch stopped short marked by a red cross, one that ends at pull-in (every step beyond its last orbit
    met an electrode) by a red triangle pointing down. PNG, and PDF beside it."""
    fig, axes = plt.subplots(3, 1, figsize=(8, 9.5), sharex=True, layout="constrained",
                             gridspec_kw={"height_ratios": [3, 2, 2]})
    seen = set()
    for index, (br, color) in enumerate(zip([result, *result.doubled], BRANCH_COLOURS * 4)):
        pts = [pt for pt in br.points]
        if not pts:
            continue
        p = np.array([pt.p for pt in pts])
        amp = np.array([(pt.x_max - pt.x_min) / 2 for pt in pts])
        x_min = np.array([pt.x_min for pt in pts])
        rho = np.array([np.abs(pt.multipliers) for pt in pts])
        stable = [pt.stable for pt in pts]
        name = "period-T branch" if index == 0 else f"doubled branch {index} (period {br.problem.periods}T)"
        for start, stop, flag in _segments(p, stable):
            style = "-" if flag else "--"
            label = f"{name}, {'stable' if flag else 'unstable'}"
            show = label not in seen
            seen.add(label)
            axes[0].plot(p[start:stop], amp[start:stop], style, color=color, lw=1.4, label=label if show else None)
            axes[1].plot(p[start:stop], x_min[start:stop], style, color=color, lw=1.4)
            for k in range(2):
                axes[2].plot(p[start:stop], rho[start:stop, k], style, color=color, lw=1.0 if k else 1.4)
        for pt in pts:
            if pt.event:
                marker, c = EVENT_MARKERS[pt.event]
                show = pt.event not in seen
                seen.add(pt.event)
                axes[0].plot(pt.p, (pt.x_max - pt.x_min) / 2, marker, color=c, ms=7, mfc="none", mew=1.6,
                             label=pt.event if show else None)
                axes[1].plot(pt.p, pt.x_min, marker, color=c, ms=7, mfc="none", mew=1.6)
                axes[2].plot(pt.p, np.max(np.abs(pt.multipliers)), marker, color=c, ms=7, mfc="none", mew=1.6)
        if br.stop_reason.startswith("pull-in"):  # an end of the branch, not a sample: the next orbit meets an electrode
            last = pts[-1]
            label = "pull-in beyond the branch's end"
            show = label not in seen
            seen.add(label)
            axes[0].plot(last.p, (last.x_max - last.x_min) / 2, "v", color="k", ms=10, mfc="tab:red",
                         label=label if show else None, zorder=5)
            axes[1].plot(last.p, last.x_min, "v", color="k", ms=10, mfc="tab:red", zorder=5)
        elif br.stop_reason and not br.stop_reason.startswith(("reached", "left")):
            last = pts[-1]
            label = "branch stopped short (point budget or step)"
            show = label not in seen
            seen.add(label)
            axes[0].plot(last.p, (last.x_max - last.x_min) / 2, "X", color="tab:red", ms=10,
                         label=label if show else None)
            axes[1].plot(last.p, last.x_min, "X", color="tab:red", ms=10)
    axes[1].axhline(cont.CONTACT_EDGE, color="tab:orange", lw=0.8, ls=":")
    axes[1].annotate("contact edge 1 + 2x/3 = 0", (0.01, cont.CONTACT_EDGE), xycoords=("axes fraction", "data"),
                     fontsize=8, color="tab:orange", xytext=(0, 3), textcoords="offset points")
    axes[0].set_ylabel(r"amplitude $(x_{max} - x_{min})/2$")
    axes[1].set_ylabel(r"$x_{min}$ over the orbit")
    axes[2].axhline(1.0, color="0.4", lw=0.8, ls=":")
    axes[2].set_yscale("log")
    axes[2].set_ylabel(r"multipliers $|\rho_1|$, $|\rho_2|$")
    axes[2].set_xlabel(parameter_label(result.problem.param))
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.suptitle(wrapped(title, fig.get_figwidth(), 11), fontsize=11)
    legend_below(fig, [axes[0]], columns=2)
    save_plot(fig, path, vector=True)


# ----- the two-parameter chart in (omega, Delta) -------------------------------------------------------------

# A slow-flow fold "holds" when its frequency is within this fraction of the damping width mu of the exact
# fold: the resonance peak's half-width is mu/2, so an error of 0.1 mu is a tenth of what a sweep resolves
HOLDS = 0.1


def slow_flow_folds(scene: Scene, samples: int = 801) -> list[av.Fold]:
    """The slow flow's folds (det J = 0) on its frequency-response curve, traced through the peak.

    averaging.folds traces the curve by r on each side of the backbone separately, up to r_peak (1 - 1e-9): a
    fold closer to the peak than its last sample (at large Delta/mu the upper fold sits within ~1e-4 of r_peak)
    is missed. Here the curve is one smooth parameter: the steady states satisfy (mu/2)^2 + nu^2 = (drive/r)^2,
    so mu/2 = (drive/r) cos theta, nu = (drive/r) sin theta, theta in (-pi/2, pi/2), through the peak at theta = 0:
    for each theta, omega solves detuning(omega) - kappa(r) = (mu/2) tan theta with r = 2 drive(omega) cos theta / mu
    (Brent), and the sign changes of det J along theta are located by Brent. Orbits beyond the contact edge
    (r >= r_max) are left out: the averaged model does not reach them."""
    from scipy.optimize import brentq

    model = av.averaged(scene)
    if scene.Delta == 0.0 or scene.mu <= 0.0:
        return []
    mu = scene.mu

    def omega_of(theta):
        def mismatch(omega):
            flow = model.flow(omega)
            r = 2.0 * flow.drive * math.cos(theta) / mu
            return flow.detuning - model.backbone.kappa(r) - 0.5 * mu * math.tan(theta)

        centre = model.omega_e
        width = 0.05 * centre
        for _ in range(40):
            lo, hi = max(centre - width, 1e-6), centre + width
            if mismatch(lo) * mismatch(hi) < 0.0:
                return brentq(mismatch, lo, hi, xtol=1e-15, rtol=1e-15)
            width *= 1.5
        return None

    def state(theta):
        omega = omega_of(theta)
        if omega is None:
            return None, None
        flow = model.flow(omega)
        r = 2.0 * flow.drive * math.cos(theta) / mu
        return omega, av.steady_state(flow, r)

    def det(theta):
        return state(theta)[1].det

    # theta near +-pi/2 is far from resonance (r -> 0); tan theta's range is covered uniformly in arctan
    thetas = np.arctan(np.sinh(np.linspace(-12.0, 12.0, samples)))
    values = []
    for theta in thetas:
        omega, st = state(theta)
        values.append(math.nan if st is None or st.r >= model.r_max else st.det)
    found = []
    for t0, t1, d0, d1 in zip(thetas, thetas[1:], values, values[1:]):
        if d0 * d1 < 0.0:
            theta = brentq(det, t0, t1, xtol=1e-15)
            omega, st = state(theta)
            found.append(av.Fold(omega, st.r, -1 if theta > 0 else 1))
    return sorted(found, key=lambda fold: fold.omega)


def slow_flow_cusp_point(scene: Scene) -> dict | None:
    """(omega, Delta, r) of the slow flow's cusp, without sampling: its steady states are s (mu^2/4 + u^2) = d^2 with
    s = r^2, u = D - k(s), k(s) = kappa2 s + kappa4 s^2 (the backbone), D = (omega^2 - k1) / (2 omega), d = Delta /
    (2 omega); the cusp is a triple root in s: F_ss = 0 gives u = s k'^2 / (2 k' + s k''), then F_s = mu^2/4 + u^2 -
    2 s u k' = 0 is one equation in s, bracketed around its kappa4 = 0 root mu / (sqrt 3 |kappa2|) and solved by
    Brent; D = u + k(s), omega = D + sqrt(D^2 + k1), Delta = 2 omega sqrt(s (mu^2/4 + u^2)). None without a cubic
    backbone term or damping (no cusp)."""
    model = av.averaged(scene)
    k1, mu = model.eq.k[1], scene.mu
    k2, k4 = model.backbone.kappa2, model.backbone.kappa4
    if k2 == 0.0 or mu <= 0.0:
        return None

    def u_of(s):
        kp = k2 + 2 * k4 * s
        return s * kp * kp / (2 * kp + 2 * k4 * s)

    def fold(s):
        u = u_of(s)
        return mu * mu / 4 + u * u - 2 * s * u * (k2 + 2 * k4 * s)

    s0 = mu / (math.sqrt(3.0) * abs(k2))
    if fold(0.5 * s0) * fold(2.0 * s0) > 0.0:
        return None
    s = brentq(fold, 0.5 * s0, 2.0 * s0, xtol=1e-16 * s0, rtol=1e-15)
    u = u_of(s)
    D = u + k2 * s + k4 * s * s
    omega = D + math.sqrt(D * D + k1)
    return {"omega": omega, "Delta": 2 * omega * math.sqrt(s * (mu * mu / 4 + u * u)), "r": math.sqrt(s)}


def slow_flow_cusp(scene: Scene, lo: float, hi: float) -> float | None:
    """The smallest Delta in [lo, hi] with slow-flow folds (the cusp's, slow_flow_cusp_point, or lo beyond it), None
    if there is none in the range."""
    cusp = slow_flow_cusp_point(scene)
    if cusp is None or cusp["Delta"] > hi:
        return None
    return max(lo, cusp["Delta"])


def omega_window(scene: Scene) -> tuple[float, float]:
    """Where the primary resonance's branch is continued: from below the slow flow's softened peak (its
    backbone at the contact edge) to 3 mu above omega_e, and never below 0.5 omega_e."""
    model = av.averaged(scene)
    w = model.omega_e
    r_peak = min(scene.Delta / (scene.mu * w), model.r_max)
    shift = abs(model.backbone.kappa(r_peak))
    return max(0.5 * w, w - 1.5 * shift - 3 * scene.mu), w + 3 * scene.mu


def chart_row(scene: Scene, points: int, rtol: float = cont.RTOL) -> dict:
    """Exact events of the omega-branch at this Delta beside the slow flow's folds, and the verdict:
    'holds' (same number of folds, each within HOLDS mu), 'quantitatively off' (same number, some further),
    'qualitatively wrong' (a different number of folds, or contact lost at an exact fold)."""
    lo, hi = omega_window(scene)
    result = cont.branch(scene, "omega", lo, hi, points=points, rtol=rtol)
    exact = sorted([pt for pt in result.points if pt.event == "fold"], key=lambda pt: pt.p)
    slow = slow_flow_folds(scene)
    events = {name: [pt.p for pt in result.points if pt.event == name] for name in cont.EVENTS}
    for br in result.doubled:
        events["period-doubling"] += [pt.p for pt in br.points if pt.event == "period-doubling"]
    # each slow-flow fold against the nearest exact one (also when the counts differ: the fold that the slow
    # flow does have may still be right while the other has moved beyond contact loss)
    errors = [min((e.p - f.omega for e in exact), key=abs) for f in slow] if exact else []
    contact = any(pt.x_min < cont.CONTACT_EDGE for pt in exact)
    if len(exact) != len(slow) or contact:
        verdict = "qualitatively wrong"
    elif all(abs(e) <= HOLDS * scene.mu for e in errors):
        verdict = "holds"
    else:
        verdict = "quantitatively off"
    return {"Delta": scene.Delta, "omega_lo": lo, "omega_hi": hi, "points": len(result.points),
            "seconds": result.seconds,
            "exact_folds": [pt.p for pt in exact], "exact_fold_amplitudes": [(pt.x_max - pt.x_min) / 2 for pt in exact],
            "exact_fold_contact_lost": [bool(pt.x_min < cont.CONTACT_EDGE) for pt in exact],
            "slow_folds": [f.omega for f in slow], "slow_fold_amplitudes": [f.r for f in slow],
            "fold_errors": errors, "fold_errors_in_mu": [e / scene.mu for e in errors],
            "grazing": events["grazing"], "period_doubling": events["period-doubling"],
            "neimark_sacker": events["neimark-sacker"], "verdict": verdict,
            "why": ("no fold in either: one stable orbit per frequency in both" if not exact and not slow else
                    f"{len(slow)} slow-flow folds, {len(exact)} exact" if len(exact) != len(slow) else
                    "contact lost at an exact fold: beyond the slow flow's model" if contact else
                    f"largest fold error {max(abs(e) for e in errors) / scene.mu:.3g} mu (threshold {HOLDS:g} mu)")}


def chart(scene: Scene, deltas, points: int, progress: Callable[[str], None] | None = None) -> dict:
    rows = []
    for delta in deltas:
        row = chart_row(scene.with_values(Delta=float(delta)), points)
        rows.append(row)
        if progress is not None:
            progress(f"chart: Delta = {delta:.4g}: {len(row['exact_folds'])} exact folds, "
                     f"{len(row['slow_folds'])} slow-flow folds, {len(row['grazing'])} grazing: {row['verdict']}")
    fine = np.geomspace(min(deltas), max(deltas), 60)
    slow_curve = [{"Delta": float(d), "folds": [f.omega for f in slow_flow_folds(scene.with_values(Delta=float(d)))]}
                  for d in fine]
    cusp = slow_flow_cusp(scene, float(min(deltas)), float(max(deltas)))
    return {"scene": scene.as_dict(), "rows": rows, "slow_flow_curve": slow_curve, "slow_flow_cusp_Delta": cusp,
            "holds_threshold_in_mu": HOLDS}


def write_chart(out: Path, data: dict, curves: two.Curves | None = None) -> None:
    """chart.parquet, chart.json, chart.png (and chart.pdf); `curves` (continued in (omega, Delta)) drawn too."""
    flat = [{k: (json.dumps(v) if isinstance(v, list) else v) for k, v in row.items()} for row in data["rows"]]
    write_parquet(pa.Table.from_pylist(flat), out / "chart.parquet")
    write_json(out / "chart.json", data)
    plot_chart(out / "chart.png", data, curves)


VERDICT_COLORS = {"holds": "#d9f2d9", "quantitatively off": "#fff2cc", "qualitatively wrong": "#f8d7da"}


def plot_chart(path: Path, data: dict, curves: two.Curves | None = None) -> None:
    """The (omega, Delta) plane: rows shaded by verdict, the slow flow's folds and cusp, each row's exact events,
    and with `curves` (continued in (omega, Delta), --follow) the continued curves and their codimension-two points
    (the exact cusp among them). PNG, and PDF beside it."""
    fig, ax = plt.subplots(figsize=(8, 6.5), layout="constrained")
    rows = data["rows"]
    deltas = [r["Delta"] for r in rows]
    edges = np.sqrt(np.array(deltas[:-1]) * np.array(deltas[1:])) if len(deltas) > 1 else np.array([])
    lows = np.concatenate([[deltas[0] / 1.2], edges])
    highs = np.concatenate([edges, [deltas[-1] * 1.2]])
    for row, a, b in zip(rows, lows, highs):
        ax.axhspan(a, b, color=VERDICT_COLORS[row["verdict"]], zorder=0)
    for verdict, color in VERDICT_COLORS.items():
        ax.fill_between([], [], color=color, label=f"averaging {verdict}")
    curve = data["slow_flow_curve"]
    xs = [w for c in curve for w in c["folds"]]
    ys = [c["Delta"] for c in curve for _ in c["folds"]]
    ax.plot(xs, ys, ".", color="tab:blue", ms=4, label="slow-flow folds")  # dots: the count changes along Delta
    cusp = slow_flow_cusp_point(Scene(**data["scene"]))
    if data["slow_flow_cusp_Delta"] and cusp is not None and cusp["Delta"] == data["slow_flow_cusp_Delta"]:
        ax.plot(cusp["omega"], cusp["Delta"], "^", color="tab:blue", mec="w", ms=8, label="slow-flow cusp",
                zorder=6)  # above the exact cusp's star, which lies close to it
    for key, marker, color, label in (("exact_folds", "s", "tab:red", "exact folds"),
                                      ("grazing", "o", "tab:orange", "exact grazing (contact first lost)"),
                                      ("period_doubling", "D", "tab:purple", "exact period doubling")):
        xs = [w for r in rows for w in r[key]]
        ys = [r["Delta"] for r in rows for _ in r[key]]
        if xs:
            ax.plot(xs, ys, marker, color=color, mfc="none", mew=1.5, ms=6, label=label)
    if curves is not None and curves.params == ("omega", "Delta"):
        draw_curves(ax, curves, set(), label="continued {kind} curve")
    ax.set_yscale("log")
    ax.set_xlabel(r"forcing frequency $\omega$")
    ax.set_ylabel(r"forcing amplitude $\Delta$")
    ax.grid(True, alpha=0.3, which="both")
    s = data["scene"]
    fig.suptitle(wrapped(f"where the averaged (slow-flow) predictions hold: exact folds, grazing and period "
                         f"doubling beside the slow flow's folds ($\\mu$ = {s['mu']:g}, $R$ = {s['R']:g})",
                         fig.get_figwidth(), 11), fontsize=11)
    legend_below(fig, [ax], columns=3)
    save_plot(fig, path, vector=True)


def agreement_table(data: dict) -> list[str]:
    """Markdown rows: Delta, slow-flow folds, exact folds, errors in units of mu, contact at the exact fold, verdict."""
    lines = ["| Δ | slow-flow folds ω | exact folds ω | error / μ (nearest) | contact lost at exact fold "
             "| verdict |",
             "|---|---|---|---|---|---|"]
    for r in data["rows"]:
        def fmt(values, spec=".6f"):
            return ", ".join(format(v, spec) for v in values) or "—"
        lines.append(f"| {r['Delta']:.4g} | {fmt(r['slow_folds'])} | {fmt(r['exact_folds'])} | "
                     f"{fmt(r['fold_errors_in_mu'], '+.3f')} | "
                     f"{', '.join('yes' if c else 'no' for c in r['exact_fold_contact_lost']) or '—'} | "
                     f"{r['verdict']}: {r['why']} |")
    return lines


# ----- two-parameter curves (--follow) ------------------------------------------------------------------------

CURVE_STYLE = {"fold": ("-", "tab:red"), "period-doubling": ("--", "tab:purple"), "grazing": ("-.", "tab:orange")}
# the curves of a doubled branch's orbits: a dash pattern per period (the colour stays the kind's)
DOUBLED_DASHES = {2: ":", 4: (0, (6, 2, 1, 2, 1, 2)), 8: (0, (1, 4))}
# one marker per codimension-two point (curves.CODIM2; a grazing one hollow: the curve is seen through it)
CODIM2_MARKERS = {"cusp": ("*", "k"), "grazing-fold": ("P", "tab:brown"), "grazing-flip": ("D", "tab:green"),
                  "fold-flip": ("s", "tab:cyan")}


def write_curves(out: Path, curves: two.Curves, scene: Scene, title: str) -> None:
    """curves.parquet (one row per point: curves.rows; the scene and the parameters in the metadata),
    curves.png and curves.pdf."""
    p1, p2 = curves.params
    table = pa.Table.from_pylist(two.rows(curves)) if curves.curves else pa.table(
        {name: pa.array([], type=pa.float64()) for name in ("curve", p1, p2, "x0", "v0", "period", "x_min", "x_max")})
    fixed = {k: v for k, v in scene.as_dict().items() if k not in (p1, p2)}
    meta = {"scene": fixed, "params": [p1, p2], "stop_reasons": [c.stop_reason for c in curves.curves],
            "columns": "see docs/continuation.md, curves.parquet"}
    write_parquet(table.replace_schema_metadata({b"vibrofmu": json.dumps(meta).encode()}), out / "curves.parquet")
    plot_curves(out / "curves.png", curves, scene, title)


def plot_curves(path: Path, curves: two.Curves, scene: Scene, title: str) -> None:
    """The curves in the (p1, p2) plane, the codimension-two points marked; in (omega, Delta) the slow flow's
    cusp beside the exact one. PNG and PDF."""
    p1, p2 = curves.params
    fig, ax = plt.subplots(figsize=(7.5, 6), layout="constrained")
    seen: set = set()
    draw_curves(ax, curves, seen)
    if (p1, p2) == ("omega", "Delta") and any(pt.event == "cusp" for c in curves.curves for pt in c.points):
        slow = slow_flow_cusp_point(scene)
        if slow is not None:
            ax.plot(slow["omega"], slow["Delta"], "^", color="tab:blue", ms=9, mec="w",
                    label="slow flow's cusp (averaging)", zorder=6)
    ax.set_xlabel(parameter_label(p1))
    ax.set_ylabel(parameter_label(p2))
    ax.grid(True, alpha=0.3)
    fig.suptitle(wrapped(title, fig.get_figwidth(), 11), fontsize=11)
    legend_below(fig, [ax], columns=2)
    save_plot(fig, path, vector=True)


def draw_curves(ax, curves: two.Curves, seen: set, label: str = "{kind} curve") -> None:
    """Each curve in its kind's style, its codimension-two points (one marker per kind, in the legend) and a curve
    stopped by its point budget marked at its end."""
    for curve in curves.curves:
        style, color = CURVE_STYLE[curve.kind]
        periods = curve.points[0].periods if curve.points else 1
        name = curve.kind if periods == 1 else f"{curve.kind} (period-{periods}T orbits)"
        if periods > 1:  # a doubled branch's curve: in its kind's colour, a dash pattern per period, thinner
            style = DOUBLED_DASHES.get(periods, ":")
        ax.plot([pt.p1 for pt in curve.points], [pt.p2 for pt in curve.points], color=color,
                ls=style, lw=1.5 if periods == 1 else 1.2, label=label.format(kind=name) if name not in seen else None)
        seen.add(name)
        for pt in curve.points:
            if pt.event:
                marker, c = CODIM2_MARKERS.get(pt.event, ("o", "k"))
                ax.plot(pt.p1, pt.p2, marker, color=c, ms=12, mfc="none" if pt.event.startswith("grazing-") else c,
                        mew=1.8, label=pt.event if pt.event not in seen else None, zorder=5)
                seen.add(pt.event)
        for last, why in curve.ends or [(curve.points[-1], curve.stop_reason)]:
            if why.startswith("pull-in"):  # creeping towards an electrode: an end, drawn as the branch's pull-in
                ax.plot(last.p1, last.p2, "v", color="k", ms=10, mfc="tab:red", zorder=5,
                        label="curve ends creeping towards pull-in" if "pull-in" not in seen else None)
                seen.add("pull-in")
            elif "stopped at" in why or why.startswith("step below"):
                ax.plot(last.p1, last.p2, "X", color="tab:red", ms=9,
                        label="curve stopped (point budget or step)" if "stop" not in seen else None)
                seen.add("stop")


def curves_summary(curves: two.Curves) -> list[dict]:
    p1, p2 = curves.params
    return [{"kind": c.kind, "curve": c.index, "periods": c.points[0].periods if c.points else 1,
             "points": len(c.points), "stop_reason": c.stop_reason,
             "events": [{"event": pt.event, p1: pt.p1, p2: pt.p2, "x0": float(pt.z0[0]), "v0": float(pt.z0[1])}
                        for pt in c.points if pt.event]} for c in curves.curves]


def curves_lines(curves: two.Curves) -> list[str]:
    p1, p2 = curves.params
    lines = []
    for c in curves.curves:
        periods = c.points[0].periods if c.points else 1
        of = f" of period-{periods}T orbits" if periods > 1 else ""
        lines.append(f"{c.kind} curve {c.index}{of}: {len(c.points)} points ({c.stop_reason})")
        lines += [f"  {pt.event} at {p1} = {pt.p1:.10g}, {p2} = {pt.p2:.10g}" for pt in c.points if pt.event]
    return lines
