"""fmusim (the Reference-FMUs' simulator) on the native FMI 2.0 FMUs: Model Exchange under fmusim's CVode against
the co-simulation (fmusim's and FMPy's) and against FMPy's CVode (the controller in FMI 2.0 and 3.0), within the bounds the Model Exchange tests derive
(tests/fmus/test_controller_model_exchange.py: (steps + 1) 30 rtol (max|theta^_i| + 1) + the co-simulation's
rounding for the controller's estimates; _loop_bound for the closed loop), with fmusim's own number of right-hand
sides (from its FMI call log) as the bound's step count.

    python benchmarks/fmusim_compare.py FMUSIM [BUILD_DIR]

FMUSIM: an fmusim binary (its options --interface-type, --solver cvode, --tolerance, --stop-time,
--output-interval, --start-value, --output-variable, --output-file, --log-fmi-calls, --fmi-log-file); BUILD_DIR: a
`vibrofmu build --out-dir` folder (built into a temporary folder when left out). fmusim is not packaged for Debian
or PyPI, so this is a script run by hand, not a test. Prints one line per comparison; exit status 1 when a
difference exceeds its bound or the controller's FMI 3.0 Model Exchange under fmusim does not give its FMI 2.0 bits (the
same C calls under the same solver).
"""
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from fmpy import simulate_fmu

TESTS = Path(__file__).resolve().parents[1] / "tests"
sys.path[:0] = [str(TESTS), str(TESTS / "fmus")]
import test_controller_model_exchange as mex  # noqa: E402  (the derivations and runs of the Model Exchange tests)

EPS = np.finfo(float).eps


def run_fmusim(fmusim, fmu, interface, work, stop, outputs, rtol=None, start_values=None):
    """fmusim's rows on the output grid (at an event time the last row: after the event) and the number of
    fmi2GetDerivatives calls in its FMI call log."""
    out, log = work / f"{fmu.stem}_{interface}_{rtol}.csv", work / f"{fmu.stem}_{interface}_{rtol}.log"
    cmd = [str(fmusim), "--interface-type", interface, "--stop-time", repr(stop), "--output-interval",
           repr(mex.INTERVAL), "--output-file", str(out), "--log-fmi-calls", "--fmi-log-file", str(log)]
    if interface == "me":
        cmd += ["--solver", "cvode"]
    if rtol is not None:
        cmd += ["--tolerance", repr(rtol)]
    for name, value in (start_values or {}).items():
        cmd += ["--start-value", name, repr(value)]
    for name in outputs:
        cmd += ["--output-variable", name]
    proc = subprocess.run([*cmd, str(fmu)], capture_output=True, text=True, timeout=900)
    if proc.returncode != 0:
        sys.exit(f"error: {' '.join(cmd)} {fmu} failed:\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    with open(out, newline="") as f:
        rows = list(csv.reader(f))
    header, data = rows[0], np.array([[float(x) for x in row] for row in rows[1:]])
    grid = np.round(data[:, 0] / mex.INTERVAL)
    on_grid = np.abs(data[:, 0] - grid * mex.INTERVAL) <= 1e-9
    last = {int(k): i for i, k in enumerate(grid) if on_grid[i]}  # the last row of each grid time
    keep = [last[k] for k in sorted(last)]
    with open(log) as f:
        rhs = sum(1 for line in f if line.startswith(("fmi2GetDerivatives(", "fmi3GetContinuousStateDerivatives(")))
    return {name: data[keep, header.index(name)] for name in header}, rhs


def line(what, error, bound):
    ok = error <= bound
    print(f"  {what:58s} {error:10.3e}  bound {bound:10.3e}  {'ok' if ok else 'EXCEEDED'}")
    return ok


def controller(fmusim, fmu, fmu3, work):
    ok = True
    outputs = [*mex.ESTIMATES, "U", "e1", "e2"]
    fcs, _ = run_fmusim(fmusim, fmu, "cs", work, mex.STOP, outputs, start_values=mex.INPUTS)
    for rtol in (1e-8, 1e-10):
        fme, rhs = run_fmusim(fmusim, fmu, "me", work, mex.STOP, outputs, rtol, mex.INPUTS)
        pme, pcs, prhs = mex._me_against_cs(fmu, rtol)
        assert len(fme["time"]) == len(pcs) == len(fcs["time"]), (len(fme["time"]), len(pcs))
        print(f"controller, rtol {rtol:g}: fmusim {rhs} right-hand sides, FMPy {prhs}")
        print(f"  fmusim CS against FMPy CS, max |diff| over the estimates and U: "
              f"{max(np.max(np.abs(fcs[n] - pcs[n])) for n in [*mex.ESTIMATES, 'U']):.3e}")
        for what, me, cs, steps in (("fmusim ME - fmusim CS", fme, fcs, rhs), ("fmusim ME - FMPy CS", fme, pcs, rhs),
                                    ("FMPy ME - FMPy CS", pme, pcs, prhs)):
            scaled = max(np.max(np.abs(me[n] - cs[n])) / (np.max(np.abs(cs[n])) + 1) for n in mex.ESTIMATES) / rtol
            worst = [(np.max(np.abs(me[n] - cs[n])),
                      (steps + 1) * 30 * rtol * (np.max(np.abs(cs[n])) + 1) + 500 * 4 * EPS * np.max(np.abs(cs[n])),
                      n) for n in mex.ESTIMATES]
            error, bound, name = max(worst, key=lambda w: w[0] / w[1])
            ok &= line(f"{what}: {scaled:6.1f} rtol (max+1); tightest {name}", error, bound)
        print(f"  fmusim ME - FMPy ME, estimates: {scaled_gap(fme, pme, rtol):.1f} rtol (max+1)")
        fme3, rhs3 = run_fmusim(fmusim, fmu3, "me", work, mex.STOP, outputs, rtol, mex.INPUTS)
        same = rhs3 == rhs and all(fme3[n].tobytes() == fme[n].tobytes() for n in fme)
        print(f"  fmusim ME, FMI 3.0 against FMI 2.0: {rhs3} right-hand sides, "
              f"{'the same bits' if same else f'{scaled_gap(fme3, fme, rtol):.1f} rtol (max+1) apart'}")
        ok &= same
    return ok


def scaled_gap(a, b, rtol):
    return max(np.max(np.abs(a[n] - b[n])) / (np.max(np.abs(b[n])) + 1) for n in mex.ESTIMATES) / rtol


def closed_loop(fmusim, fmu, work):
    ok = True
    rtol = mex.LOOP_RTOL
    fme, rhs = run_fmusim(fmusim, fmu, "me", work, mex.LOOP_STOP, mex.LOOP_OUT, rtol)
    fcs, _ = run_fmusim(fmusim, fmu, "cs", work, mex.LOOP_STOP, mex.LOOP_OUT, rtol)
    pcs = simulate_fmu(str(fmu), stop_time=mex.LOOP_STOP, output_interval=mex.INTERVAL, output=mex.LOOP_OUT,
                       relative_tolerance=rtol)
    assert len(fme["time"]) == len(pcs) == len(fcs["time"]), (len(fme["time"]), len(pcs))
    amplification = mex._loop_amplification(fmu)
    bound = mex._loop_bound(pcs, rhs, amplification, rtol)
    print(f"closed loop, rtol {rtol:g}: fmusim {rhs} right-hand sides")
    print(f"  fmusim CS against FMPy CS, max |diff|: {max(np.max(np.abs(fcs[n] - pcs[n])) for n in mex.LOOP_OUT):.3e}")
    for name in mex.LOOP_OUT:
        error = np.max(np.abs(fme[name] - pcs[name]))
        scaled = error / (np.max(np.abs(pcs[name])) + 1) / rtol
        ok &= line(f"fmusim ME - FMPy CS, {name}: {scaled:6.1f} rtol (max+1)", error, bound[name])
    return ok


def usage_error(message):
    """A user mistake: one line and exit status 2 (the project's CLI rule)."""
    print(f"error: {message}", file=sys.stderr)
    sys.exit(2)


def main(argv):
    if len(argv) not in (2, 3):
        usage_error("usage: python benchmarks/fmusim_compare.py FMUSIM [BUILD_DIR]")
    fmusim = Path(argv[1])
    if not fmusim.is_file():
        usage_error(f"no fmusim binary at {fmusim}")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        build = Path(argv[2]) if len(argv) == 3 else work / "build"
        if len(argv) == 3 and not (build / "native").is_dir():
            usage_error(f"{build} is not a `vibrofmu build --out-dir` folder (no native/ in it)")
        if len(argv) == 2:
            subprocess.run(["vibrofmu", "build", "--no-win64", "--out-dir", str(build)], check=True)
        native = build / "native"
        ok = controller(fmusim, native / "AdaptiveLyapunovController.fmu",
                        native / "fmi3" / "AdaptiveLyapunovController.fmu", work)
        ok &= closed_loop(fmusim, native / "HertzEAClosedLoop.fmu", work)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
