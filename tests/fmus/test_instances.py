"""Several instances in one process do not share state; fmi2Reset returns an instance to the state
after fmi2Instantiate (FMI 2.0: start values again, parameters set before the reset forgotten)."""
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException

OUTPUTS = ["x", "v", "a", "F_contact", "F_electrostatic", "in_contact"]
SCENES = [
    {},
    {"solver": 1, "R": 2.0, "mu": 0.2},
    {"x_start": -1.3, "v_start": -0.8, "R": 2.0},
    {"fidelity": 1, "Omega": 1.5},
]
STEPS = [(0.1 * i, 0.1) for i in range(150)]


def outputs(instance):
    reals = instance.fmu.getReal(instance.value_references(OUTPUTS[:-1]))
    return tuple(reals) + tuple(instance.fmu.getBoolean(instance.value_references(OUTPUTS[-1:])))


def test_interleaved_instances_equal_separate_runs(start_plant):
    separate = []
    for values in SCENES:
        with start_plant(**values) as instance:
            rows = []
            for t, h in STEPS:
                instance.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
                rows.append(outputs(instance))
            separate.append(rows)
    instances = [start_plant(**values) for values in SCENES]
    try:
        interleaved = [[] for _ in SCENES]
        for t, h in STEPS:
            for instance, rows in zip(instances, interleaved):
                instance.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
                rows.append(outputs(instance))
    finally:
        for instance in instances:
            instance.close()
    assert interleaved == separate
    assert len({rows[-1] for rows in separate}) == len(SCENES)  # the scenes do differ


def test_reset_returns_to_start_values_and_reruns_identically(plant_fmu, start_plant):
    starts = {v.name: v.start for v in read_model_description(str(plant_fmu)).modelVariables}
    changed = {"mu": 0.2, "R": 2.0, "solver": 1}
    with start_plant(**changed) as instance:
        def rerun():
            rows = []
            for t, h in STEPS[:50]:
                instance.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
                rows.append(outputs(instance))
            return rows

        first = rerun()
        instance.fmu.reset()
        instance.fmu.enterInitializationMode()  # FMI 2.0: no getters in the instantiated state
        mu, R = instance.fmu.getReal(instance.value_references(["mu", "R"]))
        (solver,) = instance.fmu.getInteger(instance.value_references(["solver"]))
        assert (mu, R, solver) == (float(starts["mu"]), float(starts["R"]), int(starts["solver"]))
        assert outputs(instance)[:2] == (float(starts["x"]), float(starts["v"]))
        with pytest.raises(FMICallException):  # not initialised any more
            instance.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)
        instance.fmu.reset()  # leaves the error state too
        instance.fmu.setupExperiment(startTime=0.0)
        instance.fmu.enterInitializationMode()
        instance.set(changed)
        instance.fmu.exitInitializationMode()
        assert rerun() == first
