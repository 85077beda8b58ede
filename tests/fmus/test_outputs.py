"""All outputs of a communication point belong to that point (issue 13 item 4): after do_step(t, h, U) the forces and
the acceleration are the model's at (t + h, x, v) with the held input, for every fidelity and both kernels, and the
FMU's getters (the C fast path included) return those values. Before the fix F_electrostatic (and fidelities 1, 2's
F_contact drive term) were evaluated with x(t + h) but the drive at t."""
import numpy as np
import pytest

from vibrofmu.fmus import kernel
from vibrofmu.hosts.run import FmuInstance
from vibromodel.compiled import CompiledPlant
from vibromodel.fidelities import make_model
from vibromodel.parameters import Scene
from vibromodel.plant import Plant, Settings

# A strong, fast AC drive: between t and t + h = t + 0.1 the drive beta sin(Omega t) + gamma (1 - cos 2 Omega t) moves
# by O(beta Omega h) = O(0.1), far above rounding, so an output taken at the wrong time cannot pass an equality test.
SCENE = Scene(beta=0.05, gamma=0.02, Omega=3.0, Delta=0.3)
CASES = [(fidelity, solver) for fidelity in (0, 1, 2) for solver in (0, 1)]


def check_point(model, t, out, U):
    """Outputs out (plant.Outputs) against the model at (t, out.x, out.v), exactly: the same function, the same
    arguments."""
    f_contact, f_electrostatic = model.forces(t, out.x)
    assert (out.F_contact, out.F_electrostatic) == (f_contact, f_electrostatic)
    assert out.a == model.accel(t, out.x, out.v, U)


@pytest.mark.parametrize("fidelity, solver", CASES)
def test_outputs_are_the_models_at_the_new_communication_point(fidelity, solver):
    library = kernel.kernel_library()
    settings = Settings(fidelity=fidelity, solver=solver)
    model = make_model(SCENE, fidelity)
    for plant in (Plant(SCENE, settings), CompiledPlant(SCENE, settings, library)):
        for i in range(30):
            U = 0.01 * i
            out = plant.do_step(plant.t, 0.1, U)
            check_point(model, plant.t, out, U)


@pytest.mark.parametrize("fidelity", [3])
def test_open_loop_fidelity_outputs_are_at_the_new_point(fidelity):
    plant = Plant(SCENE, Settings(fidelity=fidelity), stop_time=3.0)
    model = make_model(SCENE, fidelity)  # their forces are Eq. 3's at their x
    for _ in range(30):
        out = plant.do_step(plant.t, 0.1, 0.0)
        assert model.forces(plant.t, out.x) == (out.F_contact, out.F_electrostatic)


@pytest.mark.parametrize("kernel_choice", [0, 1])
def test_fmu_getters_return_the_outputs_at_the_new_point(plant_fmu, kernel_choice):
    model = make_model(SCENE, 0)
    with FmuInstance(plant_fmu, f"outputs{kernel_choice}") as instance:
        fmu = instance.fmu
        fmu.setupExperiment(startTime=0.0, stopTime=10.0)
        fmu.enterInitializationMode()
        instance.set({**SCENE.as_dict(), "kernel": kernel_choice})
        fmu.exitInitializationMode()
        refs = instance.value_references(["x", "v", "a", "F_contact", "F_electrostatic"])
        for i in range(20):
            fmu.doStep(i * 0.1, 0.1)
            x, v, a, f_contact, f_electrostatic = fmu.getReal(refs)
            t = i * 0.1 + 0.1  # the plant's clock: the host's t + h, as Plant.do_step takes it
            assert (f_contact, f_electrostatic) == model.forces(t, x)
            assert a == model.accel(t, x, v, 0.0)
            assert np.isfinite([x, v]).all()
