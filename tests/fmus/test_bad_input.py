"""Bad input: FMU returns fmi2Error with a log message naming the parameter; the CLI exits non-zero
with a one-line message; nothing crashes and no output is NaN."""
import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from vibrofmu.cli import main
from vibrofmu.hosts.run import FmuInstance, run_fmu

BAD_PARAMETERS = [
    ("R", 0.0), ("R", -1.0), ("x_start", 1.5), ("x_start", 2.0), ("x_start", -1.5), ("rtol", 0.0),
    ("rtol", -1e-6), ("max_step", -0.1), ("mu", -0.1), ("fidelity", 7), ("solver", 3),
] + [(name, bad) for name in ("mu", "Delta", "omega", "Omega", "alpha", "beta", "gamma", "R", "x_start",
                              "v_start", "rtol", "max_step") for bad in (math.nan, math.inf, -math.inf)]


def initialise(fmu, values):
    instance = FmuInstance(fmu)
    instance.fmu.setupExperiment(startTime=0.0)
    instance.fmu.enterInitializationMode()
    instance.set(values)
    return instance


def outputs_are_finite(instance):
    refs = instance.value_references(["x", "v", "a", "F_contact", "F_electrostatic"])
    return all(math.isfinite(v) for v in instance.fmu.getReal(refs))


@pytest.mark.parametrize("name,value", BAD_PARAMETERS)
def test_fmu_rejects_bad_parameter_with_fmi2error(plant_fmu, name, value):
    with initialise(plant_fmu, {name: value}) as instance:
        with pytest.raises(FMICallException) as failure:
            instance.fmu.exitInitializationMode()
        assert failure.value.status == 3  # fmi2Error
        message = instance.log.errors()[-1]
        assert f"parameter {name} = " in message, message
        assert outputs_are_finite(instance)
        with pytest.raises(FMICallException) as step_failure:
            instance.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)
        assert step_failure.value.status == 3
        assert outputs_are_finite(instance)


@pytest.mark.parametrize("step", [-0.1, 0.0, math.nan, math.inf])
def test_fmu_rejects_bad_step_size(plant_fmu, step):
    with initialise(plant_fmu, {}) as instance:
        instance.fmu.exitInitializationMode()
        with pytest.raises(FMICallException) as failure:
            instance.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=step)
        assert failure.value.status == 3
        assert "communicationStepSize" in instance.log.errors()[-1]
        assert outputs_are_finite(instance)


def test_fmu_rejects_nan_input(plant_fmu):
    with initialise(plant_fmu, {}) as instance:
        instance.fmu.exitInitializationMode()
        instance.set({"U": math.nan})
        with pytest.raises(FMICallException) as failure:
            instance.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)
        assert failure.value.status == 3
        assert "parameter U = nan" in instance.log.errors()[-1]


@pytest.mark.parametrize("solver", [0, 1])
def test_pull_in_stops_with_error_naming_tau_and_x(run_plant, solver):
    run = run_plant(stop_time=10.0, solver=solver, x_start=0.29, R=0.2)
    assert not run.completed
    assert "pull-in" in run.stop_reason and "tau = " in run.stop_reason and "x = " in run.stop_reason
    assert "status 3" in run.stop_reason
    for values in run.outputs.values():
        assert np.all(np.isfinite(values))


@pytest.mark.parametrize("args,needle", [
    (["--set", "R=0"], "parameter R = 0.0"),
    (["--set", "x_start=1.6"], "parameter x_start = 1.6"),
    (["--set", "mu=nan"], "parameter mu = nan"),
    (["--set", "gamma=inf"], "parameter gamma = inf"),
    (["--rtol", "0"], "parameter rtol = 0.0"),
    (["--rtol", "-1"], "parameter rtol = -1.0"),
    (["--set", "bogus=1"], "parameter bogus = 1.0: unknown parameter"),
    (["--set", "mu=abc"], "parameter mu = 'abc': not a number"),
    (["--output-interval", "-0.1"], "parameter output-interval = -0.1"),
])
def test_cli_rejects_bad_input_with_one_line(tmp_path, capsys, plant_fmu, args, needle):
    code = main(["simulate", "--fmu", str(plant_fmu), "--out", str(tmp_path / "out"), *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("error: ") and needle in err[0], err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name,value", [("mu", 0.2), ("fidelity", 1), ("x", 0.5), ("fmi_status", 0)])
def test_setting_fixed_parameters_or_outputs_after_initialisation_is_refused(plant_fmu, name, value):
    with initialise(plant_fmu, {}) as instance:
        instance.fmu.exitInitializationMode()
        with pytest.raises(FMICallException) as failure:
            instance.set({name: value})
        assert failure.value.status == 3
        assert f"parameter {name} = {value!r}: " in instance.log.errors()[-1]
        if name != "fmi_status":
            assert "cannot be set after fmi2ExitInitializationMode" in instance.log.errors()[-1]


def test_the_input_may_be_set_between_steps(plant_fmu):
    with initialise(plant_fmu, {}) as instance:
        instance.fmu.exitInitializationMode()
        instance.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)
        instance.set({"U": 0.01})
        instance.fmu.doStep(currentCommunicationPoint=0.1, communicationStepSize=0.1)
        assert outputs_are_finite(instance) and instance.log.errors() == []


def test_non_oscillating_linear_part_is_refused_by_the_analytic_fidelity(plant_fmu):
    """alpha = 1 makes a1 = 1 - 8/3 - ... < 0: no OAFM solution; the error names alpha (found by the fuzzing)."""
    run = run_fmu(plant_fmu, {"fidelity": 4, "alpha": 1.0}, 1.0, 0.1)
    assert not run.completed and "parameter alpha = 1.0" in run.stop_reason and "a1 = " in run.stop_reason
