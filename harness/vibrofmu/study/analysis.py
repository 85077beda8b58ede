"""The averaged (slow-flow) predictions of each kind, the agreement of the runs with them, the summary
numbers, and the throughput projection.

- response-map: bistable where the slow flow has two stable steady states (vibromodel.averaging); the runs
  are bistable where the up and down sweeps settle on different branches (sweep.hysteresis_jumps' rule,
  with BRANCHES_APART).
  Points nearer a slow-flow fold than stability.sweep_tolerance (one omega step + the ghost margin of the
  longest wait) are not compared. The cusp: the smallest Delta with two folds, by bisection (slow flow), the
  first Delta row with a bistable point (runs), and the estimates of study.cusp (extrapolation of the bistable
  bands of the runs and of the slow flow; the two-start test's bracket when it ran).
- basins: which stable steady state each initial state reaches, against the averaged model's run from it
  (cases.predicted_attractor); the predicted boundary is the stable manifold of the slow flow's saddle,
  traced backwards in (A, B) and mapped to (x0, v0) by the averaged model's reconstruction of x, x'.
- monte-carlo: amplitude statistics, probabilities of contact loss and pull-in with Wilson intervals, and
  the settled amplitude against the slow flow's stable branch at each sample.
"""
from __future__ import annotations

import math

import numpy as np

from vibromodel import averaging as av

from vibrofmu.analyses.stability import sweep_tolerance
from vibrofmu.analyses.sweep import SETTLE_TOLERANCE, Sweep, SweepPoint, hysteresis_jumps
from vibrofmu.study.spec import Spec

Z95 = 1.959963984540054  # two-sided 95 % normal quantile
# response map: up and down amplitudes farther apart than this are on different branches. Each settled
# amplitude is within SETTLE_TOLERANCE (3 %) of its steady state, so two runs at one state differ by up to
# 6 %; below the cusp (one state) they differed by up to 9.2 % at Delta = 0.0004 with the AC drive on and
# 5.4 % with it off (Omega = 2 near 2 omega adds a slow beat the averaged model leaves out): 10 % is above
# both. The branches of the bistable band differ by 25 % and more (50 % at Delta = 0.0007).
BRANCHES_APART = 0.10
BASIN_MARGIN = 0.03  # basins: compared only farther than this from the predicted boundary in (x0, v0/omega)


def wilson(k: int, n: int) -> list[float]:
    """95 % Wilson score interval of a proportion k/n."""
    if n == 0:
        return [math.nan, math.nan]
    p = k / n
    centre = (p + Z95**2 / (2 * n)) / (1 + Z95**2 / n)
    half = Z95 * math.sqrt(p * (1 - p) / n + Z95**2 / (4 * n * n)) / (1 + Z95**2 / n)
    return [0.0 if k == 0 else max(0.0, centre - half), 1.0 if k == n else min(1.0, centre + half)]


def projection(run: dict, workers: int) -> dict:
    """Cases per second on `workers` workers from the measured cost per case c_w and the scheduler's cost per
    task c_s at batch size b: each worker does b cases per b c_w + c_s seconds, and the scheduler, serial,
    hands out at most 1/c_s tasks per second: min(W b / (b c_w + c_s), b / c_s)."""
    c_w, c_s = run.get("case_cost_s_mean", math.nan), run.get("scheduler_s_per_task", math.nan)
    if not (c_w > 0 and c_s > 0):
        return {}
    from vibrofmu.study.scheduling import needed_batch

    b_needed = needed_batch(c_s, c_w, workers)
    out = {"workers": workers, "case_cost_s": c_w, "scheduler_s_per_task": c_s}
    for label, b in (("at_this_batch_size", run["batch_size"]), ("at_the_batch_size_for_these_workers", b_needed)):
        worker_bound, scheduler_bound = workers * b / (b * c_w + c_s), b / c_s
        out[label] = {"batch_size": b, "cases_per_s": min(worker_bound, scheduler_bound),
                      "worker_bound": worker_bound, "scheduler_bound": scheduler_bound}
    out["derivation"] = "min(W b / (b c_w + c_s), b / c_s): W workers each b c_w + c_s per task; one scheduler"
    return out


def _usable(table) -> np.ndarray:
    return ~(table["pull_in"] | table["failed"])


def analyse(spec: Spec, table, tests: list[dict] | None = None) -> dict:
    data = {name: np.asarray(table.column(name).to_pylist()) for name in table.column_names}
    if spec.kind == "monte-carlo":
        return monte_carlo(spec, data)
    if spec.kind == "basins":
        return basins(spec, data)
    return response_map(spec, data, tests)


# --- monte-carlo -------------------------------------------------------------------------------------

def monte_carlo(spec: Spec, d: dict) -> dict:
    n = len(d["case"])
    usable = _usable(d) & d["settled"]
    r = d["r"][usable]
    predicted, agree, ambiguous, notes = np.full(n, np.nan), 0, 0, 0
    base = spec.base_scene()
    for i in np.flatnonzero(usable):
        scene = base.with_values(**{name: float(d[name][i]) for name in spec.tolerances})
        model = av.averaged(scene)
        notes += bool(av.validity_notes(model))
        stable = [s.r for s in av.steady_states(model.flow(), model.r_max) if s.stable]
        if not stable:
            continue
        ambiguous += len(stable) > 1
        predicted[i] = min(stable, key=lambda value: abs(value - d["r"][i]))
        agree += abs(d["r"][i] - predicted[i]) <= SETTLE_TOLERANCE * predicted[i]
    compared = int(np.sum(np.isfinite(predicted)))
    mean, std = (float(np.mean(r)), float(np.std(r, ddof=1))) if len(r) > 1 else (math.nan, math.nan)
    contact, pull_in = int(np.sum(d["contact_loss"])), int(np.sum(d["pull_in"]))
    summary = {
        "amplitude": {"settled_samples": int(len(r)), "mean": mean, "std": std,
                      "mean_ci95": [mean - Z95 * std / math.sqrt(len(r)), mean + Z95 * std / math.sqrt(len(r))]
                      if len(r) > 1 else [math.nan, math.nan],
                      "quantiles_5_50_95": np.quantile(r, [0.05, 0.5, 0.95]).tolist() if len(r) else []},
        "contact_loss": {"count": contact, "probability": contact / n, "ci95_wilson": wilson(contact, n)},
        "pull_in": {"count": pull_in, "probability": pull_in / n, "ci95_wilson": wilson(pull_in, n)},
        "unsettled": int(np.sum(~d["settled"] & _usable(d))),
        "failed": int(np.sum(d["failed"])),
        "agreement": {"fraction": agree / compared if compared else math.nan, "compared": compared,
                      "agreeing": int(agree), "criterion": f"|r - r_slow_flow| <= {SETTLE_TOLERANCE:g} r_slow_flow "
                      "(the settling bound), r_slow_flow the stable slow-flow branch nearest r",
                      "samples_with_two_stable_branches": ambiguous,
                      "samples_outside_averaging_validity": notes},
    }
    return {"summary": summary, "predicted_r": predicted}


# --- basins ------------------------------------------------------------------------------------------

def stable_manifold(scene, model, bound: float, samples: int = 40000, with_times: bool = False) -> list:
    """The saddle's stable manifold: both branches traced backwards in slow time from the saddle along the
    stable eigenvector, until |(A, B)| exceeds `bound` or 40 slow decay times (2/mu) pass; each branch as
    an array of (A, B) rows (with_times: (backward times, that array))."""
    from scipy.integrate import solve_ivp

    flow = model.flow()
    saddles = [s for s in av.steady_states(flow, model.r_max) if s.kind == "saddle"]
    if not saddles:
        return []
    s = saddles[0]
    values, vectors = np.linalg.eig(flow.jacobian(s.A, s.B))
    v = vectors[:, int(np.argmin(values.real))].real

    def backwards(_t, z):
        a, b = flow.rhs(z[0], z[1])
        return [-a, -b]

    def leave(_t, z):
        return math.hypot(z[0], z[1]) - bound

    leave.terminal = True
    branches = []
    for sign in (1.0, -1.0):
        start = np.array([s.A, s.B]) + sign * 1e-7 * v
        sol = solve_ivp(backwards, (0.0, 40 * 2.0 / scene.mu), start, method="DOP853", rtol=1e-10, atol=1e-13,
                        dense_output=True, events=leave)
        t = np.linspace(0.0, sol.t[-1], samples)
        branches.append((t, sol.sol(t).T) if with_times else sol.sol(t).T)
    return branches


def to_initial_state(model, AB: np.ndarray) -> np.ndarray:
    """(x0, v0) whose averaged run starts at slow state (A, B): the reconstruction x, x' at tau = 0 of the
    averaged model (slowflow.SlowFlowSolution, the inverse of its choice of the initial (A, B))."""
    from vibromodel.slowflow import SlowFlowSolution

    solution = SlowFlowSolution(model, 0.0, model.eq.x_e, 0.0, 1e-8)
    A, B = AB[:, 0], AB[:, 1]
    dA, dB = model.flow().rhs(A, B)
    x, v, _ = solution._reconstruct(0.0, A, B, dA, dB, 0.0, 0.0)
    return np.column_stack([x, v])


def basins(spec: Spec, d: dict) -> dict:
    from scipy.spatial import cKDTree

    from vibrofmu.study.cases import basins_omega

    omega = basins_omega(spec)
    scene = spec.base_scene().with_values(omega=omega)
    model = av.averaged(scene)
    stable = [s for s in av.steady_states(model.flow(), model.r_max) if s.stable]
    ok = _usable(d) & ~d["contact_loss"]
    measured = np.where(ok, d["branch"], -1)
    predicted = d["predicted_branch"]
    x0, v0 = spec.axis("x0"), spec.axis("v0")
    corner = max(math.hypot(x - model.eq.x_e, v / omega) for x in (x0[0], x0[-1]) for v in (v0[0], v0[-1]))
    branches = stable_manifold(scene, model, bound=1.5 * corner + 0.1)
    boundary = [to_initial_state(model, ab) for ab in branches]
    points = np.column_stack([d["x_start"], d["v_start"] / omega])
    if boundary:
        curve = np.vstack(boundary)
        distance, _ = cKDTree(np.column_stack([curve[:, 0], curve[:, 1] / omega])).query(points)
    else:
        distance = np.full(len(points), np.inf)
    margin = BASIN_MARGIN
    table = {}
    for m in sorted({0.0, 0.01, 0.02, margin, 0.05}):
        far = distance > m
        agree = far & (measured == predicted)
        table[f"{m:g}"] = {"compared": int(np.sum(far)), "agreeing": int(np.sum(agree)),
                           "fraction": float(np.sum(agree) / np.sum(far)) if np.sum(far) else math.nan}
    far = distance > margin
    summary = {
        "omega": omega, "stable_states": [{"r": s.r, "A": s.A, "B": s.B, "kind": s.kind} for s in stable],
        "grid": [len(x0), len(v0)],
        "reached": {"branch_" + str(k): int(np.sum(measured == k)) for k in range(len(stable))}
        | {"neither": int(np.sum(measured == -1)), "unsettled_at_max_periods": int(np.sum(~d["settled"])), "contact_loss": int(np.sum(d["contact_loss"])),
           "pull_in": int(np.sum(d["pull_in"]))},
        "agreement": {**table[f"{margin:g}"], "margin": margin,
                      "margin_meaning": "Euclidean distance in (x0, v0/omega) from the predicted boundary",
                      "by_margin": table,
                      "disagreements": [{"x0": float(d["x_start"][i]), "v0": float(d["v_start"][i]),
                                         "measured": int(measured[i]), "predicted": int(predicted[i]),
                                         "distance": float(distance[i])}
                                        for i in np.flatnonzero(far & (measured != predicted))][:20]},
    }
    return {"summary": summary, "measured": measured, "predicted": predicted, "boundary": boundary,
            "distance": distance, "stable": stable, "model": model, "omega": omega}


# --- response-map ------------------------------------------------------------------------------------

def slow_flow_folds(scene, deltas) -> list[list[av.Fold]]:
    return [av.folds(av.averaged(scene.with_values(Delta=float(delta))), samples=400) for delta in deltas]


def slow_flow_cusp(scene, lo: float, hi: float, iterations: int = 30) -> dict | None:
    """Smallest Delta with two folds, by bisection between lo (none) and hi (two); omega there."""
    def two(delta):
        return len(av.folds(av.averaged(scene.with_values(Delta=delta)), samples=400)) >= 2

    if two(lo) or not two(hi):
        return None
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if two(mid) else (mid, hi)
    folds = av.folds(av.averaged(scene.with_values(Delta=hi)), samples=400)
    return {"Delta": hi, "omega": 0.5 * (folds[0].omega + folds[-1].omega), "bracket": [lo, hi]}


def response_map(spec: Spec, d: dict, tests: list[dict] | None = None) -> dict:
    scene = spec.base_scene()
    deltas = np.array(spec.axis("Delta"))
    omega_e = av.averaged(scene).omega_e
    omegas = omega_e + np.array(spec.axis("omega_offset"))
    n_w, n_d = len(omegas), len(deltas)
    r = {"up": np.full((n_d, n_w), np.nan), "down": np.full((n_d, n_w), np.nan)}
    settled = {"up": np.zeros((n_d, n_w), bool), "down": np.zeros((n_d, n_w), bool)}
    for k in range(len(d["case"])):
        j, i, direction = int(d["Delta_index"][k]), int(d["omega_index"][k]), str(d["direction"][k])
        ok = not (d["failed"][k] or d["pull_in"][k])
        r[direction][j, i] = d["r"][k] if ok else np.nan
        settled[direction][j, i] = bool(d["settled"][k]) and ok
    both = settled["up"] & settled["down"]
    apart = np.abs(r["up"] - r["down"]) > BRANCHES_APART * np.fmax(r["up"], r["down"])
    measured = both & apart
    step = float(omegas[1] - omegas[0]) if n_w > 1 else math.nan
    folds = slow_flow_folds(scene, deltas)
    predicted = np.zeros((n_d, n_w), bool)
    predicted_jump = np.full((n_d, n_w), np.nan)  # slow flow: r of the high stable state - r of the low one
    near = np.zeros((n_d, n_w), bool)
    jumps = []
    for j, delta in enumerate(deltas):
        model = av.averaged(scene.with_values(Delta=float(delta)))
        for i, omega in enumerate(omegas):
            stable = [s.r for s in av.steady_states(model.flow(float(omega)), model.r_max) if s.stable]
            predicted[j, i] = len(stable) >= 2
            if predicted[j, i]:
                predicted_jump[j, i] = max(stable) - min(stable)
            near[j, i] = any(abs(omega - f.omega) <= sweep_tolerance(model, f, step) for f in folds[j])
        up = Sweep("up", [SweepPoint(float(w), float(r["up"][j, i]), 0.0, bool(settled["up"][j, i]), 0, (0, 0))
                          for i, w in enumerate(omegas)])
        down = Sweep("down", [SweepPoint(float(w), float(r["down"][j, i]), 0.0, bool(settled["down"][j, i]), 0, (0, 0))
                              for i, w in list(enumerate(omegas))[::-1]])
        jumps.append({"Delta": float(delta), "slow_flow_folds": [f.omega for f in folds[j]],
                      "run_jumps": [jump["omega"] for jump in hysteresis_jumps(up, down, BRANCHES_APART)]})
    compared = ~near & both
    agree = compared & (measured == predicted)
    cusp = slow_flow_cusp(scene, float(deltas[0]), float(deltas[-1])) if n_d > 1 else None
    rows_bistable = [j for j in range(n_d) if measured[j].any()]
    run_cusp = None
    if rows_bistable:
        first = rows_bistable[0]
        where = omegas[measured[first]]
        run_cusp = {"Delta_bracket": [float(deltas[first - 1]) if first > 0 else None, float(deltas[first])],
                    "omega": float(0.5 * (where.min() + where.max())),
                    "first_bistable_Delta": float(deltas[first])}
    from vibrofmu.study import cusp as cusp_module

    extrapolation = {
        "runs_sweeps": cusp_module.extrapolate(cusp_module.band_rows(deltas, omegas, measured, np.abs(r["up"] - r["down"]))),
        "slow_flow_same_grid": cusp_module.extrapolate(cusp_module.band_rows(deltas, omegas, predicted, predicted_jump)),
        "slow_flow_exact_folds": cusp_module.extrapolate(
            [{"Delta": float(delta), "width": f[-1].omega - f[0].omega, "centre": 0.5 * (f[0].omega + f[-1].omega),
              "jump": math.nan} for delta, f in zip(deltas, folds) if len(f) >= 2], use_jump=False),
        "method": "width^(2/3) and jump^2 linear in Delta over the rows with >= "
                  f"{cusp_module.MIN_POINTS} bistable grid points; zero = Delta_c (least squares, delta-method "
                  "standard error); omega_c = the band centres' line at Delta_c",
    }
    test = None
    if tests is not None:
        test = cusp_module.test_summary(tests, deltas, omegas)
        test_mask = test.pop("_mask")
        extrapolation["runs_two_start_test"] = test.pop("extrapolation")
    else:
        test_mask = None
    cusp_comparison = None
    if cusp and run_cusp:
        lo, hi = run_cusp["Delta_bracket"]
        cusp_comparison = {"slow_flow_Delta_in_run_bracket": (lo is None or lo <= cusp["Delta"]) and cusp["Delta"] <= hi,
                           "omega_difference": run_cusp["omega"] - cusp["omega"],
                           "Delta_step": float(deltas[1] - deltas[0]), "omega_step": step}
    summary = {
        "omega_e": omega_e, "grid": [n_w, n_d],
        "bistable_points": {"runs": int(measured.sum()), "slow_flow": int(predicted.sum())},
        "agreement": {"fraction": float(agree.sum() / compared.sum()) if compared.sum() else math.nan,
                      "compared": int(compared.sum()), "agreeing": int(agree.sum()),
                      "excluded_near_folds": int((near & both).sum()), "excluded_unsettled": int((~both).sum()),
                      "margin": "one omega step + the ghost margin of a MAX_PERIODS wait (stability.sweep_tolerance) "
                                "around each slow-flow fold at that Delta"},
        "cusp": {"slow_flow": cusp, "runs": run_cusp, "comparison": cusp_comparison,
                 "extrapolation": extrapolation, "two_start_test": test,
                 "two_start_points": tests},
        "jumps": jumps,
    }
    return {"summary": summary, "r": r, "measured": measured, "predicted": predicted, "near": near,
            "omegas": omegas, "deltas": deltas, "folds": folds, "cusp": cusp, "run_cusp": run_cusp,
            "extrapolation": extrapolation, "test_mask": test_mask, "test": test}


def headline(summary: dict) -> str:
    agreement = summary.get("agreement", {})
    text = (f"{summary['kind']}: {summary['cases']}/{summary['cases_in_study']} cases "
            f"({summary['computed_this_run']} computed now) on {summary['workers']} workers in {summary['wall_s']:.1f} s")
    if agreement:
        text += (f"; agreement with the averaged prediction {agreement.get('fraction', math.nan):.3f} "
                 f"({agreement.get('agreeing')}/{agreement.get('compared')})")
        everywhere = (agreement.get("by_margin") or {}).get("0")
        if isinstance(agreement.get("margin"), (int, float)) and everywhere:  # basins: say what was not counted
            text += (f" farther than {agreement['margin']:g} from the predicted boundary; all points "
                     f"{everywhere['agreeing']}/{everywhere['compared']}")
    cusp = summary.get("cusp")
    if cusp:
        text += "\n" + cusp_headline(cusp)
    return text


def cusp_headline(cusp: dict) -> str:
    """The cusp estimates, one per line: slow flow, the extrapolations, the two-start test's bracket."""
    lines = []
    if cusp.get("slow_flow"):
        lines.append(f"cusp, slow flow (bisection on the folds): Delta = {cusp['slow_flow']['Delta']:.6f}, "
                     f"omega = {cusp['slow_flow']['omega']:.6f}")
    labels = {"slow_flow_exact_folds": "slow flow, extrapolated from its folds",
              "slow_flow_same_grid": "slow flow, extrapolated on the grid",
              "runs_sweeps": "runs, extrapolated from the sweeps",
              "runs_two_start_test": "runs, extrapolated from the two-start test"}
    for key, label in labels.items():
        e = (cusp.get("extrapolation") or {}).get(key)
        if e:
            lines.append(f"cusp, {label} ({len(e['rows'])} rows): Delta = {e['Delta']:.6f} +- {e['Delta_stderr']:.6f}, "
                         f"omega = {e['omega']:.6f} +- {e['omega_stderr']:.6f}")
    test = cusp.get("two_start_test")
    if test:
        lo, hi = test["Delta_bracket"] or (None, None)
        lines.append(f"cusp, runs, two-start test ({test['points_tested']} points, {test['verdicts']}): "
                     f"Delta in [{lo}, {hi}]")
    return "\n".join(lines)
