"""The plant FMU's C fast path (fmi2_status_shim.c "Fast path", fast_path.py): with kernel = 0 the shim steps the
compiled plant and reads its outputs without Python. It must change nothing but the speed: every output, every
stop and every message equals the pure-Python FMU (kernel = 1) bit for bit, and it must actually be used.

Why bit for bit: the compiled plant performs the Python plant's operations in the same order, compiled with
-ffp-contract=off and without -ffast-math (tests/core/test_plant_kernel.py), and the shim passes the same
doubles in and out, so equality is the expectation, not luck."""
import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from vibrofmu.hosts.run import FmuInstance, run_fmu

SCENES = {
    "paper example": {},
    "contact loss and re-impact": {"x_start": -1.3, "v_start": -0.8, "R": 2.0},
    "pull-in": {"R": 0.2, "alpha": 0.05, "x_start": 0.25},
    "polynomial, ceiling": {"fidelity": 1, "max_step": 0.05},
    "RK4, contact loss and re-impact": {"solver": 1, "x_start": -1.3, "v_start": -0.8, "R": 2.0},
    "RK4 pull-in": {"solver": 1, "R": 0.2, "alpha": 0.05, "x_start": 0.25},
}


@pytest.mark.parametrize("scene", SCENES)
def test_fast_path_equals_the_python_fmu_bit_for_bit(plant_fmu, scene):
    compiled, python = (run_fmu(plant_fmu, {**SCENES[scene], "kernel": kernel}, 60.0, 0.1) for kernel in (0, 1))
    assert compiled.stop_reason == python.stop_reason
    assert np.array_equal(compiled.time, python.time)
    for name, values in python.outputs.items():
        assert np.array_equal(compiled.outputs[name], values), name
    if "pull-in" in scene:  # the scene must really stop, or it tests nothing
        assert "pull-in" in compiled.stop_reason and compiled.end_time < 60.0


def drive(plant_fmu, kernel: int, steps: int = 400, solver: int = 0):
    """A doStep loop with U changed before every step, outputs and parameters read together (a getReal the fast
    path must forward) and one FMU state round trip; returns (rows, fast steps)."""
    with FmuInstance(plant_fmu, f"kernel{kernel}") as instance:
        fmu = instance.fmu
        fmu.setupExperiment(startTime=0.0, stopTime=steps * 0.1)
        fmu.enterInitializationMode()
        instance.set({"kernel": kernel, "solver": solver})
        fmu.exitInitializationMode()
        refs = instance.value_references(["x", "v", "a", "F_contact", "F_electrostatic", "mu"])
        (u_ref,) = instance.value_references(["U"])
        rows, saved = [], None
        for i in range(steps):
            fmu.setReal([u_ref], [0.05 * math.sin(0.3 * i)])
            if i == steps // 2:
                saved = fmu.getFMUstate()
            fmu.doStep(i * 0.1, 0.1)
            rows.append(fmu.getReal(refs) + [float(b) for b in fmu.getBoolean(instance.value_references(["in_contact"]))])
        fmu.setFMUstate(saved)  # back to the middle: the rest must repeat exactly
        for i in range(steps // 2, steps):
            fmu.setReal([u_ref], [0.05 * math.sin(0.3 * i)])
            fmu.doStep(i * 0.1, 0.1)
            assert fmu.getReal(refs[:5]) == rows[i][:5]
        return np.array(rows), instance.fast_path_steps()


@pytest.mark.parametrize("solver", [0, 1])
def test_fast_path_with_changing_input_state_restore_and_mixed_getters(plant_fmu, solver):
    compiled, n_fast = drive(plant_fmu, 0, solver=solver)
    python, n_python = drive(plant_fmu, 1, solver=solver)
    assert np.array_equal(compiled, python)
    assert n_fast == 400 + 200  # every doStep went through the fast path, also after fmi2SetFMUstate
    assert n_python == 0


def test_error_met_on_the_fast_path_is_reported_by_the_slave(plant_fmu):
    """A pull-in inside a fast-path doStep: the slave raises the pending error (fmi2Error, the pull-in message),
    publishes the state where it stopped and refuses further steps."""
    result = run_fmu(plant_fmu, {**SCENES["pull-in"], "kernel": 0}, 60.0, 0.1)
    assert not result.completed and "pull-in" in result.stop_reason
    assert all(np.isfinite(values).all() for values in result.outputs.values())
    with FmuInstance(plant_fmu) as instance:
        fmu = instance.fmu
        fmu.setupExperiment(startTime=0.0, stopTime=60.0)
        fmu.enterInitializationMode()
        instance.set(SCENES["pull-in"])
        fmu.exitInitializationMode()
        steps = round(result.end_time / 0.1)
        for i in range(steps):
            fmu.doStep(i * 0.1, 0.1)
        assert instance.fast_path_steps() == steps
        with pytest.raises(FMICallException):
            fmu.doStep(steps * 0.1, 0.1)
        assert instance.fast_path_steps() == steps
        with pytest.raises(FMICallException):
            fmu.doStep(steps * 0.1, 0.1)
        assert any("doStep" in m or "not allowed" in m for m in instance.log.errors())
