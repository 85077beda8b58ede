"""The native plant FMU as FMI 2.0 Model Exchange (beside its Co-Simulation) and as FMI 3.0 (Co-Simulation with event
mode and early return at contact loss and re-contact, Model Exchange): every variant validates silently and runs
under FMPy; Model Exchange under CVode matches the independent reference and locates every contact change; FMI 3.0
early return stops at each contact change at the reference's time and leaves the trajectory FMI 2.0's; bad calls
are errors, never a crash (fmu_src/native/fmi2_me.c, fmi3_native.c, me_model.h)."""
import ctypes
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Model
from fmpy.fmi3 import FMU3Model, FMU3Slave
from fmpy.validation import validate_fmu

from vibromodel.parameters import Scene
from vibrofmu.analyses.reference import reference_solution
from vibrofmu.hosts.run import FmuLog
from model_exchange import assert_co_simulation_has_no_derivatives, model_exchange_instance, restart

pytestmark = pytest.mark.fmu

# A scene that leaves the contact every forcing period (max|x| 2.7 > 3/2) without pull-in (R = 5: the electrodes
# at |x| = 7.5): 56 contact changes (28 impacts) in [0, 200], each crossed at |x'| >= 1.05 (no graze), so each
# contact change is a well-conditioned zero of 1 + 2x/3.
IMPACTS = dict(Delta=0.3, omega=0.95, R=5.0, x_start=0.0, v_start=0.0)
STOP = 200.0
OUT = ["x", "v", "in_contact"]


def _events_and_grid(result, interval):
    """(times of the off-grid rows: the early returns or recorded events, the rows on the output grid, first each)"""
    t = result["time"]
    on_grid = np.abs(t / interval - np.round(t / interval)) <= 1e-9
    grid_times, first = np.unique(t[on_grid], return_index=True)
    return np.unique(t[~on_grid]), result[on_grid][first]


def test_every_variant_validates_silently(native_plant_fmu, plant_fmi3):
    assert validate_fmu(str(native_plant_fmu)) == []
    assert validate_fmu(str(plant_fmi3)) == []
    md2, md3 = read_model_description(str(native_plant_fmu)), read_model_description(str(plant_fmi3))
    assert md2.modelExchange is not None and md2.coSimulation is not None and md2.numberOfEventIndicators == 3
    assert md3.fmiVersion == "3.0" and md3.modelExchange is not None
    assert md3.coSimulation.hasEventMode and md3.coSimulation.mightReturnEarlyFromDoStep
    # x' = v, v' = a: the states are x and v
    assert [(d.variable.name, d.variable.derivative.name) for d in md2.derivatives] == [("v", "x"), ("a", "v")]


def test_every_variant_runs_the_paper_scene_under_fmpy(native_plant_fmu, plant_fmi3):
    """FMI 2 CS, FMI 3 CS with and without event mode and early return: one integrator, the same bits (the paper scene
    stays in contact: no early return). FMI 2 and FMI 3 ME under CVode: the same equations, so within CVODE's error
    of the co-simulation (bound: the ME reference test's budget, 1000 rtol (max|x| + 1), at rtol 1e-10)."""
    stop = 20.0
    cs2 = simulate_fmu(str(native_plant_fmu), stop_time=stop, output_interval=0.1, output=OUT)
    for options in ({}, {"early_return_allowed": True}, {"use_event_mode": True},
                    {"early_return_allowed": True, "use_event_mode": True}):
        cs3 = simulate_fmu(str(plant_fmi3), stop_time=stop, output_interval=0.1, output=OUT, **options)
        assert cs3["x"].tobytes() == cs2["x"].tobytes(), options
    for fmu in (native_plant_fmu, plant_fmi3):
        me = simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10,
                          stop_time=stop, output_interval=0.1, output=OUT)
        assert me["time"][-1] == stop and np.all(me["in_contact"])
        # cs2 at rtol 1e-8: its own error 10 rtol max|x| (GRAZE_BOUND) is below this bound's 1e-7 * 1.04
        assert np.max(np.abs(me["x"] - cs2["x"])) <= 1000 * 1e-10 * (np.max(np.abs(cs2["x"])) + 1) + 10 * 1e-8 * 0.04


def test_fmi3_early_return_stops_at_contact_changes_short(native_plant_fmu, plant_fmi3):
    """The impacts scene for 40 time units: a master that allows early return is stopped at each contact change (the
    reference's count), with event mode or without; between them, its outputs are FMI 2 CS's bits (the same solver
    steps: the doStep only ends where a step that the solver takes anyway ends)."""
    stop = 40.0
    reference = reference_solution(Scene(**IMPACTS), 0, stop)
    cs2 = simulate_fmu(str(native_plant_fmu), stop_time=stop, output_interval=0.1, output=OUT, start_values=IMPACTS)
    for options in ({"early_return_allowed": True}, {"early_return_allowed": True, "use_event_mode": True}):
        cs3 = simulate_fmu(str(plant_fmi3), stop_time=stop, output_interval=0.1, output=OUT, start_values=IMPACTS,
                           **options)
        events, grid = _events_and_grid(cs3, 0.1)
        assert len(events) == len(reference.contact_changes) >= 4
        # rtol 1e-8: the state within 10 rtol max|x| (GRAZE_BOUND) ~ 3e-7, crossed at |dz/dt| = 2|v|/3 >= 0.7
        assert np.max(np.abs(events - reference.contact_changes)) <= 1e-6
        assert grid["x"].tobytes() == cs2["x"].tobytes()
        # at each early return the contact flag is already on its new side, alternating
        at_events = cs3[np.isin(cs3["time"], events)]
        flags = [row["in_contact"] for row in at_events[np.unique(at_events["time"], return_index=True)[1]]]
        assert flags == [bool(k % 2) for k in range(len(flags))]


@pytest.mark.slow
@pytest.mark.parametrize("scene", [{}, IMPACTS], ids=["paper", "impacts"])
def test_model_exchange_under_cvode_matches_the_reference(native_plant_fmu, plant_fmi3, scene):
    """ME under FMPy's CVode at rtol 1e-10 (atol = rtol * nominal 1) against the phase-wise DOP853 reference
    (rtol 1e-12, its error two orders below the bound).
    The bound: CVODE holds each step's local error to rtol |y| + atol in its WRMS norm; the global error is those
    local errors carried forward by the flow. With damping mu = 0.1 an error fades over ~2/mu = 20 time units, in
    which CVODE at 1e-10 takes O(10^2) steps between restarts; with the norm's factor and the BDF error estimate's
    looseness (a factor of up to 10) the budget is 1000 rtol (max|x| + atol/rtol). Measured: 34 (paper) and 200
    (impacts) of it. That the gap is the integrator's and not a wrong equation or a missed event: it shrinks with
    the tolerance (rtol 1e-8 -> 1e-10: at least tenfold), and every contact change is an event (same count)."""
    reference = reference_solution(Scene(**scene), 0, STOP)
    errors = {}
    for rtol in (1e-8, 1e-10):
        for fmu in (native_plant_fmu, plant_fmi3):
            me = simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", relative_tolerance=rtol,
                              stop_time=STOP, output_interval=0.1, output=OUT, start_values=scene, record_events=True)
            t = me["time"]
            x_ref = reference(t)
            errors[rtol] = np.max(np.abs(me["x"] - x_ref[0]))
            assert errors[rtol] <= 1000 * rtol * (np.max(np.abs(x_ref[0])) + 1.0)
            events = np.unique(t[np.nonzero(np.diff(t) == 0.0)[0]])  # record_events: two rows at each event
            assert len(events) == len(reference.contact_changes)
            assert np.count_nonzero(np.diff(me["in_contact"].astype(int))) == len(reference.contact_changes)
            if len(events):  # each event where the reference's contact change is: the state error over |dz/dt|
                speed = 2.0 / 3.0 * np.min(np.abs(reference(np.array(reference.contact_changes))[1]))
                assert np.max(np.abs(events - reference.contact_changes)) <= errors[rtol] * 10 / speed
    assert errors[1e-10] * 10 <= errors[1e-8]
    if scene:
        assert len(reference.contact_changes) // 2 >= 20  # at least 20 impacts


@pytest.mark.slow
def test_fmi3_early_return_gives_each_impact_time_and_fmi2s_trajectory(native_plant_fmu, plant_fmi3):
    """A master that stops at each impact (FMPy's with early return and event mode) at rtol 1e-12 gets every contact
    change within 1e-10 of the reference, and afterwards the same x as FMI 2 CS.
    The reference at rtol 1e-13, atol 1e-15 (its default 1e-12 is itself 1.3e-10 off in these times). The bound:
    the FMU's state within 10 rtol max|x| = 2.7e-11 (GRAZE_BOUND, tests/model/test_event_location.py), the
    reference's ten times less, over the crossing speed |dz/dt| = 2|v|/3 >= 0.7: 4.3e-11 < 1e-10."""
    rtol = 1e-12
    reference = reference_solution(Scene(**IMPACTS), 0, STOP, rtol=1e-13, atol=1e-15)
    changes = np.array(reference.contact_changes)
    speed = 2.0 / 3.0 * np.min(np.abs(reference(changes)[1]))
    assert 10 * rtol * 2.72 * 1.1 / speed <= 1e-10
    cs2 = simulate_fmu(str(native_plant_fmu), stop_time=STOP, output_interval=0.1, output=OUT, start_values=IMPACTS,
                       relative_tolerance=rtol)
    cs3 = simulate_fmu(str(plant_fmi3), stop_time=STOP, output_interval=0.1, output=OUT, start_values=IMPACTS,
                       relative_tolerance=rtol, early_return_allowed=True, use_event_mode=True)
    events, grid = _events_and_grid(cs3, 0.1)
    assert len(events) == len(changes) and len(changes) // 2 >= 20
    assert np.max(np.abs(events - changes)) <= 1e-10
    # the same solver steps; only the master's t + h after an early return may round differently: |v| ulp(t)
    assert np.max(np.abs(grid["x"] - cs2["x"])) <= rtol * np.max(np.abs(cs2["x"]))


# ---- bad calls: errors, never a crash ----

def _logger():
    messages = []

    def log(*args):
        messages.append(args[-1].decode() if isinstance(args[-1], bytes) else str(args[-1]))

    return messages, log


def test_model_exchange_bad_calls_are_errors(native_plant_fmu, tmp_path):
    # FMPy's FMI 2 logger is a process-wide proxy: without a live logger of its own, an instance that logs after
    # another test's logger was collected calls freed memory (hosts.run.FmuLog keeps its callback alive)
    log = FmuLog()
    from fmpy.fmi1 import FMICallException

    md, folder, fmu = model_exchange_instance(native_plant_fmu, tmp_path, log)
    with pytest.raises(FMICallException):  # before initialisation
        fmu.getDerivatives((ctypes.c_double * 2)(), 2)
    restart(fmu)
    with pytest.raises(FMICallException):  # event mode: continuous states are set in continuous-time mode
        fmu.setContinuousStates((ctypes.c_double * 2)(0.0, 0.0), 2)
    restart(fmu, continuous_time=True)
    assert fmu.dll.fmi2GetDerivatives(ctypes.c_void_p(fmu.component), None, 2) > 0           # NULL array
    restart(fmu, continuous_time=True)
    assert fmu.dll.fmi2GetDerivatives(ctypes.c_void_p(fmu.component), (ctypes.c_double * 5)(), 5) > 0  # wrong size
    assert fmu.dll.fmi2GetEventIndicators(None, (ctypes.c_double * 3)(), 3) > 0     # NULL instance
    restart(fmu, continuous_time=True)
    x, z = (ctypes.c_double * 2)(), (ctypes.c_double * 3)()
    fmu.getContinuousStates(x, 2)
    fmu.getEventIndicators(z, 3)
    assert list(x) == [0.04, 0.0]  # x_start, v_start
    assert z[0] == pytest.approx(1 + 2 * 0.04 / 3)
    step = fmu.dll.fmi2DoStep  # a Model Exchange instance has no doStep
    assert step(ctypes.c_void_p(fmu.component), ctypes.c_double(0.0), ctypes.c_double(0.1), 1) > 0
    fmu.freeInstance()
    assert_co_simulation_has_no_derivatives(md, folder, log, 2)
    assert any("fmi2SetContinuousStates is not allowed in the event mode state" in m for m in log.errors())
    assert any("instantiated for Co-Simulation" in m for m in log.errors())


def test_fmi3_bad_calls_are_errors(plant_fmi3, tmp_path):
    from fmpy.fmi1 import FMICallException

    md = read_model_description(str(plant_fmi3))
    folder = extract(str(plant_fmi3), str(tmp_path / "u"))
    cs = FMU3Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                   instanceName="cs")
    cs.instantiate(eventModeUsed=True, earlyReturnAllowed=True)
    with pytest.raises(FMICallException):  # doStep before initialisation
        cs.doStep(0.0, 0.1)
    cs.reset()
    cs.enterInitializationMode(startTime=0.0)
    cs.exitInitializationMode()  # event mode (eventModeUsed)
    with pytest.raises(FMICallException):
        cs.doStep(0.0, 0.1)
    cs.reset()
    cs.enterInitializationMode(startTime=0.0)
    cs.exitInitializationMode()
    cs.updateDiscreteStates()
    cs.enterStepMode()
    assert cs.dll.fmi3DoStep(ctypes.c_void_p(cs.component), ctypes.c_double(0.0), ctypes.c_double(0.1), True, None, None, None, None) > 0  # NULL outputs
    cs.reset()
    cs.enterInitializationMode(startTime=0.0)
    cs.exitInitializationMode()
    cs.updateDiscreteStates()
    cs.enterStepMode()
    event, terminate, early, last = cs.doStep(0.0, 0.1)
    assert (event, terminate, early, last) == (False, False, False, pytest.approx(0.1))
    vr_time = next(v.valueReference for v in md.modelVariables if v.name == "time")
    assert cs.getFloat64([vr_time])[0] == pytest.approx(0.1)
    with pytest.raises(FMICallException):
        cs.setFloat64([vr_time], [1.0])  # time is not settable
    with pytest.raises(FMICallException):
        cs.getFloat64([0])  # fmi_status is an Int32
    cs.freeInstance()
    me = FMU3Model(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.modelExchange.modelIdentifier,
                   instanceName="me")
    me.instantiate()
    me.enterInitializationMode(startTime=0.0)
    me.exitInitializationMode()
    with pytest.raises(FMICallException):  # continuous states are set in continuous-time mode
        me.setContinuousStates((ctypes.c_double * 2)(0.0, 0.0), 2)
    assert me.dll.fmi3GetEventIndicators(ctypes.c_void_p(me.component), (ctypes.c_double * 7)(), 7) > 0  # wrong size
    assert me.dll.fmi3GetContinuousStates(None, (ctypes.c_double * 2)(), 2) > 0  # NULL instance
    me.freeInstance()


CLOSED_LOOP_OUT = ["x", "v", "U", "mu_hat", "gamma_hat"]


def _closed_loop_me_bound(cs, rtol):
    """ME (CVode) against CS (DOP853) at the same rtol, per output: CVODE's budget 1000 rtol (max + 1) (the ME
    reference test's) plus the co-simulation's own 10 rtol max (GRAZE_BOUND)."""
    return {name: 1000 * rtol * (np.max(np.abs(cs[name])) + 1) + 10 * rtol * np.max(np.abs(cs[name]))
            for name in CLOSED_LOOP_OUT}


def test_closed_loop_model_exchange_runs_under_cvode(native_closed_loop_fmu):
    """The closed loop as FMI 2 ME: 11 states (x, v, the nine estimates), derivatives v, der(v), der(theta^_i);
    under CVode it follows the co-simulation within CVODE's budget over the first 20 time units."""
    assert validate_fmu(str(native_closed_loop_fmu)) == []
    md = read_model_description(str(native_closed_loop_fmu))
    assert md.modelExchange is not None and md.numberOfEventIndicators == 3
    assert [d.variable.derivative.name for d in md.derivatives] == ["x", "v", "mu_hat", "a1_hat", "a2_hat", "a3_hat",
                                                                    "a4_hat", "a5_hat", "Delta_hat", "beta_hat",
                                                                    "gamma_hat"]
    rtol, stop = 1e-10, 20.0
    cs = simulate_fmu(str(native_closed_loop_fmu), stop_time=stop, output_interval=0.1, output=CLOSED_LOOP_OUT,
                      relative_tolerance=rtol)
    me = simulate_fmu(str(native_closed_loop_fmu), fmi_type="ModelExchange", solver="CVode", relative_tolerance=rtol,
                      stop_time=stop, output_interval=0.1, output=CLOSED_LOOP_OUT)
    bound = _closed_loop_me_bound(cs, rtol)
    for name in CLOSED_LOOP_OUT:
        assert np.max(np.abs(me[name] - cs[name])) <= bound[name], name
    assert np.ptp(me["mu_hat"]) > 0.0  # the estimates move
    # in co-simulation der(v), der(mu_hat) are computed when read: the slopes of v, mu_hat (central differences at
    # h = 0.01: h^2/6 times the third derivative <= 2e-5 where it is <= 1; the outputs' own error 10 rtol / h
    # <= 1e-5)
    fine = simulate_fmu(str(native_closed_loop_fmu), stop_time=2.0, output_interval=0.01,
                        output=["v", "der(v)", "mu_hat", "der(mu_hat)"])
    for name in ("v", "mu_hat"):
        slope = np.gradient(fine[name], 0.01)[1:-1]
        assert np.max(np.abs(fine[f"der({name})"][1:-1] - slope)) <= 1e-4, name
        assert np.max(np.abs(slope)) > 1e-4  # not trivially zero


@pytest.mark.slow
@pytest.mark.parametrize("name", ["controller", "closed_loop"])
def test_fmi3_cosimulation_of_the_other_models(name, request):
    """The controller and the closed loop as FMI 3.0 Co-Simulation (no early return: no contact events of their own
    located by the layer; event mode accepted): validate silent, the default experiment FMI 2's bits; the closed
    loop's FMI 3 ME under CVode follows its co-simulation on the default experiment (tau 0..200)."""
    native2 = request.getfixturevalue(f"native_{name}_fmu")
    fmu3 = request.getfixturevalue(f"{name}_fmi3")
    assert validate_fmu(str(fmu3)) == []
    md = read_model_description(str(fmu3))
    assert md.modelExchange is not None and not md.coSimulation.mightReturnEarlyFromDoStep
    if name == "closed_loop":
        rtol = 1e-10
        cs = simulate_fmu(str(native2), output_interval=0.1, output=CLOSED_LOOP_OUT, relative_tolerance=rtol)
        me = simulate_fmu(str(fmu3), fmi_type="ModelExchange", solver="CVode", relative_tolerance=rtol,
                          output_interval=0.1, output=CLOSED_LOOP_OUT)
        bound = _closed_loop_me_bound(cs, rtol)
        for name_ in CLOSED_LOOP_OUT:
            assert np.max(np.abs(me[name_] - cs[name_])) <= bound[name_], name_
    outputs = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Float64"][:3]
    r2 = simulate_fmu(str(native2), stop_time=20.0, output_interval=0.1, output=outputs)
    r3 = simulate_fmu(str(fmu3), stop_time=20.0, output_interval=0.1, output=outputs, use_event_mode=True)
    for name_ in outputs:
        assert r3[name_].tobytes() == r2[name_].tobytes()


def test_fmu_state_holds_the_model_exchange_and_fmi3_state(native_plant_fmu, plant_fmi3, tmp_path):
    """FMI 2 ME: a state taken in continuous-time mode (and serialized) brings back the states and time it had; FMI
    3 CS with early return: a step redone from a restored (serialized) state gives the same bits."""
    # FMPy's FMI 2 logger is a process-wide proxy: without a live logger of its own, an instance that logs after
    # another test's logger was collected calls freed memory (hosts.run.FmuLog keeps its callback alive)
    log = FmuLog()
    md = read_model_description(str(native_plant_fmu))
    fmu = FMU2Model(guid=md.guid, unzipDirectory=extract(str(native_plant_fmu), str(tmp_path / "2")),
                    modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
    fmu.instantiate(callbacks=log.callbacks)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.newDiscreteStates()
    fmu.enterContinuousTimeMode()
    fmu.setTime(1.5)
    fmu.setContinuousStates((ctypes.c_double * 2)(0.25, -0.5), 2)
    state = fmu.deSerializeFMUstate(fmu.serializeFMUstate(fmu.getFMUstate()))
    fmu.setTime(2.0)
    fmu.setContinuousStates((ctypes.c_double * 2)(0.0, 0.0), 2)
    fmu.setFMUstate(state)
    x, dx = (ctypes.c_double * 2)(), (ctypes.c_double * 2)()
    fmu.getContinuousStates(x, 2)
    fmu.getDerivatives(dx, 2)
    assert list(x) == [0.25, -0.5] and dx[0] == -0.5
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    assert fmu.getReal([vrs["a"]])[0] == dx[1]  # the output a is the derivative of v, at the restored time
    fmu.freeFMUstate(state)
    fmu.freeInstance()
    assert log.errors() == []

    md3 = read_model_description(str(plant_fmi3))
    cs = FMU3Slave(guid=md3.guid, unzipDirectory=extract(str(plant_fmi3), str(tmp_path / "3")),
                   modelIdentifier=md3.coSimulation.modelIdentifier, instanceName="cs")
    cs.instantiate(earlyReturnAllowed=True)
    vr3 = {v.name: v.valueReference for v in md3.modelVariables}
    cs.setFloat64([vr3[name] for name in IMPACTS], list(IMPACTS.values()))
    cs.enterInitializationMode(startTime=0.0)
    cs.exitInitializationMode()
    t = 0.0
    while t < 17.0:  # the first contact loss is at tau = 17.23
        t = cs.doStep(t, 0.5)[3]
    saved = cs.deserializeFMUState(cs.serializeFMUState(cs.getFMUState()))
    first = cs.doStep(t, 0.5), cs.getFloat64([vr3["x"], vr3["time"]])
    cs.setFMUState(saved)
    again = cs.doStep(t, 0.5), cs.getFloat64([vr3["x"], vr3["time"]])
    assert first == again and first[0][2]  # the same early return, the same bits
    cs.freeFMUState(saved)
    cs.freeInstance()


@pytest.mark.parametrize("fidelity", [0, 1])
def test_directional_derivatives_are_the_finite_differences(native_plant_fmu, plant_fmi3, tmp_path, fidelity):
    """fmi2/fmi3GetDirectionalDerivative of a, F_contact, F_electrostatic by x, v, U (Model Exchange, at a point in
    contact and one in free flight) against central differences of the outputs with h = 1e-5. Bound 1e-8: the
    truncation h^2/6 max|f'''| <= 2e-11 (f''' of the Hertz law is (1 + 2x/3)^(-3/2)/... <= 2 here, the electrostatic
    terms are ~alpha), the rounding 2 eps max|f| / h <= 1e-10 for |f| <= 2; a wrong slope is off by O(0.1)."""
    # FMPy's FMI 2 logger is a process-wide proxy: without a live logger of its own, an instance that logs after
    # another test's logger was collected calls freed memory (hosts.run.FmuLog keeps its callback alive)
    log = FmuLog()
    md = read_model_description(str(native_plant_fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Model(guid=md.guid, unzipDirectory=extract(str(native_plant_fmu), str(tmp_path / "2")),
                    modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
    fmu.instantiate(callbacks=log.callbacks)
    fmu.setupExperiment(startTime=0.0)
    fmu.setReal([vr["R"], vr["alpha"], vr["beta"], vr["gamma"]], [2.0, 0.05, 0.02, 0.03])  # electrostatics visible
    fmu.setInteger([vr["fidelity"]], [fidelity])
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.newDiscreteStates()
    fmu.enterContinuousTimeMode()
    unknowns = [vr["a"], vr["F_contact"], vr["F_electrostatic"]]
    h = 1e-5

    def outputs(t, x, v, U):
        fmu.setTime(t)
        fmu.setContinuousStates((ctypes.c_double * 2)(x, v), 2)
        fmu.setReal([vr["U"]], [U])
        return np.array(fmu.getReal(unknowns))

    for t, x, v, U in ((1.3, 0.3, 0.2, 0.01), (2.1, -2.0, 0.5, -0.02)):
        for k, known in enumerate(("x", "v", "U")):
            step = np.eye(3)[k] * h
            slope = (outputs(t, *(np.array([x, v, U]) + step)) - outputs(t, *(np.array([x, v, U]) - step))) / (2 * h)
            outputs(t, x, v, U)
            analytic = fmu.getDirectionalDerivative(unknowns, [vr[known]], [1.0])
            assert np.max(np.abs(np.array(analytic) - slope)) <= 1e-8, (x, known, analytic, slope)
    assert fmu.getDirectionalDerivative([vr["v"]], [vr["x"], vr["v"]], [2.0, 3.0]) == [3.0]  # v is a state
    from fmpy.fmi1 import FMICallException

    with pytest.raises(FMICallException):  # not a provided pair
        fmu.getDirectionalDerivative([vr["in_contact"]], [vr["x"]], [1.0])
    fmu.freeInstance()
    assert log.errors() == [f"[error] fmi2GetDirectionalDerivative: the derivative of valueReference {vr['in_contact']} "
                            f"by valueReference {vr['x']} is not provided (provided: the derivatives of x, v, a, "
                            "F_contact, F_electrostatic by x, v, U)"]
    assert md.modelExchange.providesDirectionalDerivative and md.coSimulation.providesDirectionalDerivative
    # FMI 3: the same partials through fmi3GetDirectionalDerivative, in co-simulation at the start point
    md3 = read_model_description(str(plant_fmi3))
    with zipfile.ZipFile(plant_fmi3) as z:  # FMI 3.0's attribute is plural (FMPy 0.3.32 reads the singular)
        root = ET.fromstring(z.read("modelDescription.xml"))
    assert {root.find(tag).get("providesDirectionalDerivatives") for tag in ("ModelExchange", "CoSimulation")} == {
        "true"}
    cs = FMU3Slave(guid=md3.guid, unzipDirectory=extract(str(plant_fmi3), str(tmp_path / "3")),
                   modelIdentifier=md3.coSimulation.modelIdentifier, instanceName="cs")
    cs.instantiate()
    cs.enterInitializationMode(startTime=0.0)
    cs.exitInitializationMode()
    x0 = 0.04  # x_start: in contact, d a / d x = -(1 + 2 x0 / 3)^(1/2) + the electrostatic slope (alpha ~ 1e-3)
    assert cs.getDirectionalDerivative([vr["F_contact"], vr["a"]], [vr["x"]], [1.0]) == pytest.approx(
        [np.sqrt(1 + 2 * x0 / 3), -np.sqrt(1 + 2 * x0 / 3)], abs=1e-2)
    with pytest.raises(FMICallException):  # nSensitivity must be nUnknowns
        cs.getDirectionalDerivative([vr["a"]], [vr["x"]], [1.0], nSensitivity=2)
    cs.freeInstance()


def test_fmi3_takes_any_resource_path_and_none(native_plant_fmu, plant_fmi3, tmp_path):
    """FMI 3.0 gives the resources as a file system path (any characters: here a space and a '%') or NULL (no
    resources folder, or no path to give); the FMI 3.0 layer turns it into the percent-encoded file URI that
    fmi2Instantiate's check decodes back to the same folder (a raw 'file://' + path failed for both)."""
    from fmpy.fmi3 import fmi3IntermediateUpdateCallback, fmi3LogMessageCallback

    folder = extract(str(plant_fmi3), str(tmp_path / "a b%20c"))
    three = simulate_fmu(folder, stop_time=1.0, output_interval=0.1, output=["x"])
    two = simulate_fmu(str(native_plant_fmu), stop_time=1.0, output_interval=0.1, output=["x"])
    np.testing.assert_array_equal(three["x"], two["x"])  # the same bits: FMI 3.0 maps each call onto FMI 2.0's
    md = read_model_description(folder)
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="null")
    log = fmi3LogMessageCallback(lambda *args: None)
    c = fmu.fmi3InstantiateCoSimulation(b"null", md.guid.encode(), None, False, False, False, False, None, 0, None,
                                        log, fmi3IntermediateUpdateCallback())
    assert c  # NULL resourcePath: the native FMU reads no resources
    fmu.fmi3FreeInstance(c)
    fmu.freeLibrary()


def test_model_exchange_stops_at_pull_in_with_the_co_simulations_message(native_plant_fmu):
    """Pull-in under Model Exchange (the plant's me_stop_at_pull_in): CVode stops at the upper gap's indicator zero,
    the FMU asks the host to stop (terminateSimulation) with one warning, the co-simulation's pull-in message, whose
    tau is the last output time (printed to 10 digits: 1e-9) and whose gap 1 - 2x/(3R) there is PULL_IN_GAP (CVode's
    event location to its root tolerance, far below 1e-9)."""
    import re

    log = []
    scene = dict(alpha=0.025, R=0.2, x_start=0.2)  # the upper electrode pulls the plate in at tau ~ 1.92
    result = simulate_fmu(str(native_plant_fmu), fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10,
                          start_values=scene, stop_time=5.0, output_interval=0.01, output=["x"],
                          logger=lambda c, i, status, category, message: log.append((status, message.decode())))
    stopped = [(status, text) for status, text in log if "simulation stopped" in text]
    assert len(stopped) == 1 and stopped[0][0] == 1, stopped  # one fmi2Warning
    match = re.fullmatch(r"simulation stopped: pull-in: upper gap 1 - 2x/\(3R\) below 0\.001 at tau = (\S+), "
                         r"x = \S+ \(terminateSimulation\)", stopped[0][1])
    assert match, stopped[0][1]
    assert abs(result["time"][-1] - float(match.group(1))) <= 1e-9
    assert abs(1.0 - 2.0 * result["x"][-1] / (3.0 * scene["R"]) - 1e-3) <= 1e-9


@pytest.mark.slow
def test_fmi3_event_mode_step_budget_bounds_the_whole_do_step(plant_fmi3, tmp_path):
    """With event mode and no early return, fmi3DoStep goes through each contact event with internal doSteps; the
    step budget (10^6 solver steps) bounds the whole call, as it bounds a doStep without events.  A doStep of 200
    over the IMPACTS scene with max_step 2e-4 passes the up-front check (200 / 2e-4 = 10^6 steps, the budget) but
    takes more: DOP853 (the default solver) steps at max_step (its error-controlled step is far larger here) and
    cuts a step at each of the 56 contact changes.  Without event mode the call stops with the budget's error; in
    event mode it stopped there too only per internal doStep (each between two events, far under 10^6 steps), so
    the call took them all and answered OK."""
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi3 import fmi3LogMessageCallback

    md = read_model_description(str(plant_fmi3))
    folder = extract(str(plant_fmi3), str(tmp_path / "u"))
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    outcomes = {}
    for event_mode in (False, True):
        messages = []
        log = fmi3LogMessageCallback(lambda env, status, category, message: messages.append(message.decode()))
        fmu = FMU3Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="budget")
        fmu.instantiate(eventModeUsed=event_mode, earlyReturnAllowed=False, logMessage=log)
        names = [name for name in IMPACTS if name in vrs] + ["max_step"]
        fmu.setFloat64([vrs[n] for n in names], [float(IMPACTS.get(n, 2e-4)) for n in names])
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        if event_mode:
            fmu.updateDiscreteStates()
            fmu.enterStepMode()
        with pytest.raises(FMICallException):
            fmu.doStep(0.0, STOP)
        outcomes[event_mode] = [m for m in messages if "steps reached only" in m]
        fmu.freeInstance()
    assert outcomes[False] and outcomes[True], outcomes
