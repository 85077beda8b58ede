"""FMU state: fmi2GetFMUstate/SetFMUstate and (de)serialization reproduce a run bit for bit.

Run to tau1, save, run to tau2 (A); restore, run to tau2 again (B): A == B exactly, and the same
from a serialized state deserialized into a fresh instance with the same parameters.
"""
import math

import pytest
from fmpy.fmi1 import FMICallException

OUTPUTS = ["x", "v", "a", "F_contact", "F_electrostatic"]
ERROR = 3

CONTACT_SCENE = {"x_start": -1.3, "v_start": -0.8, "R": 2.0}  # leaves the contact and re-impacts
PULL_IN_SCENE = {"x_start": 0.29, "R": 0.2}  # pull-in at tau = 0.135

TAU1, TAU2 = 7.3, 14.1
CASES = {  # start values, input U changes, tau1
    "adaptive": ({}, True, TAU1),
    "rk4": ({"solver": 1}, True, TAU1),
    "polynomial": ({"fidelity": 1}, True, TAU1),
    "averaged": ({"fidelity": 3}, False, TAU1),  # open loop: U stays 0
    "analytic": ({"fidelity": 4}, False, TAU1),  # open loop: U stays 0
    "between-contacts": (CONTACT_SCENE, True, 0.2),  # in free flight at tau1, re-impacts after it
    "rk4-between-contacts": ({**CONTACT_SCENE, "solver": 1}, True, 0.2),
}


def schedule(with_input):
    """(t, h, U or None) of an irregular step sequence from 0 to TAU2; U changes before and after TAU1."""
    steps, t = [], 0.0
    sizes = (0.1, 0.37, 0.013, 1.1, 0.25)
    while t < TAU2 - 1e-12:
        h = min(sizes[len(steps) % len(sizes)], TAU2 - t)
        U = None
        if with_input and len(steps) == 3:
            U = 0.03
        if with_input and len(steps) == 30:
            U = -0.02
        steps.append((t, h, U))
        t += h
    return steps


def run(instance, steps):
    """doStep through steps; the outputs (and in_contact) after each."""
    refs = instance.value_references(OUTPUTS)
    contact = instance.value_references(["in_contact"])
    rows = []
    for t, h, U in steps:
        if U is not None:
            instance.set({"U": U})
        instance.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        rows.append(tuple(instance.fmu.getReal(refs)) + tuple(instance.fmu.getBoolean(contact)))
    return rows


def split(steps, tau):
    before = [s for s in steps if s[0] < tau - 1e-12]
    return before, steps[len(before):]


def check_round_trips(first, fresh, run, before, after):
    """run(first, before), save, run(first, after) (A); restore, run again: A; serialize, deserialize into
    fresh (same parameters, initialised), run: A. Returns (the outputs at the save, A)."""
    saved = run(first, before)[-1]
    state = first.fmu.getFMUstate()
    A = run(first, after)
    first.fmu.setFMUstate(state)
    assert run(first, after) == A
    data = first.fmu.serializeFMUstate(state)
    first.fmu.freeFMUstate(state)
    restored = fresh.fmu.deSerializeFMUstate(data)
    fresh.fmu.setFMUstate(restored)
    fresh.fmu.freeFMUstate(restored)
    assert run(fresh, after) == A
    return saved, A


@pytest.mark.parametrize("case", CASES)
def test_restore_and_deserialize_reproduce_the_run_bit_for_bit(start_plant, case):
    values, with_input, tau1 = CASES[case]
    before, after = split(schedule(with_input), tau1)
    first = start_plant(stop_time=20.0, **values)
    fresh = start_plant(stop_time=20.0, **values)
    try:
        saved, A = check_round_trips(first, fresh, run, before, after)
        if "contact" in case:  # saved out of contact (contact event state saved), contact found after
            assert not saved[-1] and any(row[-1] for row in A)
    finally:
        first.close()
        fresh.close()


def test_a_state_can_be_restored_more_than_once(start_plant):
    before, after = split(schedule(True), TAU1)
    with start_plant(stop_time=20.0) as instance:
        run(instance, before)
        state = instance.fmu.getFMUstate()
        results = []
        for _ in range(3):
            instance.fmu.setFMUstate(state)
            results.append(run(instance, after))
        assert results[0] == results[1] == results[2]


def test_restore_after_pull_in_error_continues_as_before(start_plant):
    """The FMI 2.0 recovery path: a state saved before an error, restored after it."""
    instance = start_plant(**PULL_IN_SCENE)
    steps = [(0.02 * i, 0.02, None) for i in range(100)]
    try:
        run(instance, steps[:3])
        state = instance.fmu.getFMUstate()

        def until_error():
            rows = []
            with pytest.raises(FMICallException) as failure:
                for step in steps[3:]:
                    rows += run(instance, [step])
            assert failure.value.status == ERROR
            return rows, instance.log.errors()[-1]

        rows_a, error_a = until_error()
        instance.fmu.setFMUstate(state)  # fmi2OK: leaves the error state
        rows_b, error_b = until_error()
        assert "pull-in" in error_a and error_a == error_b
        assert rows_a == rows_b and len(rows_a) > 0
    finally:
        instance.close()


def test_restore_after_a_refused_step_continues_as_before(start_plant):
    before, after = split(schedule(True), TAU1)
    reference = start_plant(stop_time=20.0)
    instance = start_plant(stop_time=20.0)
    try:
        run(reference, before)
        A = run(reference, after)
        run(instance, before)
        state = instance.fmu.getFMUstate()
        with pytest.raises(FMICallException):
            instance.fmu.doStep(currentCommunicationPoint=123.0, communicationStepSize=0.1)
        assert "currentCommunicationPoint" in instance.log.errors()[-1]
        instance.fmu.setFMUstate(state)
        assert run(instance, after) == A
    finally:
        reference.close()
        instance.close()


def test_a_state_saved_after_an_error_restores_the_error(start_plant):
    """Saving is allowed in the error state; restoring such a state says so with fmi2Error."""
    instance = start_plant(**PULL_IN_SCENE)
    fresh = start_plant(**PULL_IN_SCENE)
    try:
        with pytest.raises(FMICallException):
            run(instance, [(0.1 * i, 0.1, None) for i in range(100)])
        halted_at = instance.fmu.getReal(instance.value_references(OUTPUTS))
        data = instance.fmu.serializeFMUstate(instance.fmu.getFMUstate())
        with pytest.raises(FMICallException) as failure:
            fresh.fmu.setFMUstate(fresh.fmu.deSerializeFMUstate(data))
        assert failure.value.status == ERROR
        assert "restored a state saved after an error: simulation stopped: pull-in" in fresh.log.errors()[-1]
        assert fresh.fmu.getReal(fresh.value_references(OUTPUTS)) == halted_at
        with pytest.raises(FMICallException):
            fresh.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)
    finally:
        instance.close()
        fresh.close()


@pytest.mark.parametrize("data", [b"", b"\xff\xfe", b"[1, 2]", b'{"format": "something else"}', b"{" * 100000])
def test_foreign_state_bytes_are_refused_with_fmi2error(start_plant, data):
    with start_plant() as instance:
        state = instance.fmu.deSerializeFMUstate(data)
        with pytest.raises(FMICallException) as failure:
            instance.fmu.setFMUstate(state)
        assert failure.value.status == ERROR
        assert "fmi2SetFMUstate refused: not a state of this FMU" in instance.log.errors()[-1]
        instance.fmu.reset()  # and the instance is usable again
        instance.fmu.setupExperiment(startTime=0.0)
        instance.fmu.enterInitializationMode()
        instance.fmu.exitInitializationMode()
        instance.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)
        assert all(map(math.isfinite, instance.fmu.getReal(instance.value_references(OUTPUTS))))
