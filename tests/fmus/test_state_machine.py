"""The FMI 2.0 co-simulation state machine in the three FMUs (issue 15, item 2): every call the standard does
not allow in the current state gives fmi2Error with a log line naming the call and the state, never fmi2OK
and never fmi2Fatal; fmi2Reset works afterwards. The plant runs on both paths: the status shim's C fast path
(kernel 0) and pythonfmu (kernel 1).
"""
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
    instance.fmu.setupExperiment(startTime=0.0, stopTime=stop_time)
    instance.fmu.enterInitializationMode()
    instance.set(values)
    return instance, values, output, input_


def last_error(instance):
    errors = instance.log.errors()
    assert errors, "fmi2Error without a log message"
    return errors[-1]


def steps(instance, n, h=0.1, t0=0.0):
    for k in range(n):
        instance.fmu.doStep(currentCommunicationPoint=t0 + k * h, communicationStepSize=h)


def assert_reset_runs(instance, values, output):
    """fmi2Reset leaves the error state; the instance then initialises and steps again with finite output."""
    instance.fmu.reset()
    instance.fmu.setupExperiment(startTime=0.0)
    instance.fmu.enterInitializationMode()
    instance.set(values)
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
        assert status(instance.fmu.enterInitializationMode) == ERROR
        message = last_error(instance)
        assert "fmi2EnterInitializationMode" in message and "step mode" in message, message
        assert status(instance.fmu.exitInitializationMode) == ERROR  # the shim: not after an error
        assert_reset_runs(instance, values, output)


@pytest.mark.parametrize("which", FMUS)
def test_exit_initialisation_twice_and_setup_after_it_are_refused(request, which):
    instance, values, output, _ = new(request, which)
    with instance:
        instance.fmu.exitInitializationMode()
        assert status(instance.fmu.exitInitializationMode) == ERROR
        assert "fmi2ExitInitializationMode" in last_error(instance) and "step mode" in last_error(instance)
        assert_reset_runs(instance, values, output)
        assert status(instance.fmu.setupExperiment, None, 0.0) == ERROR
        assert "fmi2SetupExperiment" in last_error(instance) and "step mode" in last_error(instance)


@pytest.mark.parametrize("which", FMUS)
def test_step_before_initialisation_is_refused(request, which):
    instance, values, output, _ = new(request, which)
    with instance:
        assert status(instance.fmu.doStep, 0.0, 0.1) == ERROR
        assert "fmi2DoStep" in last_error(instance) and "initialization mode" in last_error(instance)
        assert_reset_runs(instance, values, output)


@pytest.mark.parametrize("which", FMUS)
def test_step_after_terminate_is_refused(request, which):
    """Issue 15: doStep after fmi2Terminate returned fmi2OK."""
    instance, values, output, _ = new(request, which)
    with instance:
        instance.fmu.exitInitializationMode()
        steps(instance, 2)
        before = instance.fmu.getReal(instance.value_references([output]))
        instance.fmu.terminate()
        assert status(instance.fmu.doStep, 0.2, 0.1) == ERROR
        assert "fmi2Terminate was called" in last_error(instance), last_error(instance)
        assert instance.fmu.getReal(instance.value_references([output])) == before  # nothing stepped
        assert_reset_runs(instance, values, output)


@pytest.mark.parametrize("which", FMUS)
def test_terminate_twice_and_setting_after_terminate_are_refused(request, which):
    instance, values, output, input_ = new(request, which)
    with instance:
        instance.fmu.exitInitializationMode()
        instance.fmu.terminate()
        assert status(instance.fmu.terminate) == ERROR
        assert "fmi2Terminate" in last_error(instance) and "terminated" in last_error(instance)
        assert_reset_runs(instance, values, output)
        if input_ is not None:
            instance.fmu.terminate()
            assert status(instance.set, {input_: 0.01}) == ERROR
            assert "terminated state" in last_error(instance)


@pytest.mark.parametrize("which", FMUS)
def test_step_beyond_the_stop_time_is_refused(request, which):
    """Issue 15: doStep beyond the declared stop time returned fmi2OK. Steps up to it (t + h an ulp past
    the stop included, as hosts compute start + n h) run; the fast path forwards the step past it."""
    instance, values, output, _ = new(request, which, stop_time=0.3)
    with instance:
        instance.fmu.exitInitializationMode()
        steps(instance, 3)  # 0.1 * 2 + 0.1 = 0.30000000000000004 > 0.3: within the tolerance
        before = instance.fmu.getReal(instance.value_references([output]))
        assert status(instance.fmu.doStep, 0.30000000000000004, 0.1) == ERROR
        message = last_error(instance)
        assert "parameter communicationStepSize = 0.1" in message and "stop time 0.3" in message, message
        assert instance.fmu.getReal(instance.value_references([output])) == before
        if which == "plant_fast":
            assert instance.fast_path_steps() == 3


@pytest.mark.parametrize("which", FMUS)
def test_setting_an_output_is_refused(request, which):
    """Issue 15: setReal on an output before initialisation returned fmi2OK and was ignored."""
    instance, values, output, _ = new(request, which)
    with instance:
        assert status(instance.set, {output: 0.5}) == ERROR
        message = last_error(instance)
        assert f"parameter {output} = 0.5" in message and "output" in message, message
        assert_reset_runs(instance, values, output)


@pytest.mark.parametrize("which", FMUS)
def test_get_with_unknown_reference_or_wrong_type_is_an_error_not_fatal(request, which):
    """Issue 15: an unknown value reference or the wrong type gave fmi2Fatal (reset fatal afterwards). Each getter,
    each way, then fmi2Reset and a run."""
    instance, values, output, _ = new(request, which)
    with instance:
        for getter, kind in (("getReal", "Real"), ("getInteger", "Integer"), ("getBoolean", "Boolean")):
            for vr in (max(v.valueReference for v in instance.variables.values()) + 1000,
                       next(v.valueReference for v in instance.variables.values() if v.type not in (kind, "String"))):
                instance.fmu.exitInitializationMode()
                steps(instance, 1)
                assert status(getattr(instance.fmu, getter), [vr]) == ERROR
                message = last_error(instance)
                assert f"fmi2G{getter[1:]}" in message and str(vr) in message, message
                assert_reset_runs(instance, values, output)
                instance.fmu.reset()
                instance.fmu.setupExperiment(startTime=0.0)
                instance.fmu.enterInitializationMode()
                instance.set(values)


@pytest.mark.parametrize("which", ["plant_fast", "controller", "closed_loop"])
def test_get_before_initialisation_is_refused(request, which):
    from vibrofmu.hosts.run import FmuInstance

    name, values, output, _ = FMUS[which]
    with FmuInstance(request.getfixturevalue(f"{name}_fmu"),
                     unzip_dir=request.getfixturevalue(f"{name}_unzipped")) as instance:
        assert status(instance.fmu.getReal, instance.value_references([output])) == ERROR
        assert "instantiated state" in last_error(instance)
        assert_reset_runs(instance, values, output)


@pytest.mark.parametrize("which", FMUS)
def test_set_with_unknown_reference_or_wrong_type_is_an_error_not_fatal(request, which):
    instance, values, output, _ = new(request, which)
    with instance:
        for setter, kind, value in (("setReal", "Real", 1.0), ("setInteger", "Integer", 1),
                                    ("setBoolean", "Boolean", True)):
            for vr in (max(v.valueReference for v in instance.variables.values()) + 1000,
                       next(v.valueReference for v in instance.variables.values()
                            if v.type not in (kind, "String") and v.causality == "parameter")):
                assert status(getattr(instance.fmu, setter), [vr], [value]) == ERROR
                message = last_error(instance)
                assert str(vr) in message or "not of type" in message, message
                assert_reset_runs(instance, values, output)
                instance.fmu.reset()
                instance.fmu.setupExperiment(startTime=0.0)
                instance.fmu.enterInitializationMode()
                instance.set(values)
