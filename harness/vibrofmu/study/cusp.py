"""Locating the cusp of the response map (where the two fold curves meet) from the runs, two ways.

1. Extrapolation from the clearly bistable rows (`extrapolate`). Near a cusp the slow dynamics reduce to the
   normal form s' = h + l s - s^3, with h linear in omega and l linear in Delta - Delta_c. Bistability needs
   |h| < 2 (l/3)^{3/2}: the bistable interval's width in omega scales as (Delta - Delta_c)^{3/2}; at a fold
   the jump goes from s = sqrt(l/3) to -2 sqrt(l/3), a size that scales as (Delta - Delta_c)^{1/2}. So
   width^{2/3} and jump^2 are linear in Delta and vanish at Delta_c: each is fitted by least squares over
   the rows with at least MIN_POINTS bistable grid points, and its zero is an estimate of Delta_c with a
   standard error from the fit (delta method). omega at the cusp: the band's centre, fitted linearly in Delta,
   at Delta_c. The same estimator applied to the slow flow's own bistable points on the same grid, and to its
   exact fold curves, measures the estimator's bias (grid quantisation, higher-order terms of the normal form).

2. A bistability test that does not depend on sweep history (`two_start`, a sub-step of the response map with
   `--set cusp_test=1`). At each grid point where the up and down sweeps ended apart, two runs start from the
   two sweeps' end states there and run side by side, with the same forcing phase, for a wait set by the slow
   flow's slowest relaxation rate -Re lambda there (capped). Two runs on one attractor converge to each other
   (same forcing, same phase) like e^{-lambda t}; on two attractors their distance tends to the branches'
   separation. The distance |c_a - c_b| (first harmonics over the same windows) is averaged over the beat
   period of the AC drive (2 pi / |Omega - 2 omega|) and sampled at a third, two thirds and the end of the run.
   Verdict: monostable if the distance at the end is below TEST_BOUND r; bistable if it is above and has
   settled (changed by less than TEST_SETTLED over the last third) and, outside the slow flow's bistable band,
   the run outlasted twice the passage through the nearest fold's ghost (ghost_periods); else the wait doubles,
   up to a cap, and a
   point still moving at the cap is undecided (Aitken's Delta^2 extrapolation of the three samples is
   reported for it, as a hint only: near the cusp the relaxation is not exponential). The verdicts give a
   Delta bracket of the cusp and a ghost-free band per row, which goes through the same extrapolation.
"""
from __future__ import annotations

import math

import numpy as np

from vibromodel import averaging as av

from vibrofmu.analyses.harmonics import first_harmonic
from vibrofmu.analyses.sweep import SAMPLES_PER_PERIOD, WINDOW_PERIODS

MIN_POINTS = 3  # extrapolation: rows with at least 3 bistable grid points (width >= 3 omega steps; a band of
# one or two points has a width error of +-1 step, i.e. 50-100 %)
# two runs converging to one state: their distance decays to 0 (numerical noise ~ rtol 1e-8 r); two states:
# it tends to the separation of the branches, ~ 27 (Delta - Delta_c)^{1/2} r in the slow flow at mu = 0.002
# (0.5 r at Delta - Delta_c = 3.4e-4): a bound of 2 % r misses bistability only within (0.02/27)^2 = 5e-7
# of Delta_c, 1 % of the grid's Delta step
TEST_BOUND = 0.02
TEST_MAX_PERIODS = 6000  # default cap of the two-start wait (forcing periods)
TEST_E_FOLDS = 1.0  # first wait: ln(d0 / bound) relaxation times of the slow flow, plus this many more
# bistable: the distance changed by less than 10 % over the last third of the run. Two runs heading for one
# state, a few slow-flow relaxation times into the run, still lose more than that per third; two runs
# creeping through a fold's ghost (where the relaxation is slower than any steady state's) are caught by the
# doubling of the wait: their distance drops once one of them leaves the ghost
TEST_SETTLED = 0.10


# --- 1. extrapolation --------------------------------------------------------------------------------

def _zero_of_fit(x: np.ndarray, y: np.ndarray) -> dict | None:
    """Least-squares line y = a + b x; its zero -a/b with the standard error from the fit's covariance
    (residual variance over n - 2 degrees of freedom; delta method)."""
    n = len(x)
    if n < 3:
        return None
    X = np.column_stack([np.ones(n), x])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    a, b = coef
    residual = y - X @ coef
    s2 = float(residual @ residual) / (n - 2)
    cov = s2 * np.linalg.inv(X.T @ X)
    if b == 0:
        return None
    zero = -a / b
    grad = np.array([-1.0 / b, a / b**2])
    return {"zero": float(zero), "stderr": float(math.sqrt(max(grad @ cov @ grad, 0.0))), "slope": float(b),
            "rows": int(n)}


def _line_at(x: np.ndarray, y: np.ndarray, at: float, at_err: float) -> tuple[float, float]:
    """Least-squares line through (x, y) evaluated at `at`, with its standard error (fit + at's error)."""
    X = np.column_stack([np.ones(len(x)), x])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    residual = y - X @ coef
    s2 = float(residual @ residual) / max(len(x) - 2, 1)
    cov = s2 * np.linalg.inv(X.T @ X)
    g = np.array([1.0, at])
    value = float(coef[0] + coef[1] * at)
    return value, float(math.sqrt(max(g @ cov @ g, 0.0) + (coef[1] * at_err) ** 2))


def band_rows(deltas, omegas, mask, jump) -> list[dict]:
    """Per Delta row with >= MIN_POINTS bistable grid points: width (points x step: each point stands for one
    step of omega), centre (mean omega of the points) and jump (largest value of `jump` over the points)."""
    step = float(omegas[1] - omegas[0])
    rows = []
    for j, delta in enumerate(deltas):
        where = np.flatnonzero(mask[j])
        if len(where) >= MIN_POINTS:
            rows.append({"Delta": float(delta), "width": len(where) * step, "centre": float(np.mean(omegas[where])),
                         "jump": float(np.nanmax(jump[j, where]))})
    return rows


def extrapolate(rows: list[dict], use_jump: bool = True) -> dict | None:
    """Delta_c from width^{2/3} (and, reported beside it, from jump^2; module docstring), and omega at the cusp
    from the band centres; None with fewer than 3 rows."""
    if len(rows) < 3:
        return None
    delta = np.array([row["Delta"] for row in rows])
    out = {"rows": [row["Delta"] for row in rows]}
    fits = {"width": _zero_of_fit(delta, np.array([row["width"] for row in rows]) ** (2.0 / 3.0))}
    if use_jump:
        fits["jump"] = _zero_of_fit(delta, np.array([row["jump"] for row in rows]) ** 2)
    # Delta_c is the width fit's zero: on the slow flow's own grid points the jump fit is biased by about one
    # Delta step (the largest sampled jump is not the jump at the fold), the width fit is not (docs/studies.md)
    delta_c, err = fits["width"]["zero"], fits["width"]["stderr"]
    omega_c, omega_err = _line_at(delta, np.array([row["centre"] for row in rows]), delta_c, err)
    out.update({"Delta": delta_c, "Delta_stderr": err, "omega": omega_c, "omega_stderr": omega_err,
                "from_width": fits["width"], "from_jump": fits.get("jump")})
    return out


# --- 2. the two-start bistability test --------------------------------------------------------------------

def slowest_rate(scene) -> float:
    """-Re lambda of the slowest-decaying eigenvalue over the slow flow's stable steady states (docs/model.md, Averaging and slow flow)."""
    model = av.averaged(scene)
    rates = [min(-lam.real for lam in s.eigenvalues) for s in av.steady_states(model.flow(), model.r_max) if s.stable]
    return min(rates, default=scene.mu / 2)


GHOST_PASSAGES = 2.0  # a bistable verdict outside the slow flow's band needs this many ghost passage times


def ghost_periods(scene) -> float:
    """Forcing periods a run must last before its distance from a two-start partner can mean bistability at a
    point outside the slow flow's bistable band: GHOST_PASSAGES times the passage through the nearest fold's
    ghost, pi / sqrt(|a b| d_omega) (averaging.ghost_margin, Strogatz §4.3), d_omega the distance from the
    fold. A run started on the vanished branch creeps that long and looks settled meanwhile. 0 inside the
    band or where the slow flow has no fold."""
    model = av.averaged(scene)
    folds = av.folds(model, samples=400)
    if len(folds) < 2 or folds[0].omega <= scene.omega <= folds[-1].omega:
        return 0.0
    fold = min(folds, key=lambda f: abs(f.omega - scene.omega))
    # ghost_margin(wait) = pi^2 / (|a b| wait^2): at wait = 1 it is pi^2 / |a b|
    passage = math.sqrt(av.ghost_margin(model, fold, 1.0) / abs(scene.omega - fold.omega))
    return GHOST_PASSAGES * passage * scene.omega / (2 * math.pi)


def beat_windows(scene) -> int:
    """Windows of WINDOW_PERIODS forcing periods that span one beat of the AC drive, 2 pi / |Omega - 2 omega|
    (1 when there is no AC drive or no beat)."""
    if not (scene.beta or scene.gamma) or scene.Omega == 2 * scene.omega:
        return 1
    periods = scene.omega / abs(scene.Omega - 2 * scene.omega)
    return max(1, round(periods / WINDOW_PERIODS))


def aitken(d1: float, d2: float, d3: float) -> float:
    """Limit of d1, d2, d3, equally spaced samples of d_inf + a q^k (0 <= q < 1): d3 - (d3 - d2)^2 /
    (d3 - 2 d2 + d1) (Aitken's Delta^2); d3 itself when the samples are not such a converging sequence."""
    if d2 == d1:
        return d3
    q = (d3 - d2) / (d2 - d1)
    if not 0.0 <= q < 1.0:
        return d3
    return d3 - (d3 - d2) ** 2 / (d3 - 2 * d2 + d1)


def judge(ca: np.ndarray, cb: np.ndarray, beat: int, bound: float = TEST_BOUND, long_enough: bool = True) -> dict:
    """The verdict from the two runs' first harmonics per window (module docstring): the distance |c_a - c_b|
    averaged over a beat, relative to the larger amplitude, at a third, two thirds and the end of the run.
    long_enough: the run lasted the wait the slow flow's rate asks for (else a slow approach to one state
    could pass for settled, and the verdict cannot be bistable)."""
    d = np.abs(ca - cb)
    windows = len(d)

    def beat_mean(values, end):  # mean over the beat ending at window `end` (exclusive)
        return float(np.mean(values[end - beat:end]))

    ends = [max(windows // 3, beat), max(2 * windows // 3, beat), windows]
    r = [beat_mean(np.abs(ca), windows), beat_mean(np.abs(cb), windows)]
    scale = max(r)
    samples = [beat_mean(d, end) / scale for end in ends]
    end = samples[-1]
    settled = abs(samples[2] - samples[1]) <= TEST_SETTLED * samples[2]
    if end <= bound:
        verdict = "monostable"
    elif settled and long_enough:
        verdict = "bistable"
    else:
        verdict = "undecided"
    return {"verdict": verdict, "distance": end, "distance_samples": samples, "extrapolated": aitken(*samples),
            "r": r, "jump": abs(r[0] - r[1])}


def two_start(engine, scene, starts, max_periods: int = TEST_MAX_PERIODS, bound: float = TEST_BOUND) -> dict:
    """Run from the two start states side by side (same forcing phase) and decide whether they reach one
    state or two (module docstring). starts: ((x0, v0), (x1, v1)). The first wait comes from the slow flow's
    rate; while the verdict is undecided the wait doubles, up to max_periods."""
    import time

    started = time.perf_counter()
    rate = slowest_rate(scene)
    T = 2 * math.pi / scene.omega
    h = T / SAMPLES_PER_PERIOD
    beat = beat_windows(scene)
    ghost = ghost_periods(scene)
    runs = [engine.open(scene.with_values(x_start=x, v_start=v)) for x, v in starts]
    n_window = WINDOW_PERIODS * SAMPLES_PER_PERIOD
    c = [[], []]
    n = 0
    wait = first_wait = None
    message = ""
    result = None
    try:
        while True:
            x = np.empty((2, n_window))
            for k in range(n_window):
                for i, run in enumerate(runs):
                    x[i, k] = run.step(n * h, h)
                n += 1
            for i in range(2):
                c[i].append(first_harmonic(np.roll(x[i], 1), SAMPLES_PER_PERIOD)[0])
            windows = len(c[0])
            if windows == beat and wait is None:
                d0 = float(np.mean(np.abs(np.array(c[0]) - np.array(c[1])))) / max(np.mean(np.abs(c[0])), 1e-300)
                e_folds = math.log(max(d0, bound) / bound) + TEST_E_FOLDS
                wanted = e_folds / max(rate, 1e-300) / T  # forcing periods
                # at least four beats, for three beat-averaged samples a third of the run apart
                needed = max(wanted, 4 * beat * WINDOW_PERIODS, ghost)
                wait = first_wait = int(min(max_periods, needed))
            if wait is not None and windows * WINDOW_PERIODS >= wait:
                result = judge(np.array(c[0]), np.array(c[1]), beat, bound, windows * WINDOW_PERIODS >= needed)
                if result["verdict"] != "undecided" or wait >= max_periods:
                    break
                wait = min(max_periods, 2 * wait)
    except Exception as error:  # noqa: BLE001 - a run that stops (pull-in, solver) gives no verdict
        message = f"{type(error).__name__}: {error}"
    finally:
        for run in runs:
            run.release(not message)
    out = {"Delta": scene.Delta, "omega": scene.omega, "rate": rate, "beat_windows": beat, "ghost_periods": ghost,
           "periods": len(c[0]) * WINDOW_PERIODS, "first_wait_periods": first_wait, "cap_periods": max_periods,
           "cost_s": time.perf_counter() - started, "message": message}
    if message or result is None:
        out.update(verdict="failed" if message else "too short", distance=math.nan, extrapolated=math.nan,
                   r=[math.nan, math.nan], jump=math.nan)
        return out
    out.update(result)
    return out


def test_points(spec, data: dict) -> list[dict]:
    """The grid points where both sweeps ran and ended more than TEST_BOUND apart, with the two end states."""
    by_point = {}
    for k in range(len(data["case"])):
        if data["failed"][k] or data["pull_in"][k]:
            continue
        key = (int(data["Delta_index"][k]), int(data["omega_index"][k]))
        by_point.setdefault(key, {})[str(data["direction"][k])] = k
    points = []
    for (j, i), ks in sorted(by_point.items()):
        if set(ks) != {"up", "down"}:
            continue
        up, down = ks["up"], ks["down"]
        ru, rd = data["r"][up], data["r"][down]
        if abs(ru - rd) <= TEST_BOUND * max(ru, rd):
            continue
        points.append({"Delta_index": j, "omega_index": i, "Delta": float(data["Delta"][up]),
                       "omega": float(data["omega"][up]),
                       "starts": [[float(data["x_end"][up]), float(data["v_end"][up])],
                                  [float(data["x_end"][down]), float(data["v_end"][down])]]})
    return points


def run_test_point(spec_dict: dict, fmu_digest: str | None, point: dict) -> dict:
    """A Dask task: the two-start test at one grid point on this worker's engine."""
    from vibrofmu.study.engines import engine_for
    from vibrofmu.study.scheduling import FMU_BYTES
    from vibrofmu.study.spec import Spec

    spec = Spec(**spec_dict)
    engine = engine_for(spec.engine, FMU_BYTES.get(fmu_digest) if fmu_digest else None)
    scene = spec.base_scene().with_values(Delta=point["Delta"], omega=point["omega"])
    cap = int(spec.settings.get("cusp_test_periods", TEST_MAX_PERIODS))
    result = two_start(engine, scene, point["starts"], max_periods=cap)
    result.update(Delta_index=point["Delta_index"], omega_index=point["omega_index"])
    return result


def test_summary(tests: list[dict], deltas, omegas) -> dict:
    """The verdicts by row: the cusp's Delta bracket (the highest row without a bistable point below the
    lowest row with one) and the ghost-free band rows for `extrapolate`."""
    n_d, n_w = len(deltas), len(omegas)
    mask = np.zeros((n_d, n_w), bool)
    jump = np.full((n_d, n_w), np.nan)
    verdicts = {}
    for t in tests:
        if t["verdict"] == "bistable" and t["periods"] < t.get("ghost_periods", 0.0):
            t = {**t, "verdict": "undecided"}  # shorter than the ghost passage (ghost_periods)
        verdicts[t["verdict"]] = verdicts.get(t["verdict"], 0) + 1
        if t["verdict"] == "bistable":
            mask[t["Delta_index"], t["omega_index"]] = True
            jump[t["Delta_index"], t["omega_index"]] = t["jump"]
    rows_with = [j for j in range(n_d) if mask[j].any()]
    undecided_rows = sorted({t["Delta_index"] for t in tests if t["verdict"] in ("undecided", "too short", "failed")
                             or (t["verdict"] == "bistable" and t["periods"] < t.get("ghost_periods", 0.0))})
    bracket = None
    if rows_with:
        first = rows_with[0]
        below = [j for j in range(first) if j not in undecided_rows]
        bracket = [float(deltas[below[-1]]) if below else None, float(deltas[first])]
    return {"points_tested": len(tests), "verdicts": verdicts, "Delta_bracket": bracket,
            "bistable_points_by_row": {f"{deltas[j]:.6g}": int(mask[j].sum()) for j in range(n_d)},
            "rows_with_undecided_points": [float(deltas[j]) for j in undecided_rows],
            "extrapolation": extrapolate(band_rows(np.asarray(deltas), np.asarray(omegas), mask, jump)),
            "_mask": mask}
