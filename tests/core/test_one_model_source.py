"""The fidelity registry's model object is what every path computes: a rung whose model is not the scene's own
model of its compiled kind ("exact model, doubled damping": ExactModel(scene.with_values(mu=2 mu)), compiled model
EXACT) runs in the compiled plant and closed loop as in Python, to the bit, and the native FMUs' build refuses it
naming what is missing (they fill the core's model from the FMU's parameters, without Python).

Why the same bits: the compiled plant fills core/model.h's VkModel from the model object's compiled_fields() and
the kernel performs the Python plant's operations in the same order (tests/core/test_plant_kernel.py)."""
import struct
from dataclasses import replace

import pytest

from vibrofmu.fmus import kernel, toolchain
from vibromodel import fidelities
from vibromodel.compiled import CompiledPlant
from vibromodel.fidelities import Fidelity, c_header, native_mismatch
from vibromodel.models import ExactModel
from vibromodel.parameters import Scene
from vibromodel.plant import Plant, Settings


def doubled_damping(scene):
    return ExactModel(scene.with_values(mu=2 * scene.mu))


def doubled_entry(**changes):
    return replace(fidelities.REGISTRY[Fidelity.EXACT], model=doubled_damping, **changes)


@pytest.fixture(scope="module")
def library():
    return kernel.kernel_library()


def x_trace(plant, n=200, h=0.1):
    """The bits of x at n communication points of step h."""
    return [struct.pack("<d", plant.do_step(plant.t, h, 0.0).x) for _ in range(n)]


def test_the_compiled_plant_runs_the_registrys_model_not_the_scenes(library, monkeypatch):
    """Level 0's entry replaced by the doubled-damping rung (the enum and the rules stay: a level added by the recipe
    is checked on a throw-away branch, docs/architecture.md): Python and the kernel give the same x to the bit, and
    that x is the exact model's at mu = 0.2, not at the scene's 0.1 (the kernel once filled its model from the scene
    and gave the undoubled x)."""
    scene = Scene()  # the paper scene, mu = 0.1
    doubled_scene = scene.with_values(mu=2 * scene.mu)
    undoubled, expected = x_trace(Plant(scene, Settings())), x_trace(Plant(doubled_scene, Settings()))
    assert undoubled != expected  # the rung changes x: the agreement below is not the standard model's
    monkeypatch.setitem(fidelities.REGISTRY, Fidelity.EXACT, doubled_entry())
    python, compiled = Plant(scene, Settings()), CompiledPlant(scene, Settings(), library)
    assert python.model.scene.mu == 0.2 and compiled._plant.model.mu == 0.2
    # the tolerance factor (2/mu and 2/(2 mu) both below 150: 1) and the drive's ceiling do not depend on mu here,
    # so the run at mu = 0.2 of the unpatched registry is the rung's run, bit for bit
    assert x_trace(python) == expected
    assert x_trace(compiled) == expected


def test_the_native_build_refuses_a_rung_it_cannot_compute(monkeypatch):
    """c_header() (core/fidelity.h) and so the kernel's and the native FMUs' builds (kernel.check_fidelity_header)
    refuse the rung, naming the field that differs and what to add."""
    assert native_mismatch(fidelities.REGISTRY[Fidelity.EXACT]) is None
    monkeypatch.setitem(fidelities.REGISTRY, Fidelity.EXACT, doubled_entry())
    assert "mu is 0.2 on the paper scene" in native_mismatch(fidelities.REGISTRY[Fidelity.EXACT])
    with pytest.raises(toolchain.RegistryNotBuildable) as refused:
        kernel.check_fidelity_header()
    assert "fidelity 0 (exact): its model's mu is 0.2" in str(refused.value)
    assert "give its registry entry a native_refusal" in str(refused.value)


def test_a_rung_with_a_native_refusal_builds_and_the_native_fmus_refuse_it(monkeypatch):
    """With a native_refusal the header carries the refusal (the native FMUs log it at fidelity = 0); the header then
    differs from the committed one, and the build says to regenerate it."""
    why = "the native FMU cannot double the damping"
    monkeypatch.setitem(fidelities.REGISTRY, Fidelity.EXACT, doubled_entry(native_refusal=why))
    assert f'"{why} (fidelity 0 needs Python)"}},  /* 0 exact */' in c_header()
    with pytest.raises(toolchain.RegistryNotBuildable, match="regenerate it with `python3 -m vibrofmu.fmus.kernel`"):
        kernel.check_fidelity_header()


def test_a_model_of_another_compiled_kind_is_refused(monkeypatch):
    """An entry whose model is not of its c_model would run another equation in C: the header refuses it."""
    monkeypatch.setitem(fidelities.REGISTRY, Fidelity.POLYNOMIAL,
                        replace(fidelities.REGISTRY[Fidelity.POLYNOMIAL], model=ExactModel))
    with pytest.raises(ValueError, match="its model ExactModel has compiled model EXACT, the entry says POLYNOMIAL"):
        c_header()


def test_every_parameter_of_the_equation_reaches_the_core_and_a_missing_field_is_refused(monkeypatch):
    """Each of parameters.model_parameter_names() is a VkModel field (the native set-up copies them by name from
    rules.h's SCENE_MODEL_FIELDS), and a model field the core's VkModel lacks (a scene parameter added without its
    core/model.h field) stops fill_model naming it, instead of staying a Python attribute the C never reads."""
    from vibromodel.compiled import fill_model
    from vibromodel.core_layouts import VkModel
    from vibromodel.parameters import model_parameter_names

    fields = {name for name, _ in VkModel._fields_}
    assert set(model_parameter_names()) <= fields
    model = ExactModel(Scene())
    monkeypatch.setattr(model, "compiled_fields", lambda: ExactModel.compiled_fields(model) | {"kappa": 0.5})
    with pytest.raises(ValueError, match="VkModel has no field kappa"):
        fill_model(VkModel(), model)
