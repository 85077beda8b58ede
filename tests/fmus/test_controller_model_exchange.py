"""The native controller as Model Exchange (FMI 2.0 and 3.0) beside its co-simulation: its continuous states are the
nine estimates theta^, their derivatives the update law's rates theta^' = lambda2 Lambda^-1 phi(t, x, v) e2 at the
inputs set, and it has no event indicators (its right-hand side is smooth). Under FMPy's CVode, and in a C host on
Debian's CVODE (tests/c_host/fmi2_me_cvode.c: the loop of fmusim's Model Exchange, which is not packaged for this
machine), it follows the co-simulation, which adds the exact integral of the same rates over each step (inputs
held), within a bound derived from CVODE's error test; a call out of order is fmi2Error, never a crash.
"""
import ctypes
import csv
import subprocess

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from vibrofmu import paths
from vibrofmu.fmus import toolchain
from vibrofmu.hosts.run import FmuLog
from vibrofmu.speed.peers import CVODE_LIBS
from model_exchange import assert_co_simulation_has_no_derivatives, model_exchange_instance, restart

pytestmark = pytest.mark.fmu

ESTIMATES = ["mu_hat", "a1_hat", "a2_hat", "a3_hat", "a4_hat", "a5_hat", "Delta_hat", "beta_hat", "gamma_hat"]
# inputs held for the whole run: e1 = 0.2, e2 = v - v_ref + c e1 = -0.25 + 2 * 0.2 = 0.15 (c = sqrt(4/1)), so every
# estimate moves (mu^ .. a5^ linearly; Delta^, beta^, gamma^ with cos(omega t), sin(Omega t), cos(2 Omega t))
INPUTS = {"x": 0.3, "v": -0.2, "x_ref": 0.1, "v_ref": 0.05, "a_ref": -0.02}
STOP, INTERVAL = 50.0, 0.1


def _inputs():
    return np.array([(0.0, *INPUTS.values())], dtype=[("time", float), *((name, float) for name in INPUTS)])


def test_interface_and_validate_is_silent(native_controller_fmu, controller_fmi3):
    for fmu in (native_controller_fmu, controller_fmi3):
        assert validate_fmu(str(fmu)) == []
        md = read_model_description(str(fmu))
        assert md.modelExchange is not None and md.coSimulation is not None
        assert md.numberOfEventIndicators == 0
        assert [(d.name, d.derivative.name) for d in (s.variable for s in md.derivatives)] == [
            (f"der({name})", name) for name in ESTIMATES]


def _me_against_cs(fmu, rtol):
    """(ME result, CS result, number of right-hand sides CVODE evaluated) over tau 0..50, inputs held."""
    out = [*ESTIMATES, "U", "e1", "e2"]
    cs = simulate_fmu(str(fmu), stop_time=STOP, output_interval=INTERVAL, input=_inputs(), output=out)
    calls = []
    me = simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", relative_tolerance=rtol, stop_time=STOP,
                      output_interval=INTERVAL, input=_inputs(), output=out, fmi_call_logger=calls.append)
    rhs = sum(1 for call in calls if call.startswith(("fmi2GetDerivatives(", "fmi3GetContinuousStateDerivatives(")))
    return me, cs, rhs


def test_model_exchange_under_cvode_matches_the_co_simulation(native_controller_fmu, controller_fmi3):
    """The bound, per estimate theta^_i (derived, not fitted):
    - the problem: with the inputs held, theta^' = f(t) does not depend on theta^ (df/dtheta^ = 0), so an error made
      in one step is carried unchanged to the end, neither damped nor amplified: the global error is the sum of
      the local errors of the steps taken, plus the interpolation to the output point (FMPy's CVode steps past
      each output time and interpolates back: at most one more step's error);
    - CVODE accepts a step when its local error estimate has WRMS norm <= 1, the weights 1/(rtol |theta^_i| +
      atol_i), and FMPy sets atol_i = rtol * nominal_i = rtol (the nominals are 1): with 9 states, each component's
      estimate is at most sqrt(9) rtol (|theta^_i| + 1); the estimate may be off by up to a factor 10 (the BDF
      estimate's looseness, as in the plant's Model Exchange tests), so a step contributes at most
      30 rtol (max|theta^_i| + 1);
    - the number of steps is at most the number of right-hand sides evaluated (each step takes at least one; the
      difference-quotient Jacobians take 9 more each), counted from FMPy's call log;
    - the co-simulation adds the closed-form integral of the same rates over each step (vk_controller_increment):
      rounding only, at most 4 ulps of max|theta^_i| per step, 500 steps.
    So |theta^_i,ME - theta^_i,CS| <= (n_rhs + 1) 30 rtol (max|theta^_i| + 1) + 500 * 4 eps max|theta^_i|.
    U = -phi^T theta^ + x~'' - c e2 is linear in theta^: its bound is sum_i |phi_i| bound_i, with |phi_i| =
    |der(theta^_i)| / |e2| (the default gains make lambda2 / Lambda_i = 1). e1, e2 depend on the inputs alone:
    the same bits. Measured (rtol 1e-8 / 1e-10): max error 77 / 284 rtol (max + 1), the bound's (n_rhs + 1) 30 is
    about 5e4 / 1e5. That the gap is the integrator's and not a wrong rate: it shrinks with the tolerance (rtol
    1e-8 -> 1e-10: at least tenfold; measured 27-fold), and FMI 3.0's Model Exchange gives FMI 2.0's bits (the
    same C calls under the same solver)."""
    eps = np.finfo(float).eps
    errors = {}
    for rtol in (1e-8, 1e-10):
        me, cs, rhs = _me_against_cs(native_controller_fmu, rtol)
        me3, cs3, rhs3 = _me_against_cs(controller_fmi3, rtol)
        assert rhs3 == rhs and all(me3[k].tobytes() == me[k].tobytes() and cs3[k].tobytes() == cs[k].tobytes()
                                   for k in me.dtype.names)
        assert me["time"][-1] == STOP and len(me) == len(cs)
        bound = {name: (rhs + 1) * 30 * rtol * (np.max(np.abs(cs[name])) + 1) + 500 * 4 * eps * np.max(np.abs(cs[name]))
                 for name in ESTIMATES}
        error = {name: np.max(np.abs(me[name] - cs[name])) for name in ESTIMATES}
        for name in ESTIMATES:
            assert error[name] <= bound[name], (name, rtol, error[name], bound[name])
            assert np.ptp(cs[name]) > 0.01  # the estimate moves (a5^ least: x^5 e2 50 = 0.018): not constants
        for name in ("e1", "e2"):
            assert me[name].tobytes() == cs[name].tobytes()
        rates = simulate_fmu(str(native_controller_fmu), stop_time=STOP, output_interval=INTERVAL, input=_inputs(),
                             output=[f"der({name})" for name in ESTIMATES])
        phi = np.array([np.abs(rates[f"der({name})"]) for name in ESTIMATES]) / abs(cs["e2"][0])
        u_bound = np.sum(phi * np.array([[bound[name]] for name in ESTIMATES]), axis=0)
        assert np.all(np.abs(me["U"] - cs["U"]) <= u_bound + 4 * eps * np.abs(cs["U"]))
        errors[rtol] = max(error[name] / (np.max(np.abs(cs[name])) + 1) for name in ESTIMATES)
    assert errors[1e-10] * 10 <= errors[1e-8]


def test_model_exchange_bad_calls_are_errors(native_controller_fmu, tmp_path):
    """Out of order, wrong sizes, a Co-Simulation instance's ME call, an ME instance's doStep, and an input beyond
    its rule: fmi2Error with a log line, never a value with fmi2OK; the derivatives are the update law's rates."""
    log = FmuLog()  # a live logger of this test's own (FMPy's FMI 2 logger is a process-wide proxy)
    md, folder, fmu = model_exchange_instance(native_controller_fmu, tmp_path, log)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    nine = (ctypes.c_double * 9)()
    with pytest.raises(FMICallException):  # before initialisation
        fmu.getDerivatives(nine, 9)

    restart(fmu)
    with pytest.raises(FMICallException):  # event mode: continuous states are set in continuous-time mode
        fmu.setContinuousStates(nine, 9)
    restart(fmu, continuous_time=True)
    assert fmu.dll.fmi2GetDerivatives(ctypes.c_void_p(fmu.component), (ctypes.c_double * 2)(), 2) > 0  # wrong size
    restart(fmu, continuous_time=True)
    assert fmu.dll.fmi2DoStep(ctypes.c_void_p(fmu.component), ctypes.c_double(0.0), ctypes.c_double(0.1), 1) > 0
    restart(fmu, continuous_time=True)
    fmu.getContinuousStates(nine, 9)  # the estimates' start values
    assert list(nine) == [md_start(md, f"{name}_start") for name in ESTIMATES]
    assert fmu.dll.fmi2GetEventIndicators(ctypes.c_void_p(fmu.component), None, 0) == 0  # none: n = 0 is fine
    fmu.setReal([vr["x"], vr["v"]], [0.3, -0.2])
    derivatives = (ctypes.c_double * 9)()
    fmu.getDerivatives(derivatives, 9)
    # theta^' = phi e2 (unit gains): mu^' = -v e2, a1^' = -x e2, ..., a5^' = -x^5 e2 with e2 = v + 2 x = 0.4
    assert list(derivatives)[:6] == pytest.approx([0.2 * 0.4] + [-(0.3 ** k) * 0.4 for k in range(1, 6)], rel=1e-14)
    assert list(derivatives) == fmu.getReal([vr[f"der({name})"] for name in ESTIMATES])  # the variables agree
    with pytest.raises(FMICallException):  # an input beyond its rule (|x| <= 1.5e6, where x^5 e2 stays finite)
        fmu.setReal([vr["x"]], [1e70])
    assert any("parameter x = 1e+70" in m for m in log.errors())
    # the instance is in the error state: the derivatives are not answered with fmi2OK
    assert fmu.dll.fmi2GetDerivatives(ctypes.c_void_p(fmu.component), derivatives, 9) > 0
    fmu.freeInstance()
    assert_co_simulation_has_no_derivatives(md, folder, log, 9)
    errors = log.errors()  # one line each, naming the call and the state or the interface
    assert any("fmi2SetContinuousStates is not allowed in the event mode state" in m for m in errors), errors
    assert any("fmi2GetDerivatives" in m and "instantiated for Co-Simulation" in m for m in errors), errors
    assert any("fmi2DoStep" in m and "instantiated for Model Exchange" in m for m in errors), errors


def md_start(md, name):
    return float(next(v.start for v in md.modelVariables if v.name == name))



# ---- the closed loop (plant + controller + reference in one FMU): 11 states, three contact/pull-in indicators ----

LOOP_STATES = ["x", "v", *ESTIMATES]
LOOP_OUT = [*LOOP_STATES, "U"]
LOOP_STOP, LOOP_RTOL = 20.0, 1e-10


def _loop_amplification(fmu):
    """A_i = max over t of sum_j |d y_i(t) / d y_j(0)|: how much an error in the states at one time can grow in output
    i, measured by perturbing each state's start value by 1e-6 (co-simulation at rtol 1e-12: the differences' own
    error 2e-12 / 1e-6 = 2e-6 relative, the nonlinearity's O(1e-6))."""
    md = read_model_description(str(fmu))
    start = {v.name: float(v.start) for v in md.modelVariables if v.name.endswith("_start")}
    run = {"stop_time": LOOP_STOP, "output_interval": INTERVAL, "output": LOOP_OUT, "relative_tolerance": 1e-12}
    base = simulate_fmu(str(fmu), **run)
    total = {name: np.zeros(len(base)) for name in LOOP_OUT}
    delta = 1e-6
    for state in LOOP_STATES:
        moved = simulate_fmu(str(fmu), start_values={f"{state}_start": start[f"{state}_start"] + delta}, **run)
        for name in LOOP_OUT:
            total[name] += np.abs(moved[name] - base[name]) / delta
    return {name: float(np.max(total[name])) for name in LOOP_OUT}


def _loop_bound(cs, steps, amplification, rtol):
    """The closed loop's ME against its CS, per output i: the ME's global error is the sum of its steps' local errors,
    each carried to the output time by the loop's flow; a step's local error is at most 10 sqrt(11) rtol (|y_j| + 1)
    per state j (CVODE's WRMS test over 11 states, the estimate's looseness 10: the controller's derivation above),
    and the flow grows an error in the states by at most A_i in output i (measured from the start, taken for every
    time: the tracking error decays (V' <= 0) and the estimates' errors are carried unchanged, so the loop does not
    amplify more later). Plus the co-simulation's own error, 10 rtol max|y_i| (DOP853, GRAZE_BOUND)."""
    local = 10 * np.sqrt(len(LOOP_STATES)) * rtol * max(np.max(np.abs(cs[name])) + 1 for name in LOOP_STATES)
    return {name: (steps + 1) * local * amplification[name] + 10 * rtol * np.max(np.abs(cs[name]))
            for name in LOOP_OUT}


def test_closed_loop_model_exchange_within_its_derived_bound(native_closed_loop_fmu):
    """The closed loop's ME under FMPy's CVode (rtol 1e-10) against its co-simulation (DOP853, the same rtol) over
    tau 0..20, within _loop_bound with the number of right-hand sides CVODE evaluated (an upper bound of its steps)
    and the loop's measured amplification (A_i measured: 1.1 for x, 2.2 for v, 1.0 to 1.9 for the estimates, 6.2
    for U). Measured: 1273 right-hand sides; at most 56 rtol (max|y_i| + 1) for the states (v, gamma^), 129 for U;
    the bound 2,500 to 6,000 times the error for x, v, U and the estimates that move most (it takes every step's
    error at its limit and in the same direction)."""
    amplification = _loop_amplification(native_closed_loop_fmu)
    assert all(1.0 <= amplification[name] < 100 for name in LOOP_STATES), amplification  # each state moves itself
    cs = simulate_fmu(str(native_closed_loop_fmu), stop_time=LOOP_STOP, output_interval=INTERVAL, output=LOOP_OUT,
                      relative_tolerance=LOOP_RTOL)
    calls = []
    me = simulate_fmu(str(native_closed_loop_fmu), fmi_type="ModelExchange", solver="CVode",
                      relative_tolerance=LOOP_RTOL, stop_time=LOOP_STOP, output_interval=INTERVAL, output=LOOP_OUT,
                      fmi_call_logger=calls.append)
    rhs = sum(1 for call in calls if call.startswith("fmi2GetDerivatives("))
    bound = _loop_bound(cs, rhs, amplification, LOOP_RTOL)
    for name in LOOP_OUT:
        assert np.max(np.abs(me[name] - cs[name])) <= bound[name], (name, bound[name])
    assert np.ptp(me["gamma_hat"]) > 1e-2 and np.ptp(me["x"]) > 0.05  # the loop moves (measured 0.017, 0.093)


ME_HOST_SOURCE = paths.C_HOST_DIR / "fmi2_me_cvode.c"


def _me_host(out_dir):
    program = out_dir / "fmi2_me_cvode"
    cmd = [*toolchain.c_compiler(), *toolchain.HOST, *toolchain.host_includes(), "-o", str(program),
           str(ME_HOST_SOURCE), *CVODE_LIBS, *toolchain.HOST_LIBS]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stderr}"
    return program


def _run_me_host(host, fmu, unzip_dir, stop, rtol, outputs, values):
    """The C host's rows (time and the outputs) and its CVODE step count."""
    md = read_model_description(str(fmu))
    folder = extract(str(fmu), str(unzip_dir))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    library = f"{folder}/binaries/linux64/{md.modelExchange.modelIdentifier}.so"
    cmd = [str(host), library, f"file://{folder}/resources", md.guid, str(len(md.derivatives)),
           str(md.numberOfEventIndicators), repr(stop), repr(INTERVAL), repr(rtol),
           ",".join(str(vr[name]) for name in outputs), *(f"{vr[name]}={value!r}" for name, value in values.items())]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stderr[-3000:]}"
    rows = list(csv.reader(proc.stdout.splitlines()))[1:]
    data = np.array([[float(x) for x in row] for row in rows])
    summary = proc.stderr.strip().splitlines()[-1].split()  # fmi2_me_cvode: steps N rhs M events K
    return {"time": data[:, 0], **{name: data[:, 1 + k] for k, name in enumerate(outputs)}}, int(summary[2])


@pytest.mark.tools("cvode/cvode.h")
def test_model_exchange_in_a_c_host_on_cvode(native_controller_fmu, native_closed_loop_fmu, tmp_path):
    """The controller's Model Exchange in the C host on Debian's CVODE (BDF, FMPy's settings) against its
    co-simulation, with the bound of the test above and the host's own step count (CVodeGetNumSteps: each step's
    local error is bounded, not each right-hand side's): (steps + 1) 30 rtol (max|theta^_i| + 1) + the
    co-simulation's rounding. Measured at rtol 1e-8: 1277 steps, max error 77 rtol (max + 1). The closed loop's
    Model Exchange in the same host (its three event indicators as CVODE's root functions) follows its co-simulation
    within _loop_bound with the host's step count."""
    host = _me_host(tmp_path)
    eps = np.finfo(float).eps
    for rtol in (1e-8, 1e-10):
        me, steps = _run_me_host(host, native_controller_fmu, tmp_path / "controller", STOP, rtol, ESTIMATES, INPUTS)
        cs = simulate_fmu(str(native_controller_fmu), stop_time=STOP, output_interval=INTERVAL, input=_inputs(),
                          output=ESTIMATES)
        assert len(me["time"]) == len(cs) and np.max(np.abs(me["time"] - cs["time"])) <= 1e-12
        for name in ESTIMATES:
            bound = (steps + 1) * 30 * rtol * (np.max(np.abs(cs[name])) + 1) + 500 * 4 * eps * np.max(np.abs(cs[name]))
            assert np.max(np.abs(me[name] - cs[name])) <= bound, (name, rtol, steps)
    me, steps = _run_me_host(host, native_closed_loop_fmu, tmp_path / "closed_loop", LOOP_STOP, LOOP_RTOL, LOOP_OUT,
                             {})
    cs = simulate_fmu(str(native_closed_loop_fmu), stop_time=LOOP_STOP, output_interval=INTERVAL, output=LOOP_OUT,
                      relative_tolerance=LOOP_RTOL)
    assert len(me["time"]) == len(cs)
    bound = _loop_bound(cs, steps, _loop_amplification(native_closed_loop_fmu), LOOP_RTOL)
    for name in LOOP_OUT:
        assert np.max(np.abs(me[name] - cs[name])) <= bound[name], (name, bound[name])
