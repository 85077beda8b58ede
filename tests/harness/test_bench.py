"""`vibrofmu bench --quick`: work-precision cases, baselines, targets (issue 6). One quick bench run per module."""
import contextlib
import io
import json
import math
import struct
import sys
import types
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

import vibrofmu.analyses
from vibrofmu.speed import bench
from vibrofmu.speed import ladder as ladder_module
from vibrofmu.cli import main
from vibrofmu.analyses.reference import reference_solution
from vibromodel.parameters import Scene
from vibromodel.plant import Plant, Settings

STAND_IN_ROWS = [{"name": "stand-in extreme row"}]


@pytest.fixture(scope="module")
def quick(plant_fmu, closed_loop_fmu, native_plant_fmu, plant_fmi3, tmp_path_factory):
    """(bench.json, stdout, out dir) of `vibrofmu bench --quick`, with a stand-in vibrofmu.analyses.extremes (the real
    module has its own tests; this keeps the run short and checks the rows are passed through). The FMUs the bench
    builds for itself from these sources (the closed loop for the ladder; the native plant as FMI 2.0 and 3.0 for the
    FMI versions record) are the session's, built from the same sources by the same builders (conftest.py): three
    builds fewer (each a compile of the whole model, a third of this run's CPU). The session's native FMU may hold a
    win64 DLL and a reference result besides (the bench leaves them out to build faster): the linux64 binary the
    bench times is the same."""
    from vibrofmu.fmus import build as fmu_build
    from vibrofmu.fmus import native

    out = tmp_path_factory.mktemp("bench")
    extremes = types.ModuleType("vibrofmu.analyses.extremes")
    extremes.extreme_rows = lambda quick, fmu: [{**row, "quick": quick, "fmu": str(fmu)} for row in STAND_IN_ROWS]
    built = {2: native_plant_fmu, 3: plant_fmi3}

    def session_native(pythonfmu, out_dir, win64=None, reference=True, fmi_version=2):
        assert Path(pythonfmu).resolve() == Path(plant_fmu).resolve()  # the bench's own plant: the session's native FMUs are built from it
        return built[fmi_version]

    stdout, stderr = io.StringIO(), io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        mp.setattr(fmu_build, "build_closed_loop", lambda folder: closed_loop_fmu)
        mp.setattr(native, "build_native", session_native)
        mp.setitem(sys.modules, "vibrofmu.analyses.extremes", extremes)
        # the cli imports it as `from vibrofmu.analyses import extremes`: the package attribute, once imported
        mp.setattr(vibrofmu.analyses, "extremes", extremes, raising=False)
        # without the instruction counts (minutes under valgrind: test_ladder.py checks them) and with two rounds
        # instead of three (enough to check the rounds' structure; test_ladder.py checks three with stand-in runs)
        code = main(["bench", "--quick", "--no-instructions", "--ladder-rounds", "2", "--fmu", str(plant_fmu),
                     "--out", str(out)])
    assert code == 0, stderr.getvalue()
    return json.loads((out / "bench.json").read_text()), stdout.getvalue(), stderr.getvalue(), out


def line(summary, method, interval=bench.TARGET_INTERVAL):
    """(rtol, L-infinity) of one work-precision line, loosest rtol first."""
    return [(r["rtol"], r["errors"]["linf_x"]) for r in summary["cases"]
            if r["method"] == method and r["output_interval"] == interval]


def test_every_case_has_finite_errors_or_a_stated_reason(quick):
    summary, _, stderr, _ = quick
    assert summary["bench"]["quick"] and summary["bench"]["stop_time"] == bench.QUICK_STOP
    assert {"platform", "python", "numpy", "scipy", "fmpy", "cpu_count"} <= set(summary["machine"])
    cases = summary["cases"]
    assert {r["kind"] for r in cases} >= {"fmu", "solve_ivp"}
    assert {r["fidelity"] for r in cases if r["kind"] == "fmu"} == {0, 1, 2, 3, 4}
    assert {r["output_interval"] for r in cases} == set(bench.INTERVALS)
    assert stderr.count("\n[") == len(cases)  # one progress line per case
    for r in cases:
        assert {"method", "setting", "rtol", "output_interval", "errors", "reason", "nfev", "do_steps"} <= set(r)
        if r["errors"] is None:
            assert isinstance(r["reason"], str) and r["reason"], r
            continue
        e = r["errors"]
        assert all(math.isfinite(e[k]) and e[k] >= 0 for k in ("linf_x", "l2_x", "final_x")), r
        assert e["l2_x"] <= e["linf_x"] and e["final_x"] <= e["linf_x"]
        n = round(r["stop_time"] / r["output_interval"])
        # the record's own numbers divided again: one rounding (1.1e-16 relative) at most; approx's default rel
        # 1e-6 checks the formula (a wrong divisor is off by a factor), not the rounding
        assert r["wall_seconds"] > 0 and r["seconds_per_step"] == pytest.approx(r["wall_seconds"] / n)
        assert r["seconds_per_0.1_tau"] == pytest.approx(r["wall_seconds"] / (r["stop_time"] / 0.1))
        assert r["error_is_model_error"] == (r["kind"] == "fmu" and r["fidelity"] in (3, 4))
        if r["kind"] == "fmu":
            assert r["do_steps"] == n and r["output_points"] == n + 1
            assert r["repeatable"], r["method"]
            if r["kernel"] != 0:  # the FMU runs vibromodel.Plant: the same bits (the C kernel: see the next test)
                assert r["plant_direct"]["identical_to_fmu"], r["method"]
            assert r["instantiation_seconds"]["min"] > 0  # a duration: no bound a loaded machine could break
        if r["kind"] in ("solve_ivp", "floor") or (r["kind"] == "fmu" and r["fidelity"] <= 2):
            assert isinstance(r["nfev"], int) and r["nfev"] > 0
        else:
            assert r["nfev"] is None and r["nfev_note"]
    # fidelity 2's own-model error is the solver's; against Eq. 3 the printed coefficients' ~2e-8 adds to it
    paper = [r for r in cases if r["kind"] == "fmu" and r["fidelity"] == 2 and r["rtol"] == 1e-10]
    assert paper and all(r["errors"]["linf_x_own_model"] < 1e-9 < 1e-8 < r["errors"]["linf_x"] for r in paper)


# Tolerance proportionality of DOP853's error-per-step control: an order-8 step taken where its local error
# is ~ rtol needs N ~ rtol^(-1/8) steps, so the global error is E ~ K rtol^(7/8). K is not the same at every
# rtol: the controller accepts any step whose error estimate is below the tolerance (aiming at 0.9^8 ~ 0.43 of
# it) and the error at the worst grid point is a signed sum of local errors. Slack: K may vary by 10^(7/4)
# ~ 56, so tightening by two decades (predicted fall 56x) must lower the error and one decade may raise it at
# most 7.5x; plus twice the reference's own error (its self-check), which floors the tightest settings.
PROPORTIONALITY_EXPONENT, K_SLACK = 7 / 8, 10 ** 1.75


def test_dop853_error_falls_as_rtol_tightens_within_the_controllers_slack(quick):
    summary, *_ = quick
    floor = 2 * summary["reference"]["self_check"]["max_abs_difference_x"]
    lines = [m for m in dict.fromkeys(r["method"] for r in summary["cases"])
             if m.startswith("FMU fidelity 0 DOP853") or m == "solve_ivp DOP853"]
    assert len(lines) >= 2
    for method in lines:
        for interval in bench.INTERVALS:
            points = line(summary, method, interval)
            assert len(points) >= 5, (method, interval)
            for i, (r_loose, e_loose) in enumerate(points):
                for r_tight, e_tight in points[i + 1:]:
                    assert r_tight < r_loose
                    bound = K_SLACK * (r_tight / r_loose) ** PROPORTIONALITY_EXPONENT * e_loose + floor
                    assert e_tight <= bound, (method, interval, r_loose, e_loose, r_tight, e_tight)
            assert points[-1][1] < 1e-3 * points[0][1]  # over 8 decades: the error does fall


def test_fmu_error_equals_the_plants_computed_directly(quick):
    """The same DOP853 code run on vibromodel.Plant here, against a reference computed here: the FMU's error in
    bench.json (every kernel) is the same number."""
    summary, *_ = quick
    scene, stop, h = Scene(), summary["bench"]["stop_time"], 0.1
    n = round(stop / h)
    plant = Plant(scene, Settings(rtol=1e-8, max_step=bench.NO_CEILING), 0.0, stop)  # the bench's adaptive cases' setting
    x = np.array([scene.x_start] + [plant.do_step(i * h, h, 0.0).x for i in range(n)])
    reference = reference_solution(scene, 0, stop, rtol=bench.BENCH_RTOL, atol=1e-2 * bench.BENCH_RTOL)
    error = float(np.max(np.abs(x - reference(h * np.arange(n + 1))[0])))
    cases = [r for r in summary["cases"] if r["kind"] == "fmu" and r["fidelity"] == 0 and r["solver"] == "DOP853"
             and r["rtol"] == 1e-8 and r["output_interval"] == h]
    assert len(cases) == len(summary["bench"]["kernels"]) >= 1
    for r in cases:
        # the FMU gives the plant's bits (tests/fmus/test_fast_path_plant.py) and the reference is the same solve;
        # the error is ~1e-8 (rtol 1e-8), so 1e-12 = 1e-4 of it admits only the reference's interpolation rounding
        assert abs(r["errors"]["linf_x"] - error) <= 1e-12, (r["method"], r["errors"]["linf_x"], error)
        assert r["nfev"] == plant.integrator.nfev


def test_reference_is_accurate_far_below_the_threshold(quick):
    summary, *_ = quick
    check = summary["reference"]["self_check"]
    assert summary["reference"]["rtol"] == 1e-13 and check["rtol"] == 1e-12
    # the reference must be 1000x more accurate than the accuracy the bench grades (THRESHOLD)
    assert 0 < check["max_abs_difference_x"] < 1e-3 * bench.THRESHOLD
    # and that number is what the two references give here
    stop, h = summary["bench"]["stop_time"], check["output_interval"]
    grid = h * np.arange(round(stop / h) + 1)
    fine, coarse = (reference_solution(Scene(), 0, stop, rtol=r, atol=1e-2 * r)(grid)[0] for r in (1e-13, 1e-12))
    # the same two solve_ivp runs on the same grid: the same numbers; rel 1e-6 checks that the bench reports this
    # difference (another rtol pair differs by a factor ~10), not its last digits
    assert float(np.max(np.abs(fine - coarse))) == pytest.approx(check["max_abs_difference_x"], rel=1e-6)


def test_work_precision_png_is_a_valid_png(quick):
    *_, out = quick
    data = (out / "work_precision.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    image = matplotlib.image.imread(out / "work_precision.png")
    assert image.shape[:2] == (height, width) and width > 1000 and height > 400
    assert image[..., :3].std() > 0.05  # something is drawn


def test_targets_are_the_ratios_of_the_cheapest_cases_recomputed(quick):
    summary, stdout, _, _ = quick
    cases, targets = summary["cases"], summary["targets"]
    assert targets["threshold_linf_x"] == 1e-8 and targets["output_interval"] == 0.1

    def best(kind):  # the FMU at fidelity 0, the baselines' right-hand side
        candidates = [(r["wall_seconds"], i) for i, r in enumerate(cases)
                      if r["kind"] == kind and r["output_interval"] == 0.1 and r["errors"] is not None
                      and r["errors"]["linf_x"] <= 1e-8 and not r["error_is_model_error"]
                      and (kind != "fmu" or r["fidelity"] == 0)]
        return min(candidates)[1] if candidates else None

    fmu, ivp = best("fmu"), best("solve_ivp")
    assert fmu is not None and ivp is not None  # both reach 1e-8 on [0, 200]
    inputs = targets["inputs"]
    assert inputs["fmu"]["case"] == fmu and inputs["solve_ivp"]["case"] == ivp
    assert inputs["fmu"]["method"] == cases[fmu]["method"] and cases[fmu]["fidelity"] in (0, 1, 2)
    n = round(summary["bench"]["stop_time"] / 0.1)  # communication steps of the FMU = tenths of tau of solve_ivp
    ratio = (cases[fmu]["wall_seconds"] / n) / (cases[ivp]["wall_seconds"] / n)
    check = targets["fmu_step_over_solve_ivp"]
    # ratios of the record's own times recomputed: a few roundings of 1.1e-16 relative, rel 1e-12 with margin
    assert check["ratio"] == pytest.approx(ratio, rel=1e-12) and check["limit"] == 0.25
    assert check["met"] == (ratio <= 0.25)
    floor = targets["fmu_step_over_floor"]
    flo = best("floor")
    assert inputs["floor"]["case"] == flo
    assert floor["ratio"] == pytest.approx(cases[fmu]["wall_seconds"] / cases[flo]["wall_seconds"], rel=1e-12)
    assert floor["met"] == (floor["ratio"] <= 10)
    inst = targets["instantiation"]
    assert inst["seconds"] == summary["instantiation"]["cold_seconds"] > 0 and inst["met"] == (inst["seconds"] < 0.5)
    # measured, not compared: a load spike during the warm run could make it the slower one (speed: the bench)
    assert summary["instantiation"]["warm_seconds"] > 0
    # the command prints them
    assert f"{check['ratio']:.3g} (target <= 0.25" in stdout and "instantiation (cold)" in stdout


def test_extreme_rows_are_passed_through(quick, plant_fmu):
    """The rows of the bench's own FMU (the extremes do not build another one)."""
    summary, *_ = quick
    assert summary["extremes"] == [{**row, "quick": True, "fmu": str(plant_fmu)} for row in STAND_IN_ROWS]


def test_full_plan_covers_the_issues_grid():
    """The full bench's cases, without running them: every fidelity x solver x setting x interval, both kernels
    for the adaptive integrators, the baselines and the floor, half decades at 0.1."""
    plan = bench.make_plan(quick=False)
    assert plan.stop_time == 2000.0 and plan.repeats == 3
    keys = {(c.kind, c.interval, c.fidelity, c.solver, c.rtol, c.max_step, c.kernel, c.method) for c in plan.cases}
    assert len(keys) == len(plan.cases)
    decades = [10.0 ** -k for k in range(4, 13)]
    for interval in (0.1, 1.0):
        for fidelity in (0, 1, 2):
            for kernel in (0, 1):
                assert all(("fmu", interval, fidelity, 0, r, bench.NO_CEILING, kernel, None) in keys for r in decades)
            assert all(("fmu", interval, fidelity, 1, None, h, None, None) in keys
                       for h in (0.1, 0.05, 0.02, 0.01, 0.005))
        assert {(c.fidelity, c.rtol) for c in plan.cases if c.interval == interval and c.fidelity in (3, 4)} == \
               {(3, None), (4, None)}
        for method in ("RK45", "DOP853", "LSODA"):
            assert all(("solve_ivp", interval, 0, 0, r, 0.0, None, method) in keys for r in decades)
        assert all(("floor", interval, 0, 0, r, bench.NO_CEILING, None, None) in keys for r in decades)
    for r in (10 ** -6.5, 10 ** -8.5, 10 ** -10.5):  # the target's search between decades
        assert ("fmu", 0.1, 0, 0, r, bench.NO_CEILING, 0, None) in keys and ("floor", 0.1, 0, 0, r, bench.NO_CEILING, None, None) in keys
        assert ("solve_ivp", 0.1, 0, 0, r, 0.0, None, "LSODA") in keys


def test_ladder_has_every_rung_in_both_hosts_with_its_error_and_the_acceptance_ratios(quick):
    """The C-host and FMPy ladder (ladder.py): well-formed, errors consistent with the models, interleaved rounds
    recorded, the acceptance's ratios recomputed from the kept runs (no timings asserted)."""
    summary, stdout, _, out = quick
    ladder = summary["ladder"]
    assert ladder["quick"] and ladder["stop_time"] == bench.LADDER_QUICK_STOP
    assert ladder["rounds"] == 2  # --ladder-rounds 2
    assert [r["rung"] for r in ladder["rungs"]] == [name for name, _, _ in ladder_module.RUNGS]
    columns = [("C host", 0.1), ("C host", 1.0), ("FMPy", 1.0)]
    assert [(c["host"], c["interval"]) for c in ladder["columns"]] == columns
    for rung in ladder["rungs"]:
        assert [(c["host"], c["interval"]) for c in rung["columns"]] == columns
        for c in rung["columns"]:
            assert c["outputs"] == round(ladder["stop_time"] / c["interval"])
            assert math.isfinite(c["cost_per_output_seconds"]) and c["cost_per_output_seconds"] > 0
            assert len(c["loop_seconds_runs"]) == len(c["cost_per_output_seconds_runs"]) == ladder["rounds"]
            assert len(c["cpu_per_output_seconds_runs"]) == ladder["rounds"]
            assert c["cpu_per_output_seconds"] == min(c["cpu_per_output_seconds_runs"]) > 0
            # the record's own numbers divided again: one rounding; approx's default rel 1e-6 checks the formula
            assert c["cost_per_output_seconds"] == pytest.approx(min(c["loop_seconds_runs"]) / c["outputs"])
            assert math.isfinite(c["linf_x"]) and c["linf_x"] >= 0
            assert c["repeatable"], (rung["rung"], c["host"], c["interval"])  # every round gives the same x
    # the order of the runs: a warm-up round 0, then rounds that each run every rung in every column once
    order = ladder["order"]
    assert len(order) == (ladder["rounds"] + 1) * len(ladder["rungs"]) * len(columns)
    assert [o["round"] for o in order] == sorted(o["round"] for o in order)
    assert all(a["started_seconds"] <= b["started_seconds"] for a, b in zip(order, order[1:]))
    for r in range(ladder["rounds"] + 1):
        assert sorted((o["rung"], o["host"], o["interval"]) for o in order if o["round"] == r) == sorted(
            (rung["rung"], h, i) for rung in ladder["rungs"] for h, i in columns)
    errors = {r["rung"]: max(c["linf_x"] for c in r["columns"]) for r in ladder["rungs"]}
    # the rungs' accuracy (README): exact and polynomial at the default rtol 1e-8; RK4 h = 0.01 (order 4) well
    # below; f4 ~3e-9 and f3 ~4e-4 are model errors; the closed loop against its own tighter run
    assert errors["averaged f3"] > 1e-5 > max(errors["exact f0"], errors["polynomial f1"], errors["analytic f4"])
    assert errors["RK4 h = 0.01"] < 1e-8 and errors["closed loop"] < 1e-6
    # the same FMU in two hosts gives the same x: the errors agree between the C host and FMPy at interval 1
    for rung in ladder["rungs"]:
        by_column = {(c["host"], c["interval"]): c["linf_x"] for c in rung["columns"]}
        assert by_column["C host", 1.0] == by_column["FMPy", 1.0], rung["rung"]
    assert {(a["rung"], a["host"], a["interval"]) for a in ladder["acceptance"]} == {
        (rung, host, interval) for rung in ladder_module.LIMITS for host, interval in (("C host", 0.1), ("FMPy", 1.0))}
    base = next(r for r in ladder["rungs"] if r["rung"] == ladder_module.BASE)
    for a in ladder["acceptance"]:
        rung = next(r for r in ladder["rungs"] if r["rung"] == a["rung"])
        for key, ratio, per_round_key, best in (
                ("cpu_per_output_seconds_runs", "ratio", "ratios_per_round", "ratio_best_over_best"),
                ("cost_per_output_seconds_runs", "ratio_wall", "ratios_per_round_wall", "ratio_wall_best_over_best")):
            runs = {(c["host"], c["interval"]): c[key] for c in rung["columns"]}[a["host"], a["interval"]]
            base_runs = {(c["host"], c["interval"]): c[key] for c in base["columns"]}[a["host"], a["interval"]]
            per_round = [x / y for x, y in zip(runs, base_runs)]
            # the record's own runs divided again (one rounding each); approx's default rel 1e-6 checks the formula
            assert a[per_round_key] == pytest.approx(per_round)
            assert a[ratio] == pytest.approx(float(np.median(per_round)))
            assert a[best] == pytest.approx(min(runs) / min(base_runs))
        assert a["met"] == (a["ratio"] <= a["limit"])  # the acceptance reads the CPU-time median
    # asked not to count instructions: the column is absent, with its reason, in the JSON and the output
    assert ladder["instructions"]["measured"] is False and "not requested" in ladder["instructions"]["reason"]
    assert all("instructions" not in rung for rung in ladder["rungs"]) and ladder["acceptance_instructions"] == []
    assert "speed-accuracy ladder" in stdout and "averaged f3 / exact f0 (C host, interval 0.1)" in stdout
    assert "instructions per output: not measured: not requested" in stdout
    image = matplotlib.image.imread(out / "ladder.png")
    assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 600


def test_fmi_versions_are_measured_side_by_side_and_printed(quick):
    """Issue 23: the native plant's FMI 3 CS cost per output beside FMI 2 CS's (C host, interleaved rounds), with and
    without early return, and ME under FMPy's CVode beside CS; ratios recomputable from the record, and printed."""
    summary, stdout, _, _ = quick
    cs, me = summary["fmi_versions"]["cosimulation"], summary["fmi_versions"]["model_exchange"]
    per = cs["per_output_s"]
    assert set(per) == {"fmi2", "fmi3", "fmi3er"} and all(0.0 < v < 1e-3 for v in per.values())
    assert cs["fmi3_over_fmi2"] == pytest.approx(per["fmi3"] / per["fmi2"])
    assert cs["fmi3_early_return_over_fmi2"] == pytest.approx(per["fmi3er"] / per["fmi2"])
    assert cs["met"] == (cs["fmi3_over_fmi2"] <= cs["limit"] == 1.1)
    assert me["me_over_cs"] == pytest.approx(me["per_output_s"]["me_cvode"] / me["per_output_s"]["cs"])
    assert "FMI 3 CS / FMI 2 CS per output" in stdout and "ME (FMPy CVode) / CS (FMPy) per output" in stdout


def test_auto_against_the_oracle_is_recorded_and_printed(quick):
    """bench's quick form of the auto campaign (vibrofmu.analyses.error_calibration.auto_campaign): per pair every
    candidate of auto is measured, the oracle is the cheapest one that met the tolerance (recomputed here), auto's
    cost ratio is its choice's cost over the oracle's; the table is printed."""
    from vibromodel.auto import candidates

    summary, stdout, _, _ = quick
    record = summary["auto"]
    pairs = [r for r in record["rows"] if "met" in r]
    assert len(record["rows"]) == bench.AUTO_PAIRS_QUICK and record["summary"]["pairs"] == len(pairs)
    for row in pairs:
        assert len(row["candidates"]) == len(candidates(Settings()))
        met = [c for c in row["candidates"] if c.get("met")]
        for cost in ("run", "total"):
            oracle = min(met, key=lambda c: c[cost])["candidate"] if met else None
            assert row[f"oracle_{cost}"] == oracle
        mine = next((c for c in row["candidates"] if c["candidate"] == row["chosen"]), None)
        if mine is not None and met:
            best = min(c["run"] for c in met)
            assert row["cost_ratio_run"] == pytest.approx(mine["run"] / max(best, 1e-9))
            assert row["met"] == mine["met"]
    assert "fidelity auto against the oracle" in stdout and "doStep loop" in stdout


def test_the_auto_replay_derives_the_campaigns_choices_and_counts(quick, monkeypatch):
    """error_calibration.auto_replay (what `report --check` runs for the auto block) on the quick campaign's pairs
    (the same n and seed): the same choices, met, refusals and compared counts, without building every candidate.
    Then with auto refusing every pair (choose patched), so that the replay builds and runs every candidate as the
    campaign did: a refusal is right (met) exactly when none of the campaign's candidates met the tolerance."""
    from vibrofmu.analyses import error_calibration
    from vibromodel import auto
    from vibromodel.parameters import ParameterError

    campaign = quick[0]["auto"]
    replay = error_calibration.auto_replay(bench.AUTO_PAIRS_QUICK, bench.AUTO_SEED)
    assert [(r["outcome"], r.get("chosen"), r.get("met")) for r in replay["rows"]] == \
        [(r["outcome"], r.get("chosen"), r.get("met")) for r in campaign["rows"]]
    for key in ("pairs", "met_share", "refused", "compared_run", "compared_total", "precheck_skipped",
                "precheck_confirmed"):
        assert replay["summary"][key] == campaign["summary"][key], key

    def refuse(scene, settings, tolerance, *args, **kwargs):
        raise ParameterError("tolerance", tolerance, "refused here")

    monkeypatch.setattr(auto, "choose", refuse)
    refused = error_calibration.auto_replay(bench.AUTO_PAIRS_QUICK, bench.AUTO_SEED)
    assert [(r["outcome"], r["met"]) for r in refused["rows"]] == \
        [("refused", not any(c.get("met") for c in r["candidates"])) for r in campaign["rows"]]
