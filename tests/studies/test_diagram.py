"""The bifurcation diagram and the Lyapunov exponents (analyses/diagram.py, `vibrofmu diagram`) against
independent evidence: the damped linear oscillator's closed form, Floquet multipliers of shooting's monodromy
matrix, the phase-space contraction trace J = -mu, shooting's periodic orbits, the slow flow's folds."""
import math
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pyarrow.parquet as pq
import pytest

from vibromodel import averaging as av
from vibromodel.parameters import Scene

from vibrofmu.analyses import diagram as dg
from vibrofmu.analyses import shooting as sh
from vibrofmu.cli import main
from vibrofmu.fmus.kernel import kernel_library

# beta = gamma = 0: the forcing is strictly T-periodic, so the stroboscopic map is a Poincare map and the model
# is shooting's PeriodicModel exactly (shooting.py, module doc); R = 3 puts the lower electrode beyond the
# contact edge (R = 1 puts both at x = -3/2: contact loss would be pull-in)
PERIODIC = Scene(mu=0.1, Delta=0.05, omega=0.9, beta=0.0, gamma=0.0, R=3.0, x_start=0.0)
# the chaotic window found by `vibrofmu diagram --param omega --from 1.74 --to 2.2 ...` (docs/bifurcation-diagram.md)
CHAOTIC = Scene(mu=0.1, Delta=2.5, omega=1.77, beta=0.0, gamma=0.0, R=3.0, x_start=0.0)
# integration error of the Benettin estimate per unit time: DOP853's error over one period is a small multiple
# (<= 10) of rtol relative to Phi, so ln |R_ii| is off by <= 10 rtol a period, i.e. 10 rtol / T per unit time
BENETTIN_ERROR_PER_PERIOD = 10 * dg.LYAPUNOV_RTOL


def eigvec_condition(monodromy: np.ndarray) -> float:
    return float(np.linalg.cond(np.linalg.eig(monodromy)[1]))


def test_linear_oscillator_gives_minus_mu_over_two_twice():
    """x'' + mu x' + k x = Delta cos omega t (underdamped): both exponents are -mu/2. The Benettin estimate of
    the largest after time t is ln ||e^{At} e1|| / t with e^{At} = e^{-mu t/2} [cos pt I + sin pt (A + mu/2 I)/p]
    (p^2 = k - mu^2/4), so ||e^{At} e1|| lies within a factor c = 1 + ||A + mu/2 I||_2 / p of e^{-mu t/2} and the
    estimate within ln(c) / t of -mu/2 (plus the integration error)."""
    scene, k, n = Scene(mu=0.3, Delta=0.1, omega=1.3), 1.7, 60
    result = dg.lyapunov(scene, (0.2, -0.1), n, linear_stiffness=k)
    p = math.sqrt(k - scene.mu**2 / 4)
    A = np.array([[0.0, 1.0], [-k, -scene.mu]])
    c = 1.0 + np.linalg.norm(A + scene.mu / 2 * np.eye(2), 2) / p
    period = 2 * math.pi / scene.omega
    t = n * period
    assert abs(result.largest + scene.mu / 2) <= math.log(c) / t + BENETTIN_ERROR_PER_PERIOD / period
    assert abs(result.second + scene.mu / 2) <= math.log(c) / t + BENETTIN_ERROR_PER_PERIOD / period
    # the sum is ln det Phi / t = trace A = -mu exactly (Liouville), up to the integration error
    assert abs(result.sum + scene.mu) <= 2 * BENETTIN_ERROR_PER_PERIOD / period


@pytest.fixture(scope="module")
def periodic_orbit():
    model = sh.PeriodicModel(PERIODIC)
    return sh.shoot(model, PERIODIC.omega, sh.linear_guess(model, PERIODIC.omega))


def floquet_bound(monodromy: np.ndarray, n: int, T: float) -> float:
    """|ln ||M^n e1|| / (n T) - ln |rho_max| / T| for a diagonalisable M = V D V^-1. A complex pair (equal
    moduli): ||M^n e1|| is within a factor cond(V) of |rho|^n. Real multipliers |rho1| > |rho2|: with
    e1 = c1 v1 + c2 v2 (unit eigenvectors), ||M^n e1|| / |rho1|^n lies in |c1| -+ |c2| |rho2 / rho1|^n."""
    rho, V = np.linalg.eig(monodromy)
    if np.iscomplexobj(rho) and abs(rho[0].imag) > 0.0:
        return math.log(np.linalg.cond(V)) / (n * T)
    order = np.argsort(-np.abs(rho))
    c = np.abs(np.linalg.solve(V, [1.0, 0.0]))[order]
    ratio = (abs(rho[order[1]]) / abs(rho[order[0]])) ** n
    return max(abs(math.log(c[0] + c[1] * ratio)), abs(math.log(c[0] - c[1] * ratio))) / (n * T)


def real_multiplier_orbit():
    """Next to the first period doubling of the chaotic scene (omega = 2.07): real multipliers -0.77, -0.96,
    no contact loss; Newton from the end of a settled run."""
    scene = CHAOTIC.with_values(omega=2.07)
    end = dg.sweep(kernel_library(), scene, "omega", [2.07], samples=1, transient=400)[0].end
    return scene, sh.shoot(sh.PeriodicModel(scene), 2.07, end)


@pytest.mark.parametrize("case", ["complex pair", "real multipliers"])
def test_exponent_on_a_periodic_orbit_is_floquets(periodic_orbit, case):
    """From shooting's orbit: the running estimate after n periods is ln ||M^n e1|| / (n T) with M shooting's
    monodromy (DOP853 at rtol 1e-11 with Newton to 1e-10, an independent integration), and it tends to
    ln |rho_max| / T within floquet_bound."""
    scene, orbit = (PERIODIC, periodic_orbit) if case == "complex pair" else real_multiplier_orbit()
    n = 40
    T = 2 * math.pi / scene.omega
    rho = np.abs(orbit.multipliers)
    result = dg.lyapunov(scene, orbit.z0, n)
    integration = BENETTIN_ERROR_PER_PERIOD / T
    # the orbit's start is off by <= NEWTON_TOL: it moves Phi by ~ NEWTON_TOL |dPhi/dz| ~ 1e-10 a period
    start = sh.NEWTON_TOL / T
    for k in (1, 10, n):
        power = math.log(np.linalg.norm(np.linalg.matrix_power(orbit.monodromy, k) @ [1.0, 0.0])) / (k * T)
        assert abs(result.running[k - 1] - power) <= integration + start
    floquet = math.log(rho.max()) / T
    assert abs(result.largest - floquet) <= floquet_bound(orbit.monodromy, n, T) + integration + start
    assert result.largest < 0.0  # a stable periodic orbit
    assert abs(result.sum + scene.mu) <= 2 * integration


def test_period_one_range_gives_one_x_per_parameter_at_the_orbit(periodic_orbit):
    """Below the resonance (no fold: one stable orbit per omega) every point's samples are one value, the
    periodic orbit's x(0) (shooting's, continued in omega). Spread: after n_tr periods an offset d has shrunk to
    <= cond(V) |rho|^n_tr d <= cond(V) TRANSIENT_EPS d (|rho| = exp(-mu T / 2) for a complex pair, and n_tr is
    chosen so that this is TRANSIENT_EPS), with d <= 1 (|x|, |v| < 0.5 on this branch and at the start), twice
    for a peak-to-peak spread. Against shooting: the core's DOP853 at rtol 1e-8 makes each period's map wrong
    by <= 10 rtol |z|; a contraction M perturbed by e per period has its fixed point moved by
    ||(I - M)^-1|| e."""
    omegas = [0.85, 0.87, 0.9]
    points = dg.sweep(kernel_library(), PERIODIC, "omega", omegas, samples=12)
    model = sh.PeriodicModel(PERIODIC)
    guess = sh.linear_guess(model, omegas[0])
    for point in points:
        orbit = sh.shoot(sh.PeriodicModel(PERIODIC.with_values(omega=point.value)), point.value, guess)
        guess = orbit.z0
        spread_tol = 2 * eigvec_condition(orbit.monodromy) * dg.TRANSIENT_EPS * 1.0
        assert not point.pull_in and not point.contact_loss
        assert np.ptp(point.x) <= spread_tol
        assert dg.distinct(point.x, spread_tol) == 1
        shift = np.linalg.norm(np.linalg.inv(np.eye(2) - orbit.monodromy), 2) * 10 * dg.SETTINGS.rtol * np.abs(
            orbit.z0).max()
        assert abs(point.x.mean() - orbit.z0[0]) <= shift + spread_tol


def test_sweeps_differ_inside_the_slow_flow_folds_and_agree_outside():
    """mu = 0.005, Delta = 0.003: the slow flow has two folds (omega_1 < omega_2); between them two stable
    orbits coexist, the up sweep stays on the upper branch and the down sweep on the lower. Inside (the middle
    half of [omega_1, omega_2], away from the exact folds, which the averaging misplaces by much less than a
    quarter of the width here) the two differ by more than half the slow flow's amplitude gap at mid-range;
    outside (a half width beyond either fold) both converge to the one orbit and agree to the transient
    bound 2 cond(V) TRANSIENT_EPS d, d <= 2 r_max <= 1.2 the largest jump between the branches, cond(V) <= 5
    (shooting's monodromy on this branch: 1.06 below the folds, 4.1 above)."""
    scene = Scene(mu=0.005, Delta=0.003, beta=0.0, gamma=0.0, x_start=0.0)
    model = av.averaged(scene)
    folds = av.folds(model, samples=300)
    assert len(folds) == 2
    lo, hi = folds[0].omega, folds[1].omega
    width = hi - lo
    omegas = np.array([lo - width, lo - 0.5 * width, lo + 0.3 * width, hi - 0.3 * width, hi + 0.5 * width,
                       hi + width])
    up = dg.sweep(kernel_library(), scene, "omega", omegas, samples=4)
    down = dg.sweep(kernel_library(), scene, "omega", omegas[::-1], samples=4)[::-1]
    radii = [s.r for s in av.steady_states(model.flow(0.5 * (lo + hi)), model.r_max) if s.stable]
    assert len(radii) == 2
    gap = abs(radii[0] - radii[1])
    agree_tol = 2 * 5.0 * dg.TRANSIENT_EPS * 1.2
    for omega, u, d in zip(omegas, up, down):
        difference = np.max(np.abs(u.x - d.x))
        if lo < omega < hi:
            assert difference > 0.5 * gap, omega
        else:
            assert difference <= agree_tol, omega


def test_bad_requests_name_the_parameter_and_the_rule(capsys, tmp_path):
    out = str(tmp_path / "d")
    cases = [(["--param", "speed", "--from", "1", "--to", "2"], "--param"),
             (["--param", "omega", "--from", "0", "--to", "1"], "omega"),
             (["--param", "omega", "--from", "1", "--to", "1"], "--to"),
             (["--param", "mu", "--from", "-1", "--to", "1"], "mu"),
             (["--param", "omega", "--from", "1", "--to", "2", "--points", "1"], "--points")]
    for argv, name in cases:
        assert main(["diagram", *argv, "--out", out]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: ") and name in err[0], err


@pytest.mark.long
def test_command_writes_the_tables_and_plots(tmp_path, capsys):
    out = tmp_path / "d"
    code = main(["diagram", "--param", "omega", "--from", "0.85", "--to", "0.9", "--points", "2", "--samples", "5",
                 "--lyapunov-periods", "6", *sum((["--set", f"{k}={v}"] for k, v in
                                                  dict(mu=0.1, Delta=0.05, beta=0, gamma=0, R=3).items()), []),
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    samples = pq.read_table(out / "diagram.parquet").to_pydict()
    assert samples["direction"].count("up") == samples["direction"].count("down") == 2 * 5
    assert sorted(set(samples["parameter"])) == [0.85, 0.9]
    exponents = pq.read_table(out / "lyapunov.parquet").to_pydict()
    assert len(exponents["largest"]) == 4 and all(e < 0 for e in exponents["largest"])
    for s in exponents["sum"]:  # 6 periods of 2 pi / omega, omega <= 0.9
        assert abs(s + 0.1) <= 2 * BENETTIN_ERROR_PER_PERIOD / (2 * math.pi / 0.85)
    assert (out / "diagram.png").stat().st_size > 0 and (out / "lyapunov_convergence.png").stat().st_size > 0
    assert len(pq.read_table(out / "convergence.parquet")) == 4 * 6
    wrote = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("wrote "))
    assert sorted(wrote.removeprefix(f"wrote {out}/").split(", ")) == sorted(p.name for p in out.iterdir())


@pytest.mark.slow
def test_chaos_has_a_positive_exponent_after_a_period_doubling_cascade():
    """omega from 2.2 down to 1.77 at mu = 0.1, Delta = 2.5, R = 3: period 1, 2, 4, 8 (Feigenbaum's
    cascade, with contact loss on every orbit past the first doubling), then a chaotic attractor whose
    exponent stays positive over the second half of 300 periods and whose exponents still sum to -mu."""
    omegas = [2.2, 2.0, 1.85, 1.8, 1.77]
    points = dg.sweep(kernel_library(), CHAOTIC, "omega", omegas, samples=64, transient=400)
    counts = [dg.distinct(p.x, 1e-4) for p in points]
    assert counts[:4] == [1, 2, 4, 8]
    assert counts[4] > 16
    assert all(p.contact_loss for p in points[1:])
    result = dg.lyapunov(CHAOTIC.with_values(omega=1.77), points[-1].end, 300)
    assert result.running[150:].min() > 0.0
    T = 2 * math.pi / 1.77
    assert abs(result.sum + CHAOTIC.mu) <= 2 * BENETTIN_ERROR_PER_PERIOD / T


@pytest.mark.slow
def test_dask_and_serial_give_the_same_bits():
    from vibrofmu.study.scheduling import connect

    values = np.linspace(1.9, 2.1, 5)
    serial = dg.compute(CHAOTIC, "omega", values, samples=8, transient=100, periods=5)
    client, cluster = connect(None, 2)
    try:
        parallel = dg.compute(CHAOTIC, "omega", values, samples=8, transient=100, periods=5, client=client)
        with pytest.raises(dg.TaskFailed, match="ParameterError.*speed"):  # raised on a worker: one message
            dg.compute(CHAOTIC, "speed", values, samples=8, transient=100, periods=5, client=client)
    finally:
        client.close()
        cluster.close()
    for direction in ("up", "down"):
        for a, b in zip(serial.sweeps[direction], parallel.sweeps[direction]):
            assert a.value == b.value and np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
        for a, b in zip(serial.exponents[direction], parallel.exponents[direction]):
            assert (a.value, a.largest, a.second, a.running) == (b.value, b.largest, b.second, b.running)


# Only ends a run that never shows its progress bar or ignores SIGINT: an idle machine stops in 0.2 s, a loaded
# 2-core one took over 120 s. What the tests check is what happened (exit code 130, the one error line).
WAIT_S = 900


def _interrupt(tmp_path, workers: str):
    """Run the command in its own session, send SIGINT to the group once the progress bar shows (as Ctrl-C in a
    terminal: the command and its worker processes), return (exit code, stderr)."""
    out = tmp_path / "out"
    argv = [sys.executable, "-c", "import sys; from vibrofmu.cli import main; sys.exit(main())", "diagram", "--param",
            "omega", "--from", "1.8", "--to", "2.2", "--points", "40", "--set", "mu=0.1", "--set", "Delta=2.5",
            "--set", "R=3", "--set", "beta=0", "--set", "gamma=0", "--workers", workers, "--out", str(out)]
    process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               start_new_session=True,  # SIGINT's default action, as in a terminal (a test run
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # in the background
                                                                                                 # ignores it)
    chunks = []
    reader = threading.Thread(target=lambda: chunks.extend(iter(lambda: process.stderr.read(1), "")))
    reader.start()
    try:
        deadline = time.monotonic() + WAIT_S
        while "diagram:" not in "".join(chunks):  # the progress bar: the cluster is up, the points run
            assert process.poll() is None and time.monotonic() < deadline, "".join(chunks)
            time.sleep(0.05)
        time.sleep(0.5)  # into the points (the whole run takes minutes)
        assert process.poll() is None
        os.killpg(process.pid, signal.SIGINT)
        process.wait(timeout=WAIT_S)
    finally:
        if process.poll() is None:
            process.kill()
        reader.join()
    err = "".join(chunks)
    return process.returncode, err


@pytest.mark.long  # a subprocess
def test_ctrl_c_stops_a_serial_diagram(tmp_path):
    code, err = _interrupt(tmp_path, "1")
    assert code == 130 and "error: interrupted" in err and "Traceback" not in err, err


@pytest.mark.slow  # a subprocess with a Dask cluster
def test_ctrl_c_stops_a_diagram_on_dask(tmp_path):
    code, err = _interrupt(tmp_path, "2")
    assert code == 130 and "error: interrupted" in err and "Traceback" not in err, err


def test_an_exponent_still_moving_over_its_second_half_is_not_converged():
    # drift = |lambda_1(n) - lambda_1(n/2)|: settled when below half of |lambda_1| (the sign cannot flip)
    from vibrofmu.analyses.diagram import SETTLED, PointExponent

    assert PointExponent(1.0, "up", largest=0.019, drift=0.0105).converged is False  # > 0.5 * 0.019
    assert PointExponent(1.0, "up", largest=-0.025, drift=0.002).converged is True
    assert PointExponent(1.0, "up").converged is False  # no exponent (pull-in): nothing settled
    assert PointExponent(1.0, "up", largest=0.03, drift=SETTLED * 0.03).converged is True
