"""The solver registry (vibromodel/solvers.py) and its readers agree with each other and with the compiled core's
table (core/solver.h: vk_solvers, in the order of VK_SOLVER_LIST)."""
import ctypes

import pytest

from vibrofmu.analyses.simulate import SOLVERS as CLI_SOLVERS
from vibrofmu.fmus import kernel
from vibromodel import solvers
from vibromodel.integrate import Dop853, Integrator, Rk4
from vibromodel.parameters import RULES, ParameterError, Scene
from vibromodel.plant import Plant
from vibromodel.settings import Settings, Solver


def test_the_compiled_table_lists_the_registry_in_order():
    """vk_solvers[k]->name (VkSolverOps's first field) is the name of the registry's entry of value k, and the table
    has one entry per registry entry that the compiled core has."""
    library = kernel.kernel_library()
    count = ctypes.c_int.in_dll(library, "vk_n_solvers").value
    table = (ctypes.POINTER(ctypes.c_char_p) * count).in_dll(library, "vk_solvers")
    names = [table[k][0].decode() for k in range(count)]
    assert names == [solvers.solver_entry(k).name for k in range(count)]
    assert count == sum(entry.compiled for entry in solvers.SOLVERS.values())


def test_settings_rule_and_cli_read_the_registry():
    values = sorted(entry.value for entry in solvers.SOLVERS.values())
    assert [int(member) for member in Solver] == values
    rule = next(rule for rule in RULES if rule.name == "solver")
    assert (rule.low, rule.high, rule.reason) == (values[0], values[-1], solvers.RULE_TEXT)
    assert sorted(CLI_SOLVERS.values()) == values
    assert solvers.RULE_TEXT == "0 adaptive DOP853, 1 fixed-step RK4"  # the FMUs' parameter description, unchanged
    with pytest.raises(ParameterError, match=r"must be 0 \(adaptive\) or 1 \(RK4\)"):
        Settings(solver=len(values)).validate()


@pytest.mark.parametrize("value, cls, scene, step", [
    (0, Dop853, Scene(), 4.0 / 4.0),  # max_step = 0: 4 rad of the fastest drive, gamma cos(2 Omega t), Omega = 2
    (0, Dop853, Scene(Delta=0.0, beta=0.0, gamma=0.0), float("inf")),  # no drive: no ceiling
    (0, Dop853, Scene(Delta=0.1, omega=30.0), 4.0 / 30.0),  # the load's omega = 30 is the fastest
    (1, Rk4, Scene(), 0.01)])
def test_a_plant_gets_the_integrator_of_its_entry(value, cls, scene, step):
    plant = Plant(scene, Settings(solver=value, kernel=1))
    assert type(plant.integrator) is cls and plant.integrator.max_step == step
    assert solvers.solver_entry(value).integrator_class is cls


def test_every_solver_is_on_the_protocol():
    """integrate.Integrator: each registry solver implements its stepping, dense output and input (an abstract method
    left out would make the class uninstantiable), and a solver the plant builds is one."""
    for entry in solvers.SOLVERS.values():
        assert issubclass(entry.integrator_class, Integrator) and not entry.integrator_class.__abstractmethods__
        plant = Plant(Scene(), Settings(solver=entry.value, kernel=1))
        assert isinstance(plant.integrator, Integrator)
