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
