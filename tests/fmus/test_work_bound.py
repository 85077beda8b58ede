"""The per-doStep guard bounds work, not only steps (vibromodel.settings.step_budget): a step of the pure-Python
kernel costs about PYTHON_STEP_COST of the compiled one, so on kernel = 1 a doStep may take MAX_STEPS_PER_DOSTEP /
PYTHON_STEP_COST steps. A closed loop on the pure-Python kernel, RK4, max_step 1e-5, doStep of 9.99 (999,000 steps,
under the compiled kernel's 10^6) had not returned after 200 s; now it is refused up front with fmi2Error naming the
limit, and a doStep within the limit runs. Each FMU in a subprocess (a hang ends in its timeout, a crash in its exit
code); the pythonfmu plant and closed loop (the native FMUs run both kernels compiled: their limit is 10^6)."""
import json
import subprocess
import sys
import textwrap

import pytest

from vibromodel.settings import MAX_STEPS_PER_DOSTEP, PYTHON_STEP_COST, step_budget

pytestmark = pytest.mark.fmu

SCRIPT = """
    import json
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave
    fmu, h_long, h_short = {fmu!r}, {h_long!r}, {h_short!r}
    md = read_model_description(fmu)
    vr = {{v.name: v.valueReference for v in md.modelVariables}}
    def initialise():
        s.setupExperiment(startTime=0.0, stopTime=20.0)
        s.enterInitializationMode()
        s.setInteger([vr["kernel"], vr["solver"]], [1, 1])
        s.setReal([vr["max_step"]], [1e-5])
        s.exitInitializationMode()
    def step(h):
        try:
            s.doStep(currentCommunicationPoint=0.0, communicationStepSize=h)
            return 0
        except FMICallException as error:
            return error.status
    s = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="bound")
    s.instantiate(loggingOn=False)  # FMPy's default logger prints the FMU's messages (read below)
    initialise()
    status = step(h_long)
    s.reset()
    initialise()
    short = step(h_short)
    print(json.dumps(dict(long=status, short=short)))
"""


@pytest.mark.parametrize("fixture", ["closed_loop_fmu", "plant_fmu"])
def test_a_pure_python_do_step_beyond_the_work_bound_is_refused(request, fixture):
    fmu = request.getfixturevalue(fixture)
    budget = step_budget(1)
    assert budget == MAX_STEPS_PER_DOSTEP // PYTHON_STEP_COST < 999_000
    # 9.99 / 1e-5 = 999,000 steps: refused (beyond the pure-Python budget); a doStep of half the budget runs
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(SCRIPT.format(fmu=str(fmu), h_long=9.99,
                                                                               h_short=0.5 * budget * 1e-5))],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result == {"long": 3, "short": 0}, (result, proc.stdout[-3000:])
    log = proc.stdout + proc.stderr
    assert f"needs more than {budget} steps" in log and "pure-Python kernel" in log, log[-3000:]


CATCH_UP = """
    import json
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave
    fmu, start = {fmu!r}, {start!r}
    md = read_model_description(fmu)
    vr = {{v.name: v.valueReference for v in md.modelVariables}}
    s = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="catch_up")
    s.instantiate(loggingOn=False)
    statuses = []
    for offset in ({offsets}):
        s.setupExperiment(startTime=start)
        s.enterInitializationMode()
        s.setInteger([vr["solver"]], [1])
        s.setReal([vr["max_step"]], [1e-2])
        s.exitInitializationMode()
        try:
            s.doStep(currentCommunicationPoint=start * (1.0 + offset), communicationStepSize=1e-3)
            statuses.append(0)
        except FMICallException as error:
            statuses.append(error.status)
        s.reset()
    print(json.dumps(statuses))
"""


# the native closed loop starts at time 0 only (its reference is set up for it); its doStep is core/closedloop.c's,
# which the pythonfmu closed loop's compiled kernel runs here
@pytest.mark.parametrize("fixture", ["plant_fmu", "closed_loop_fmu", "native_plant_fmu"])
def test_the_catch_up_from_the_plants_time_to_the_hosts_is_bounded_as_the_step_is(request, fixture):
    """A host's communication point may differ from the FMU's time by 1e-9 relative (settings.TIME_TOLERANCE), and the
    solver covers the FMU's time .. t + h, not h. At start 1e17 an offset of 5e-10 relative is 5e7 of tau: 5e9 RK4
    steps of 0.01, beyond the doStep budget of 1e6 (the fuzzer found such a doStep: a hang, over 1e280 steps at t = 3e296).
    Refused now, naming currentCommunicationPoint; at start 1e12 the same offset is 500 of tau, 5e4 steps: run."""
    fmu = request.getfixturevalue(fixture)
    for start, expected in ((1e17, 3), (1e12, 0)):
        script = CATCH_UP.format(fmu=str(fmu), start=start, offsets="0.0, 5e-10")
        proc = subprocess.run([sys.executable, "-c", textwrap.dedent(script)], capture_output=True, text=True,
                              timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
        # offset 0: the plant's own time (t + h rounds to t at 1e17: nothing to step), always run
        assert json.loads(proc.stdout.strip().splitlines()[-1]) == [0, expected], proc.stdout[-3000:]
        if expected:
            assert "currentCommunicationPoint" in proc.stdout + proc.stderr, proc.stdout[-3000:]
