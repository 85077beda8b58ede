"""FMU state, fmi2Reset and several instances of the controller and the closed-loop FMUs (the plant's:
test_fmu_state.py, test_instances.py).

Run to tau1, save, run to tau2 (A); restore, run to tau2 again (B): A == B exactly, and the same from a
serialized state deserialized into a fresh instance with the same parameters. The controller's inputs are
driven by deterministic signals, set before every step.
"""
import math

import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException

from test_fmu_state import check_round_trips
from vibromodel.control import ESTIMATE_NAMES

pytestmark = pytest.mark.fmu  # every test here asks for FMUs by name (request.getfixturevalue)

ERROR = 3
TAU1, TAU2 = 7.3, 14.1
STOP = 200.0  # the default experiment: the closed loop's OAFM reference is the one packed in the FMU
SIZES = (0.1, 0.37, 0.013, 1.1, 0.25)  # an irregular step sequence


def controller_inputs(t):
    """Plant and reference signals for the controller's inputs x, v, x_ref, v_ref, a_ref."""
    return {"x": 0.01 + 0.05 * math.cos(0.9 * t), "v": -0.045 * math.sin(0.9 * t),
            "x_ref": 0.04 * math.cos(t), "v_ref": -0.04 * math.sin(t), "a_ref": -0.04 * math.cos(t)}


FMUS = {  # starter fixture, outputs compared, inputs(t) or None
    "controller": ("start_controller", ["U", "e1", "e2", "V", *ESTIMATE_NAMES], controller_inputs),
    "closed-loop": ("start_closed_loop",
                    ["x", "v", "x_ref", "U", "e1", "e2", "V", "V_rate", "V_rate_promised", *ESTIMATE_NAMES], None),
}
CASES = {  # FMU, start values
    "controller": ("controller", {}),
    "controller-literal": ("controller", {"law": 2, "lambda1": 2.0, "mu_hat_start": 0.3}),
    "closed-loop": ("closed-loop", {}),
    "closed-loop-rk4": ("closed-loop", {"solver": 1}),
    "closed-loop-damped-multitone": ("closed-loop", {"law": 1, "reference": 2, "fidelity": 1}),
}


def schedule(tau_end=TAU2):
    steps, t = [], 0.0
    while t < tau_end - 1e-12:
        h = min(SIZES[len(steps) % len(SIZES)], tau_end - t)
        steps.append((t, h))
        t += h
    return steps


def split(steps, tau):
    before = [s for s in steps if s[0] < tau - 1e-12]
    return before, steps[len(before):]


@pytest.fixture
def fmu(request):
    """(start, run) of one FMU: start(**values) -> FmuInstance; run(instance, steps) -> outputs after each."""
    starter, outputs, inputs = FMUS[request.param]
    start = request.getfixturevalue(starter)

    def run(instance, steps):
        refs = instance.value_references(outputs)
        rows = []
        for t, h in steps:
            if inputs is not None:
                instance.set(inputs(t))
            instance.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            rows.append(tuple(instance.fmu.getReal(refs)))
        return rows

    return lambda **values: start(stop_time=STOP, **values), run


@pytest.mark.parametrize("case,fmu", [(case, which) for case, (which, _) in CASES.items()],
                         indirect=["fmu"], ids=list(CASES))
def test_restore_and_deserialize_reproduce_the_run_bit_for_bit(case, fmu):
    start, run = fmu
    values = CASES[case][1]
    before, after = split(schedule(), TAU1)
    first, fresh = start(**values), start(**values)
    try:
        _, A = check_round_trips(first, fresh, run, before, after)
        assert len(set(A)) == len(A)  # the outputs do move
    finally:
        first.close()
        fresh.close()


@pytest.mark.parametrize("fmu", FMUS, indirect=True)
def test_a_state_of_another_fmu_is_refused_with_fmi2error(fmu, plant_fmu, start_plant):
    start, _ = fmu
    plant, instance = start_plant(), start()
    try:
        data = plant.fmu.serializeFMUstate(plant.fmu.getFMUstate())
        with pytest.raises(FMICallException) as failure:
            instance.fmu.setFMUstate(instance.fmu.deSerializeFMUstate(data))
        assert failure.value.status == ERROR
        assert "fmi2SetFMUstate refused: not a state of this FMU" in instance.log.errors()[-1]
    finally:
        plant.close()
        instance.close()


@pytest.mark.parametrize("fmu", FMUS, indirect=True)
def test_interleaved_instances_equal_separate_runs(fmu):
    start, run = fmu
    scenes = [{}, {"law": 1, "lambda2": 2.0}]
    steps = schedule(3.0)
    separate = []
    for values in scenes:
        with start(**values) as instance:
            separate.append(run(instance, steps))
    instances = [start(**values) for values in scenes]
    try:
        interleaved = [[] for _ in scenes]
        for step in steps:
            for instance, rows in zip(instances, interleaved):
                rows += run(instance, [step])
    finally:
        for instance in instances:
            instance.close()
    assert interleaved == separate
    assert separate[0][-1] != separate[1][-1]  # the scenes do differ


@pytest.mark.parametrize("fmu", FMUS, indirect=True)
def test_reset_returns_to_start_values_and_reruns_identically(fmu):
    start, run = fmu
    changed = {"law": 1, "lambda2": 2.0, "mu_hat_start": 0.3}
    steps = schedule(3.0)
    with start(**changed) as instance:
        starts = {v.name: v.start for v in read_model_description(instance.unzip_dir).modelVariables}
        first = run(instance, steps)
        instance.fmu.reset()
        instance.fmu.enterInitializationMode()  # FMI 2.0: no getters in the instantiated state
        lambda2, mu_hat = instance.fmu.getReal(instance.value_references(["lambda2", "mu_hat"]))
        (law,) = instance.fmu.getInteger(instance.value_references(["law"]))
        assert (lambda2, mu_hat, law) == (float(starts["lambda2"]), float(starts["mu_hat_start"]), int(starts["law"]))
        with pytest.raises(FMICallException):  # not initialised any more
            instance.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)
        instance.fmu.reset()  # leaves the error state too
        instance.fmu.setupExperiment(startTime=0.0, stopTime=STOP)
        instance.fmu.enterInitializationMode()
        instance.set(changed)
        instance.fmu.exitInitializationMode()
        assert run(instance, steps) == first


@pytest.mark.parametrize("fmu_path", ["plant_fmu", "controller_fmu", "closed_loop_fmu"])
def test_model_descriptions_declare_state_support(request, fmu_path):
    cs = read_model_description(str(request.getfixturevalue(fmu_path))).coSimulation
    assert cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
