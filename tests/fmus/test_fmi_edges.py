"""The native plant at the edges of its domain, FMI 2.0 and 3.0, each case in a subprocess (a crash fails the test):
  - directional derivatives at an electrode (x = +-3R/2, where the electrostatic slope is infinite and
    GetDerivatives refuses) are refused with fmi2Error / fmi3Error naming the pair, never NaN or inf with OK;
  - Model Exchange started at rest on the contact surface (x = -3/2, v = 0: the contact indicator starts at 0, so
    no sign change tells the host) has in_contact = 1 from its first event on, as the co-simulation after its first
    step (the plant then moves into the contact: x rises);
  - event indicators at a state set beyond the model's numerical range (x = 1.8e308, finite, so SetContinuousStates
    takes it: the contact indicator 1 + 2x/3 overflows) are refused with fmi2Error / fmi3Error and a log line naming
    the indicator, never inf with OK (found by the fuzz campaign in the closed loop; the plant's the same);
  - FMI 3.0 co-simulation with event mode and without early return sets eventHandlingNeeded at every contact change
    (the 28-impact scene of test_native_me_fmi3: 56 changes, each seen on the output grid).
"""
import json
import math
import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.fmu
OK, ERROR = 0, 3


def run(script: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(script)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"the host died (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    return json.loads(proc.stdout.strip().splitlines()[-1])


DIRECTIONAL = """
    import ctypes, json
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Model
    from fmpy.fmi3 import FMU3Model
    fmu, version = {fmu!r}, {version}
    md = read_model_description(fmu)
    vr = {{v.name: v.valueReference for v in md.modelVariables}}
    log = []
    logger = lambda *args: log.append(str(args[-1]))
    results = []
    for x in (3.0, -3.0, 2.9):  # R = 2: the electrodes at +-3; 2.9 inside (finite: answered)
        if version == 2:
            m = FMU2Model(guid=md.guid, unzipDirectory=extract(fmu), modelIdentifier=md.modelExchange.modelIdentifier,
                          instanceName="e")
            m.instantiate(loggingOn=False)
            m.setReal([vr["R"]], [2.0])
            m.setupExperiment(startTime=0.0)
            m.enterInitializationMode(); m.exitInitializationMode()
            m.newDiscreteStates(); m.enterContinuousTimeMode()
            m.setContinuousStates((ctypes.c_double * 2)(x, 0.0), 2)
            out = (ctypes.c_double * 1)()
            known = (ctypes.c_uint * 1)(vr["x"])
            unknown = (ctypes.c_uint * 1)(vr["a"])
            seed = (ctypes.c_double * 1)(1.0)
            status = m.dll.fmi2GetDirectionalDerivative(m.component, unknown, 1, known, 1, seed, out)
        else:
            m = FMU3Model(guid=md.guid, unzipDirectory=extract(fmu), modelIdentifier=md.modelExchange.modelIdentifier,
                          instanceName="e")
            m.instantiate()
            m.setFloat64([vr["R"]], [2.0])
            m.enterInitializationMode(); m.exitInitializationMode()
            m.updateDiscreteStates(); m.enterContinuousTimeMode()
            m.setContinuousStates((ctypes.c_double * 2)(x, 0.0), 2)
            out = (ctypes.c_double * 1)()
            status = m.dll.fmi3GetDirectionalDerivative(m.component, (ctypes.c_uint * 1)(vr["a"]), 1, (ctypes.c_uint * 1)(vr["x"]),
                                                        1, (ctypes.c_double * 1)(1.0), 1, out, 1)
        results.append(dict(x=x, status=status, value=out[0] if status == 0 else None))
        m.freeInstance()
    print(json.dumps(dict(results=results)))
"""


@pytest.mark.parametrize("version", [2, 3])
def test_directional_derivatives_at_an_electrode_are_refused(native_plant_fmu, plant_fmi3, version):
    fmu = str(native_plant_fmu if version == 2 else plant_fmi3)
    results = run(DIRECTIONAL.format(fmu=fmu, version=version))["results"]
    at_electrodes, inside = results[:2], results[2]
    for r in at_electrodes:
        assert r["status"] == ERROR, r  # NaN / inf with OK before
    assert inside["status"] == OK
    assert math.isfinite(inside["value"]) and inside["value"] != 0.0


BEYOND = """
    import ctypes, json, sys
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Model
    from fmpy.fmi3 import FMU3Model
    fmu, version = {fmu!r}, {version}
    md = read_model_description(fmu)
    log = []
    kwargs = dict(guid=md.guid, unzipDirectory=extract(fmu), modelIdentifier=md.modelExchange.modelIdentifier,
                  instanceName="e")
    if version == 2:
        m = FMU2Model(**kwargs)
        m.instantiate(loggingOn=True)
        m.setupExperiment(startTime=0.0)
        m.enterInitializationMode(); m.exitInitializationMode()
        m.newDiscreteStates(); m.enterContinuousTimeMode()
        get = m.dll.fmi2GetEventIndicators
    else:
        m = FMU3Model(**kwargs)
        m.instantiate(loggingOn=True)
        m.enterInitializationMode(); m.exitInitializationMode()
        m.updateDiscreteStates(); m.enterContinuousTimeMode()
        get = m.dll.fmi3GetEventIndicators
    n, ni = md.numberOfContinuousStates, md.numberOfEventIndicators
    states = (ctypes.c_double * n)()
    m.getContinuousStates(states, n)
    results = []
    for x in (states[0], sys.float_info.max):  # the start (answered), then the largest finite x
        states[0] = x
        m.setContinuousStates(states, n)
        z = (ctypes.c_double * ni)()
        status = get(m.component, z, ni)
        results.append(dict(x=x, status=status, z=list(z)))
    print(json.dumps(dict(results=results)))
"""


@pytest.mark.parametrize("name, version", [("native_plant_fmu", 2), ("plant_fmi3", 3), ("native_closed_loop_fmu", 2),
                                           ("closed_loop_fmi3", 3)])
def test_event_indicators_beyond_the_numerical_range_are_refused(request, name, version):
    fmu = str(request.getfixturevalue(name))
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(BEYOND.format(fmu=fmu, version=version))],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"the host died (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    start, beyond = json.loads(proc.stdout.strip().splitlines()[-1])["results"]
    assert start["status"] == OK and all(map(math.isfinite, start["z"])), start
    assert beyond["status"] == ERROR, beyond  # inf with OK before
    assert "GetEventIndicators: event indicator 0 = inf at x = 1.7976931348623157e+308" in proc.stdout + proc.stderr


EDGE = """
    import json
    from fmpy import simulate_fmu
    start = dict(x_start=-1.5, v_start=0.0, R=2.0)
    me = simulate_fmu({fmu!r}, fmi_type="ModelExchange", start_values=start, stop_time=2.0,
                      output=["x", "in_contact"], output_interval=0.1)
    cs = simulate_fmu({fmu!r}, fmi_type="CoSimulation", start_values=start, stop_time=2.0,
                      output=["x", "in_contact"], output_interval=0.1)
    print(json.dumps(dict(me_contact=me["in_contact"].tolist(), me_x=me["x"].tolist(), cs_contact=cs["in_contact"].tolist(),
                          cs_x=cs["x"].tolist())))
"""


def test_model_exchange_at_rest_on_the_contact_surface(native_plant_fmu):
    r = run(EDGE.format(fmu=str(native_plant_fmu)))
    assert r["me_x"][0] == -1.5 and max(r["me_x"]) > -1.5  # it moves into the contact
    assert all(r["me_contact"]), r["me_contact"]  # 0 for the whole run before
    assert all(r["cs_contact"]), r["cs_contact"]  # the co-simulation too, from its start (0 at t = 0 before)


CS_EDGE = """
    import json
    from fmpy import simulate_fmu
    runs = {{kernel: simulate_fmu({fmu!r}, start_values=dict(x_start=-1.5, v_start=0.0, R=2.0, kernel=kernel),
                                 stop_time=0.5, output=["x", "in_contact"], output_interval=0.1)
            for kernel in (0, 1)}}
    print(json.dumps({{k: dict(contact=r["in_contact"].tolist(), x=r["x"].tolist()) for k, r in runs.items()}}))
"""


def test_co_simulation_at_rest_on_the_contact_surface_is_in_contact_from_its_start(plant_fmu):
    """The pythonfmu plant on both kernels (0: the compiled core, 1: pure Python) as the native one: at rest on the
    surface with the forces pushing in (x'' = 1 there at U = 0), in_contact is 1 at t = 0, not only after a step."""
    r = run(CS_EDGE.format(fmu=str(plant_fmu)))
    for kernel, run_ in r.items():
        assert run_["x"][0] == -1.5 and run_["x"][1] > -1.5, kernel  # it moves into the contact
        assert all(run_["contact"]), (kernel, run_["contact"])


EVENTS = """
    import json
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave
    fmu = {fmu!r}
    md = read_model_description(fmu)
    vr = {{v.name: v.valueReference for v in md.modelVariables}}
    s = FMU3Slave(guid=md.guid, unzipDirectory=extract(fmu), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="ev")
    s.instantiate(eventModeUsed=True, earlyReturnAllowed=False)
    s.enterInitializationMode(startTime=0.0, stopTime=200.0)
    s.setFloat64([vr[k] for k in ("Delta", "omega", "R", "x_start", "v_start")], [0.3, 0.95, 5.0, 0.0, 0.0])
    s.exitInitializationMode()
    s.updateDiscreteStates()
    s.enterStepMode()
    h, events, flips, prev, early = 0.1, 0, 0, None, 0
    for k in range(2000):
        needed, terminate, early_return, last = s.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
        early += bool(early_return)
        contact = s.getBoolean([vr["in_contact"]])[0]
        flips += prev is not None and contact != prev
        prev = contact
        if needed:
            events += 1
            s.enterEventMode(); s.updateDiscreteStates(); s.enterStepMode()
    print(json.dumps(dict(events=events, flips=flips, early=early)))
"""


def test_fmi3_event_mode_without_early_return_reports_each_contact_change(plant_fmi3):
    r = run(EVENTS.format(fmu=str(plant_fmi3)))
    # test_native_me_fmi3's IMPACTS scene: 56 contact changes in [0, 200], each on its own 0.1 step (no two in one
    # step: the grid sees each flip), so each doStep with one sets eventHandlingNeeded; none returns early
    assert r["early"] == 0
    assert r["flips"] == 56 and r["events"] == 56, r
