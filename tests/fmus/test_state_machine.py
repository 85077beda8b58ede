"""The FMI 2.0 co-simulation state machine in the three FMUs (issue 15, item 2): every call the standard does
not allow in the current state gives fmi2Error with a log line naming the call and the state, never fmi2OK
and never fmi2Fatal; fmi2Reset works afterwards. The plant runs on both paths: the status shim's C fast path
(kernel 0) and pythonfmu (kernel 1). The native FMUs' Model Exchange (every one offers it) likewise: each call out
of its mode is fmi2Error with a log line, and fmi2Reset gives a working instance.
"""
import ctypes
import math

import pytest
from fmpy.fmi1 import FMICallException

pytestmark = pytest.mark.fmu  # every test here asks for FMUs by name (request.getfixturevalue)

OK, ERROR = 0, 3
FMUS = {  # fixture prefix, start values, an output, an input or None
    "plant_fast": ("plant", {"kernel": 0}, "x", "U"),
    "plant_python": ("plant", {"kernel": 1}, "x", "U"),
    "controller": ("controller", {}, "U", "x"),
    "closed_loop": ("closed_loop", {"reference": 1}, "x", None),
}


def status(call, *args):
    try:
        call(*args)
        return OK
    except FMICallException as error:
        return error.status


def new(request, which, stop_time=None):
    """(instance, its start values, output, input) set up, in initialization mode."""
    from vibrofmu.hosts.run import FmuInstance

    name, values, output, input_ = FMUS[which]
    instance = FmuInstance(request.getfixturevalue(f"{name}_fmu"), unzip_dir=request.getfixturevalue(f"{name}_unzipped"))
    initialise(instance, values, stop_time)
    return instance, values, output, input_


def initialise(instance, values, stop_time=None):
    """setupExperiment from 0, enterInitializationMode and the start values."""
    instance.fmu.setupExperiment(startTime=0.0, stopTime=stop_time)
    instance.fmu.enterInitializationMode()
    instance.set(values)


def last_error(instance):
    errors = instance.log.errors()
    assert errors, "fmi2Error without a log message"
    return errors[-1]


def assert_refused(instance, call, *args, says=(), unchanged=None):
    """call(*args) ends in fmi2Error with a log line holding each of `says` (and leaves the output `unchanged`,
    where named: nothing stepped)."""
    before = None if unchanged is None else instance.fmu.getReal(instance.value_references([unchanged]))
    assert status(call, *args) == ERROR
    message = last_error(instance)
    assert all(words in message for words in says), message
    if unchanged is not None:
        assert instance.fmu.getReal(instance.value_references([unchanged])) == before


def wrong_references(instance, kind, causality=None):
    """A value reference no variable has, and one of a variable not of type `kind` (nor String; of `causality`
    where given)."""
    variables = instance.variables.values()
    return (max(v.valueReference for v in variables) + 1000,
            next(v.valueReference for v in variables
                 if v.type not in (kind, "String") and causality in (None, v.causality)))


def steps(instance, n, h=0.1, t0=0.0):
    for k in range(n):
        instance.fmu.doStep(currentCommunicationPoint=t0 + k * h, communicationStepSize=h)


def assert_reset_runs(instance, values, output):
    """fmi2Reset leaves the error state; the instance then initialises and steps again with finite output."""
    instance.fmu.reset()
    initialise(instance, values)
    instance.fmu.exitInitializationMode()
    steps(instance, 3)
    assert math.isfinite(instance.fmu.getReal(instance.value_references([output]))[0])


@pytest.mark.parametrize("which", FMUS)
def test_initialisation_again_after_steps_is_refused(request, which):
    """Issue 15: enter + exitInitializationMode after 10 doSteps returned fmi2OK and reset the plant to 0."""
    instance, values, output, _ = new(request, which)
    with instance:
        instance.fmu.exitInitializationMode()
        steps(instance, 10)
        assert_refused(instance, instance.fmu.enterInitializationMode,
                       says=("fmi2EnterInitializationMode", "step mode"))
        assert status(instance.fmu.exitInitializationMode) == ERROR  # the shim: not after an error
        assert_reset_runs(instance, values, output)


# Calls the standard does not allow in a state, each: the state (None: still in initialization mode; else the
# number of doSteps of 0.1 after fmi2ExitInitializationMode), whether fmi2Terminate came next, the refused call
# and its arguments, the words its log line must hold, whether the output must stay as it was (nothing stepped).
REFUSED_CALLS = {
    "exit_initialisation_twice": (0, False, "exitInitializationMode", (), ("fmi2ExitInitializationMode", "step mode"),
                                  False),
    "setup_after_initialisation": (0, False, "setupExperiment", (None, 0.0), ("fmi2SetupExperiment", "step mode"),
                                   False),
    "step_before_initialisation": (None, False, "doStep", (0.0, 0.1), ("fmi2DoStep", "initialization mode"), False),
    # issue 15: doStep after fmi2Terminate returned fmi2OK
    "step_after_terminate": (2, True, "doStep", (0.2, 0.1), ("fmi2Terminate was called",), True),
    "terminate_twice": (0, True, "terminate", (), ("fmi2Terminate", "terminated"), False),
}


@pytest.mark.parametrize("case", REFUSED_CALLS)
@pytest.mark.parametrize("which", FMUS)
def test_a_call_out_of_its_state_is_refused(request, which, case):
    stepped, terminated, call, args, says, unchanged = REFUSED_CALLS[case]
    instance, values, output, _ = new(request, which)
    with instance:
        if stepped is not None:
            instance.fmu.exitInitializationMode()
            steps(instance, stepped)
        if terminated:
            instance.fmu.terminate()
        assert_refused(instance, getattr(instance.fmu, call), *args, says=says, unchanged=output if unchanged else None)
        assert_reset_runs(instance, values, output)


@pytest.mark.parametrize("which", [name for name, (*_, input_) in FMUS.items() if input_ is not None])
def test_setting_an_input_after_terminate_is_refused(request, which):
    instance, values, output, input_ = new(request, which)
    with instance:
        instance.fmu.exitInitializationMode()
        instance.fmu.terminate()
        assert_refused(instance, instance.set, {input_: 0.01}, says=("terminated state",))


@pytest.mark.parametrize("which", FMUS)
def test_step_beyond_the_stop_time_is_refused(request, which):
    """Issue 15: doStep beyond the declared stop time returned fmi2OK. Steps up to it (t + h an ulp past
    the stop included, as hosts compute start + n h) run; the fast path forwards the step past it."""
    instance, values, output, _ = new(request, which, stop_time=0.3)
    with instance:
        instance.fmu.exitInitializationMode()
        steps(instance, 3)  # 0.1 * 2 + 0.1 = 0.30000000000000004 > 0.3: within the tolerance
        assert_refused(instance, instance.fmu.doStep, 0.30000000000000004, 0.1,
                       says=("parameter communicationStepSize = 0.1", "stop time 0.3"), unchanged=output)
        if which == "plant_fast":
            assert instance.fast_path_steps() == 3


@pytest.mark.parametrize("which", FMUS)
def test_setting_an_output_is_refused(request, which):
    """Issue 15: setReal on an output before initialisation returned fmi2OK and was ignored."""
    instance, values, output, _ = new(request, which)
    with instance:
        assert_refused(instance, instance.set, {output: 0.5}, says=(f"parameter {output} = 0.5", "output"))
        assert_reset_runs(instance, values, output)


@pytest.mark.parametrize("which", FMUS)
def test_get_with_unknown_reference_or_wrong_type_is_an_error_not_fatal(request, which):
    """Issue 15: an unknown value reference or the wrong type gave fmi2Fatal (reset fatal afterwards). Each getter,
    each way, then fmi2Reset and a run."""
    instance, values, output, _ = new(request, which)
    with instance:
        for getter, kind in (("getReal", "Real"), ("getInteger", "Integer"), ("getBoolean", "Boolean")):
            for vr in wrong_references(instance, kind):
                instance.fmu.exitInitializationMode()
                steps(instance, 1)
                assert_refused(instance, getattr(instance.fmu, getter), [vr], says=(f"fmi2G{getter[1:]}", str(vr)))
                assert_reset_runs(instance, values, output)
                instance.fmu.reset()
                initialise(instance, values)  # for the next reference


@pytest.mark.parametrize("which", ["plant_fast", "controller", "closed_loop"])
def test_get_before_initialisation_is_refused(request, which):
    from vibrofmu.hosts.run import FmuInstance

    name, values, output, _ = FMUS[which]
    with FmuInstance(request.getfixturevalue(f"{name}_fmu"),
                     unzip_dir=request.getfixturevalue(f"{name}_unzipped")) as instance:
        assert_refused(instance, instance.fmu.getReal, instance.value_references([output]),
                       says=("instantiated state",))
        assert_reset_runs(instance, values, output)


@pytest.mark.parametrize("which", FMUS)
def test_set_with_unknown_reference_or_wrong_type_is_an_error_not_fatal(request, which):
    instance, values, output, _ = new(request, which)
    with instance:
        for setter, kind, value in (("setReal", "Real", 1.0), ("setInteger", "Integer", 1),
                                    ("setBoolean", "Boolean", True)):
            for vr in wrong_references(instance, kind, causality="parameter"):
                assert status(getattr(instance.fmu, setter), [vr], [value]) == ERROR
                message = last_error(instance)
                assert str(vr) in message or "not of type" in message, message
                assert_reset_runs(instance, values, output)
                instance.fmu.reset()
                initialise(instance, values)  # for the next reference


# ---- Model Exchange (the native FMUs, FMI 2.0: every one offers it) ----

def _me_cases(m, nx):
    """(state reached by `setup`, call name, the call) for calls FMI 2.0 Model Exchange does not allow there."""
    x = (ctypes.c_double * max(nx, 1))()

    def init():
        m.setupExperiment(startTime=0.0)
        m.enterInitializationMode()

    def event():
        init()
        m.exitInitializationMode()

    def continuous():
        event()
        m.newDiscreteStates()
        m.enterContinuousTimeMode()

    def terminated():
        continuous()
        m.terminate()

    def nothing():
        return None

    step = m.dll.fmi2DoStep
    return [(nothing, "fmi2GetDerivatives", lambda: m.getDerivatives(x, nx)),
            (nothing, "fmi2SetTime", lambda: m.setTime(0.0)),
            (nothing, "fmi2NewDiscreteStates", m.newDiscreteStates),
            (init, "fmi2EnterContinuousTimeMode", m.enterContinuousTimeMode),
            (init, "fmi2SetContinuousStates", lambda: m.setContinuousStates(x, nx)),
            (event, "fmi2SetContinuousStates", lambda: m.setContinuousStates(x, nx)),
            (event, "fmi2CompletedIntegratorStep", m.completedIntegratorStep),
            (continuous, "fmi2NewDiscreteStates", m.newDiscreteStates),
            (continuous, "fmi2DoStep", lambda: _raise_on(step(ctypes.c_void_p(m.component), ctypes.c_double(0.0),
                                                                ctypes.c_double(0.1), 1))),
            (terminated, "fmi2SetTime", lambda: m.setTime(0.1))], continuous


def _raise_on(code):
    if code != OK:
        raise FMICallException(function="fmi2DoStep", status=code)


@pytest.mark.parametrize("name", ["plant", "controller", "closed_loop"])
def test_native_model_exchange_calls_out_of_their_mode_are_errors(request, name, tmp_path):
    """Each Model Exchange call in a state FMI 2.0 does not allow it in: fmi2Error with a log line naming the call,
    never fmi2OK nor a crash; fmi2Reset then gives a working instance (the states and derivatives finite)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Model

    from vibrofmu.hosts.run import FmuLog

    fmu = request.getfixturevalue(f"native_{name}_fmu")
    md = read_model_description(str(fmu))
    nx = len(md.derivatives)
    log = FmuLog()  # a live logger of this test's own (FMPy's FMI 2 logger is a process-wide proxy)
    m = FMU2Model(guid=md.guid, unzipDirectory=extract(str(fmu), str(tmp_path)),
                  modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
    m.instantiate(callbacks=log.callbacks)
    cases, continuous = _me_cases(m, nx)
    for setup, call, make_call in cases:
        m.reset()
        setup()
        assert status(make_call) == ERROR, (setup.__name__, call)
        assert any(call in text for text in log.errors()[-1:]), (setup.__name__, call, log.errors()[-1:])
    m.reset()
    continuous()
    x, dx = (ctypes.c_double * nx)(), (ctypes.c_double * nx)()
    m.getContinuousStates(x, nx)
    m.setTime(0.1)
    m.setContinuousStates(x, nx)
    m.getDerivatives(dx, nx)
    assert all(math.isfinite(v) for v in (*x, *dx))
    m.terminate()
    m.freeInstance()
