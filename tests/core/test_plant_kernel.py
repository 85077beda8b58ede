"""The compiled plant kernel (fmu_src/vibrokernel.c via vibromodel.compiled) against the Python plant: the same
bits at every communication point, the same evaluation and step counts, the same errors.

Why the same bits: core/*.c performs the Python plant's IEEE double operations in the same order (the same
formulas, the same branch decisions), compiled with -ffp-contract=off and without -ffast-math
(kernel.GCC_COMMAND: no fused multiply-add, no reassociation), with Python's float semantics where C's differ
(pyfloat.c); so any difference is a bug, not rounding."""
import ctypes
import json
import math
import struct
import subprocess

import numpy as np
import pytest
from message_text import Message

from vibrofmu.fmus import kernel
from vibromodel import compiled, plant as plant_module, settings as settings_module
from vibromodel.compiled import CompiledPlant, load_library
from vibromodel.fidelities import make_model
from vibromodel.integrate import IntegrationError, TerminalEvent, rk4_drive_gains
from vibromodel.parameters import ParameterError, Scene
from vibromodel.plant import Outputs, Plant, Settings

OUTPUT_FIELDS = ("x", "v", "a", "F_contact", "F_electrostatic", "in_contact")
PULL_IN_UPPER = Scene(R=0.2, x_start=0.29)  # starts next to the upper electrode
PULL_IN_LOWER = Scene(v_start=-3.0)  # thrown onto the lower electrode
RE_IMPACT = Scene(R=5.0, x_start=-2.0, Delta=0.5)  # electrodes far, forcing strong: loses contact, hits it again


@pytest.fixture(scope="session")
def library():
    return kernel.kernel_library()


def bits(value):
    """A float's exact bits (NaN payloads and the sign of zero included), recursively."""
    if isinstance(value, float):
        return struct.pack("<d", value)
    if isinstance(value, Outputs):
        return tuple(bits(getattr(value, name)) for name in OUTPUT_FIELDS)
    if isinstance(value, (tuple, list)):
        return tuple(bits(item) for item in value)
    return value


def is_error(result):
    return isinstance(result[0], type)


def state_bytes(snapshot):
    """A snapshot's bytes up to the pending error."""
    return bytes.fromhex(snapshot["kernel"])[:compiled.VkPlant.error.offset]


def counters(plant):
    ig = plant.integrator if isinstance(plant, Plant) else plant
    return ig.nfev, ig.n_steps


def outcome(call):
    """What call() gives: its result's bits, or the exception's type, "Type: text" (a message_text.Message: equal
    to another with the same words and numbers) and (t, x, v) bits."""
    try:
        return bits(call())
    except Exception as error:  # noqa: BLE001 -- every exception must match
        text = Message(f"{type(error).__name__}: {error}")
        return type(error), text, bits(tuple(getattr(error, n, None) for n in "txv"))


def trace(plant, steps):
    """do_step(plant.t, h, U) for each (h, U) of steps: outcomes and counters after each."""
    return [(outcome(lambda: plant.do_step(plant.t, h, U)), counters(plant)) for h, U in steps]


def assert_same_traces(scene, settings, steps, library):
    python = trace(Plant(scene, settings), steps)
    kernel_trace = trace(CompiledPlant(scene, settings, library), steps)
    for i, (expected, got) in enumerate(zip(python, kernel_trace)):
        assert got == expected, f"communication point {i}"
    return python


def held(n, dt=0.1, U=0.0):
    return [(dt, U)] * n


# -- bit identity ------------------------------------------------------------------------------------------
CASES = {
    "default": (Scene(), Settings(), held(2000)),
    "default rtol 1e-12": (Scene(), Settings(rtol=1e-12), held(2000)),
    "fidelity 1": (Scene(), Settings(fidelity=1), held(2000)),
    "fidelity 2": (Scene(), Settings(fidelity=2), held(2000)),
    "contact loss and re-impact": (RE_IMPACT, Settings(), held(1000)),
    "re-impact rtol 1e-12": (RE_IMPACT, Settings(rtol=1e-12), held(300)),
    "electrostatics off": (Scene(alpha=0.0, beta=0.0, gamma=0.0, x_start=-1.4), Settings(), held(1000)),
    "Delta = 0": (Scene(Delta=0.0), Settings(), held(1000)),
    "max_step ceiling": (Scene(), Settings(max_step=0.01), held(500)),
    "input changing": (Scene(), Settings(), [(0.1, 0.05 * math.sin(0.1 * i)) for i in range(1000)]),
    "input steps, fidelity 1": (Scene(), Settings(fidelity=1), held(20) + held(20, U=0.5) + held(200, U=-0.2)),
    "uneven communication steps": (RE_IMPACT, Settings(), [(h, 0.0) for h in (0.0137, 1e-6, 0.5, 3.7, 0.05) * 60]),
    "long communication steps": (Scene(), Settings(), held(20, dt=37.0)),
    "RK4": (Scene(), Settings(solver=1), held(500)),
    "RK4, fidelity 1, input changing": (Scene(), Settings(solver=1, fidelity=1),
                                        [(0.1, 0.05 * math.sin(0.1 * i)) for i in range(300)]),
    "RK4 contact loss and re-impact, uneven steps": (RE_IMPACT, Settings(solver=1, max_step=0.02),
                                                     [(h, 0.0) for h in (0.0137, 1e-6, 0.5, 0.05) * 40]),
}


@pytest.mark.parametrize("name", CASES)
def test_outputs_and_counts_are_bit_identical(name, library):
    scene, settings, steps = CASES[name]
    python = assert_same_traces(scene, settings, steps, library)
    assert not any(is_error(result) for result, _ in python)


def test_re_impact_case_crosses_the_contact_event(library):
    """The re-impact case exercises event location (brentq) both ways: in_contact changes often."""
    python = Plant(RE_IMPACT, Settings())
    contact = [python.do_step(python.t, 0.1, 0.0).in_contact for _ in range(1000)]
    assert sum(a != b for a, b in zip(contact, contact[1:])) >= 10


def test_advance_state_and_outputs_match(library):
    python, compiled_plant = Plant(RE_IMPACT, Settings()), CompiledPlant(RE_IMPACT, Settings(), library)
    for t_end, U in ((0.3, 0.0), (1.7, 0.2), (1.75, 0.2), (9.0, -0.1)):
        assert bits(compiled_plant.advance(t_end, U)) == bits(python.advance(t_end, U))
        assert bits(compiled_plant.state()) == bits(python.state())
        assert bits(compiled_plant.outputs()) == bits(python.outputs())
        elsewhere = (t_end + 0.5, -0.3, 0.1)
        assert bits(compiled_plant.outputs_at(*elsewhere)) == bits(python.outputs_at(*elsewhere))
        assert compiled_plant.t == python.t and compiled_plant.U == python.U
        assert counters(compiled_plant) == counters(python)


@pytest.mark.parametrize("fidelity", [0, 1, 2])
def test_kernel_accel_is_the_models(fidelity, library):
    scene = Scene()
    model, compiled_plant = make_model(scene, fidelity), CompiledPlant(scene, Settings(fidelity=fidelity), library)
    rng = np.random.default_rng(fidelity)
    for t, x, v, U in rng.uniform([-50, -1.4, -3, -1], [50, 1.4, 3, 1], size=(2000, 4)):
        assert bits(library.vk_accel(compiled_plant.address, t, x, v, U)) == bits(model.accel(t, x, v, U))


def test_where_python_raises_the_kernel_raises_the_same(library):
    """x at the upper electrode: Eq. 3's force divides by (1 - 2x/(3R))^2 = 0."""
    scene = Scene()
    python, compiled_plant = Plant(scene, Settings()), CompiledPlant(scene, Settings(), library)
    assert math.isnan(library.vk_accel(compiled_plant.address, 0.0, 1.5, 0.0, 0.0))
    expected = outcome(lambda: python.outputs_at(0.0, 1.5, 0.0))
    assert expected[0] is ZeroDivisionError
    assert outcome(lambda: compiled_plant.outputs_at(0.0, 1.5, 0.0)) == expected


# -- errors ------------------------------------------------------------------------------------------------
# A grazing contact at a loose tolerance: before issue 15, after a step cut at the contact event ended on the old
# side, the next step "crossed" back without a sign change and scipy's brentq raised ValueError out of do_step.
# Now a cut state lies on its new side by construction: both twins complete it (test below).
GRAZING = Scene(R=3.0, x_start=-1.910343213973064, v_start=0.6453882735758203, Delta=0.0, alpha=0.0, beta=0.0,
                gamma=0.05)
GRAZING_STEPS = [(0.001, -42.91596010716383), (0.37, 0.0), (2.0, 0.21168329882084835), (0.37, -0.7536196732598173),
                 (0.1, 0.0), (0.37, 0.0), (0.1, 0.0), (2.0, 0.0), (5.0, 0.0)]
ERROR_CASES = {  # scene, settings, steps, the first error Python raises (type, part of its text)
    "pull-in upper": (PULL_IN_UPPER, Settings(), held(5), (TerminalEvent, "upper gap")),
    "pull-in lower, then the same and a changed input (ValueError: outside the last step)":
        (PULL_IN_LOWER, Settings(), held(7) + [(0.1, 0.5)], (TerminalEvent, "lower gap")),
    "pull-in under a large input": (Scene(), Settings(), held(50) + held(20, U=3.0), (TerminalEvent, "pull-in")),
    # fidelities 1 and 2 under a large input: pull-in, like fidelity 0 (they ran past the electrode to a step
    # collapse at x = -1.8e7 before issue 25)
    "pull-in upper, fidelity 1": (Scene(), Settings(fidelity=1), held(50) + held(40, U=30.0),
                                  (TerminalEvent, "pull-in: upper gap")),
    "pull-in lower, fidelity 2": (Scene(), Settings(fidelity=2), held(50) + held(40, U=-30.0),
                                  (TerminalEvent, "pull-in: lower gap")),
    # R at its rule's upper end (parameters.R_MAX) and a huge input: R = 1e60 is now refused up front
    "OverflowError of an error norm's square": (Scene(R=1e6, x_start=1e6), Settings(fidelity=1), held(2, U=1e200),
                                                (OverflowError, "out of range")),
    "ZeroDivisionError of the first step": (Scene(), Settings(), held(2, U=1e300), (ZeroDivisionError, "by zero")),
    "RK4 pull-in upper": (PULL_IN_UPPER, Settings(solver=1), held(5), (TerminalEvent, "upper gap")),
    "RK4 pull-in lower": (PULL_IN_LOWER, Settings(solver=1), held(7) + [(0.1, 0.5)], (TerminalEvent, "lower gap")),
    # x'' ~ 1e46 from a step's start at rest: the dense output's Bernstein coefficients (1e46) round by more than g
    # (~1), and the event search walked up to 2^40 pieces (a hang the fuzzer found through a forged state; a plain
    # host reaches it with this input). With the search's rounding bound both twins stop at pull-in.
    "event search beyond the arithmetic": (Scene(), Settings(), held(2) + held(2, U=1e46),
                                           (TerminalEvent, "pull-in: upper gap")),
    "RK4 unstable step": (Scene(mu=50.0), Settings(solver=1, max_step=0.06), held(3, dt=1.0),
                          (IntegrationError, "RK4 unstable")),
    "RK4 non-finite state": (Scene(), Settings(solver=1, fidelity=1), held(5) + held(5, U=1e200),
                             (IntegrationError, "")),
}


@pytest.mark.parametrize("name", ERROR_CASES)
def test_errors_are_the_pythons(name, library):
    scene, settings, steps, first_error = ERROR_CASES[name]
    python = assert_same_traces(scene, settings, steps, library)
    kind, text = next(result[:2] for result, _ in python if is_error(result))
    assert kind is first_error[0] and first_error[1] in text


def test_the_grazing_contact_that_halted_brentq_completes_identically(library):
    python = assert_same_traces(GRAZING, Settings(rtol=1e-3), GRAZING_STEPS, library)
    assert not any(is_error(result) for result, _ in python)


def test_step_budget_failure_is_the_pythons(library, monkeypatch):
    monkeypatch.setattr(plant_module, "MAX_STEPS_PER_DOSTEP", 40)  # what Plant gives Dop853
    monkeypatch.setattr(settings_module, "MAX_STEPS_PER_DOSTEP", 40)  # what CompiledPlant gives the core
    # without a drive (no step ceiling: models.drive_step_ceiling) a step of 50 passes the up-front check and spends
    # the budget of 40 steps
    undriven = Scene(Delta=0.0, beta=0.0, gamma=0.0)
    python = assert_same_traces(undriven, Settings(), [(0.1, 0.0), (50.0, 0.0), (50.0, 0.0)], library)
    error = python[1][0]
    assert error[0] is IntegrationError and "40 steps reached only tau" in error[1]


def test_terminal_event_carries_the_state(library):
    with pytest.raises(TerminalEvent) as caught:
        CompiledPlant(PULL_IN_UPPER, Settings(), library).do_step(0.0, 1.0, 0.0)
    with pytest.raises(TerminalEvent) as expected:
        Plant(PULL_IN_UPPER, Settings()).do_step(0.0, 1.0, 0.0)
    assert str(caught.value) == str(expected.value)
    assert bits((caught.value.t, caught.value.x, caught.value.v)) == bits((expected.value.t, expected.value.x,
                                                                          expected.value.v))


BAD_STEPS = {
    "h = 0": (0.0, 0.0, 0.0), "h < 0": (0.0, -0.1, 0.0), "h NaN": (0.0, math.nan, 0.0), "h inf": (0.0, math.inf, 0.0),
    "U NaN": (0.0, 0.1, math.nan), "U inf": (0.0, 0.1, -math.inf),
    "too many steps": (0.0, 1.0, 0.0), "wrong time": (5.0, 0.1, 0.0), "time NaN": (math.nan, 0.1, 0.0),
}


@pytest.mark.parametrize("name", BAD_STEPS)
def test_pre_check_failures_raise_the_pythons_parameter_error_and_change_nothing(name, library):
    t, h, U = BAD_STEPS[name]
    settings = Settings(max_step=1e-7) if name == "too many steps" else Settings()
    python, compiled_plant = Plant(Scene(), settings), CompiledPlant(Scene(), settings, library)
    python.do_step(0.0, 1e-6, 0.2), compiled_plant.do_step(0.0, 1e-6, 0.2)
    t = 1e-6 if t == 0.0 else t
    before = compiled_plant.snapshot()
    expected = outcome(lambda: python.do_step(t, h, U))
    assert expected[0] is ParameterError
    assert outcome(lambda: compiled_plant.do_step(t, h, U)) == expected
    assert compiled_plant.snapshot() == before


def test_a_kernel_refusal_python_accepts_is_a_runtime_error(library):
    class Refusing:  # the kernel, but vk_do_step refuses every step for a wrong time
        def __getattr__(self, name):
            return getattr(library, name)

        @staticmethod
        def vk_do_step(address, t, h):
            return compiled.VK_BAD_TIME

    compiled_plant = CompiledPlant(Scene(), Settings(), Refusing())
    with pytest.raises(RuntimeError, match="VK_BAD_TIME"):
        compiled_plant.do_step(0.0, 0.1, 0.0)


@pytest.mark.parametrize("scene, settings", [(Scene(R=-1.0), Settings()), (Scene(), Settings(rtol=0.0)),
                                             (Scene(R=1e-70, x_start=0.0), Settings(fidelity=1))])
def test_construction_validates_as_plant(scene, settings, library):
    expected = outcome(lambda: Plant(scene, settings))
    assert expected[0] is ParameterError
    assert outcome(lambda: CompiledPlant(scene, settings, library)) == expected


@pytest.mark.parametrize("settings", [Settings(fidelity=3), Settings(fidelity=4, solver=1)])
def test_other_fidelities_are_refused(settings, library):
    assert not compiled.supports(settings)
    with pytest.raises(ValueError, match="runs fidelities 0, 1, 2, not fidelity"):
        CompiledPlant(Scene(), settings, library)


# -- pending errors (left by the FMU's C fast path) --------------------------------------------------------
def test_a_pending_error_is_raised_by_the_next_do_step_without_stepping(library):
    compiled_plant, python = CompiledPlant(PULL_IN_LOWER, Settings(), library), Plant(PULL_IN_LOWER, Settings())
    code = compiled.VK_OK
    while code == compiled.VK_OK:  # the fast path: vk_do_step on the structure, U_input held
        t = compiled_plant.t
        code = library.vk_do_step(compiled_plant.address, t, 0.1)
        expected = outcome(lambda: python.do_step(t, 0.1, 0.0))
    assert code == compiled.VK_TERMINAL and expected[0] is TerminalEvent
    assert compiled_plant._plant.enabled == 0
    before, counts = compiled_plant.snapshot(), counters(compiled_plant)
    assert compiled_plant._plant.error == compiled.VK_TERMINAL
    assert library.vk_do_step(compiled_plant.address, compiled_plant.t, 0.1) == code  # pending: nothing done
    assert outcome(lambda: compiled_plant.do_step(compiled_plant.t, 0.1, 0.0)) == expected
    assert counters(compiled_plant) == counts == counters(python)
    assert compiled_plant._plant.error == 0
    assert state_bytes(compiled_plant.snapshot()) == state_bytes(before)  # only the error was cleared
    # cleared: the next do_step steps again and meets the stop again, as the Python plant does
    assert trace(compiled_plant, held(2)) == trace(python, held(2))


# -- snapshots ---------------------------------------------------------------------------------------------
def test_snapshot_restore_round_trip_is_bit_identical(library):
    settings = Settings(rtol=1e-10)
    compiled_plant = CompiledPlant(RE_IMPACT, settings, library)
    trace(compiled_plant, held(77, dt=0.13, U=0.1))
    snapshot = json.loads(json.dumps(compiled_plant.snapshot()))  # plain data
    steps = [(0.1, 0.0)] * 50 + [(0.7, -0.2)] * 50
    first = trace(compiled_plant, steps)
    compiled_plant.restore(snapshot)
    assert trace(compiled_plant, steps) == first
    fresh = CompiledPlant(RE_IMPACT, settings, library)
    fresh.restore(snapshot)
    assert trace(fresh, steps) == first


def damaged_snapshots(snapshot):
    text = snapshot["kernel"]
    return {
        "truncated": {"kernel": text[:-2]}, "not hex": {"kernel": "zz" + text[2:]}, "odd length": {"kernel": text[:-1]},
        "other key": {"plant": text}, "extra key": {"kernel": text, "x": 1}, "not text": {"kernel": 5},
        "not a dict": [text],
    }


@pytest.mark.parametrize("damage", damaged_snapshots({"kernel": "00"}))
def test_a_damaged_snapshot_is_refused(damage, library):
    compiled_plant = CompiledPlant(Scene(), Settings(), library)
    compiled_plant.do_step(0.0, 0.1, 0.0)
    before = compiled_plant.snapshot()
    with pytest.raises(ValueError, match="not a snapshot"):
        compiled_plant.restore(damaged_snapshots(before)[damage])
    assert compiled_plant.snapshot() == before


def test_a_snapshot_of_another_scene_is_refused(library):
    snapshot = CompiledPlant(Scene(mu=0.2), Settings(), library).snapshot()
    with pytest.raises(ValueError, match="other parameters or settings"):
        CompiledPlant(Scene(), Settings(), library).restore(snapshot)


# -- the compiled floor ------------------------------------------------------------------------------------
@pytest.mark.parametrize("scene", [Scene(), RE_IMPACT])
def test_vk_run_is_the_do_step_loop(scene, library):
    looped, ran = CompiledPlant(scene, Settings(), library), CompiledPlant(scene, Settings(), library)
    for plant in (looped, ran):
        plant.do_step(0.0, 0.1, 0.05)
    expected = np.array([looped.do_step(looped.t, 0.1, 0.05).x for _ in range(1500)])
    # vk_run calls the same vk_do_step as the do_step loop, in C: the same operations, the same bits
    assert ran.run(0.1, 1500).tobytes() == expected.tobytes()
    assert counters(ran) == counters(looped) and ran.snapshot() == looped.snapshot()


@pytest.mark.parametrize("scene", [Scene(), RE_IMPACT])
def test_the_step_to_the_state_then_its_outputs_is_vk_do_step(scene, library):
    """vk_do_step_state then vk_step_outputs (the native plant FMU's doStep, x'' and the forces when read) against
    vk_do_step: the same plant bytes after every step, an input change included; and vk_outputs_bounded holds on
    the way (the exact model, bounded values). Why the same bits: both run step_xv_with's operations, then the
    same outputs of vm_outputs at the same (t, x, v, U)."""
    stepped, split = CompiledPlant(scene, Settings(), library), CompiledPlant(scene, Settings(), library)
    for k in range(300):
        U = 0.02 if 100 <= k < 200 else 0.0
        for plant in (stepped, split):
            plant._plant.U_input = U
        assert library.vk_do_step(stepped.address, 0.1 * k, 0.1) == 0
        assert library.vk_do_step_state(split.address, 0.1 * k, 0.1) == 0
        assert list(split._plant.out)[:2] == list(stepped._plant.out)[:2]
        assert library.vk_outputs_bounded(split.address) == 1
        assert library.vk_step_outputs(split.address) == 0
        assert bytes(split._plant) == bytes(stepped._plant)


def test_outputs_are_bounded_only_where_the_proof_holds(library):
    """vk_outputs_bounded: 0 for the polynomial model, at an electrode (1 - u = 0: electrostatic()'s division by
    zero) and for a value beyond 1e100; 1 at the same point a rounding away from those."""
    plant = CompiledPlant(Scene(R=2.0), Settings(), library)
    p = plant._plant
    assert library.vk_outputs_bounded(plant.address) == 1
    p.out[0] = 1.5 * 2.0  # u = 2x/(3R) = 1
    assert library.vk_outputs_bounded(plant.address) == 0
    p.out[0] = 1.0
    p.out[1] = 1e101
    assert library.vk_outputs_bounded(plant.address) == 0
    p.out[1] = 0.0
    assert library.vk_outputs_bounded(plant.address) == 1
    polynomial = CompiledPlant(Scene(), Settings(fidelity=1), library)
    assert library.vk_outputs_bounded(polynomial.address) == 0


def test_vk_run_stops_at_the_first_error(library):
    ran, python = CompiledPlant(PULL_IN_LOWER, Settings(), library), Plant(PULL_IN_LOWER, Settings())
    expected = trace(python, held(10))
    error = next(result for result, _ in expected if is_error(result))
    assert outcome(lambda: ran.run(0.1, 10)) == error
    assert counters(ran) == counters(python)


# -- the library ---------------------------------------------------------------------------------------------
def test_tableau_header_is_generated_from_scipy():
    assert kernel.TABLEAU_HEADER.read_text() == kernel.tableau_header()


def test_the_cached_library_is_keyed_by_the_compiler(monkeypatch, tmp_path):
    """$CC is part of the cache key: a library compiled by one compiler is not reused for another."""
    fake = tmp_path / "othercc"
    fake.write_text("#!/bin/sh\nexit 1\n")
    fake.chmod(0o755)
    monkeypatch.delenv("CC", raising=False)
    default = kernel.library_folder()
    monkeypatch.setenv("CC", str(fake))
    assert kernel.library_folder() != default
    monkeypatch.setenv("CC", "no-such-compiler-here")  # no compiler: a key of its own, nothing cached under it
    assert kernel.library_folder() not in (default,)


def test_a_library_of_another_layout_is_refused(library, monkeypatch):
    folder = kernel.library_folder()
    assert load_library([folder])[0] is not None

    class ShortMessage(ctypes.Structure):  # the same fields, a shorter message: another size
        _fields_ = compiled.VkPlant._fields_[:-1] + [("message", ctypes.c_char * 16)]

    monkeypatch.setattr(compiled, "VkPlant", ShortMessage)
    found, reason = load_library([folder])
    assert found is None and "sizeof(VkPlant)" in reason

    class ExtraField(ctypes.Structure):
        _fields_ = compiled.VkPlant._fields_ + [("spare", ctypes.c_double)]

    monkeypatch.setattr(compiled, "VkPlant", ExtraField)
    found, reason = load_library([folder])
    assert found is None and "fields" in reason


def test_a_missing_library_is_reported(tmp_path):
    found, reason = load_library([tmp_path])
    assert found is None and "no vibrokernel.so" in reason


@pytest.mark.long  # compiles the kernel
def test_the_kernel_compiles_without_warnings(library, tmp_path):
    """The build command itself (kernel.compile_kernel) built the session's kernel (`library`: compiled once per test
    run, not again here); the same sources also compile with -pedantic -Werror, no output at all."""
    assert kernel.kernel_file().is_file()
    command = [*kernel.GCC_COMMAND, "-pedantic", "-Werror", "-o", str(tmp_path / "strict.so"),
               *map(str, kernel.kernel_sources()), "-lm"]
    assert subprocess.run(command, capture_output=True, text=True).stderr == ""


@pytest.mark.parametrize("theta", [0.0, 1e-3, 0.3, 1.0, 1.696, 2.5, 4.0, 4 * math.pi / 3, 5.0, 2 * math.pi, 7.5])
def test_the_solvers_drive_gain_is_integrates_bit_for_bit(library, theta):
    """core/rk4.c vk_rk4_drive_gain_x, which the native FMUs' drive warnings read through the solver table (solver.h:
    drive_gain_x), is integrate.rk4_drive_gains(theta)[0]. Bit identity is free: the same IEEE operations in the same
    order (-ffp-contract=off), sin and cos from the same libm that CPython's math module calls."""
    function = library.vk_rk4_drive_gain_x
    function.restype, function.argtypes = ctypes.c_double, [ctypes.c_double]
    assert bits(function(theta)) == bits(rk4_drive_gains(theta)[0])


# ---- the step budget's up-front check at a ratio equal to the budget but for rounding ----

def test_step_budget_accepts_a_ratio_equal_to_it_but_for_rounding():
    """A doStep of 0.1 with max_step 1e-7 takes exactly 10^6 RK4 steps (RK4's count, ceil(h / max_step (1 -
    1e-12))), the budget, though 0.1 / 1e-7 rounds to 1000000.0000000001: accepted; one more step's worth is not."""
    assert 0.1 / 1e-7 > settings_module.MAX_STEPS_PER_DOSTEP  # the rounding this is about
    assert settings_module.too_many_steps(0.1, 1e-7) is None
    assert settings_module.too_many_steps(0.1 + 1e-7, 1e-7) is not None  # 10^6 + 1 steps


def test_compiled_step_budget_accepts_a_ratio_equal_to_it_but_for_rounding(library):
    """The kernel's check (plant.h's vk_too_many_steps, the closed loop's too) on a budget of 1000 (the plant's
    field, set here so that the step is 1000 RK4 steps rather than 10^6): h = 1e-4 over max_step 1e-7 rounds to
    1000.0000000000001 and is taken in 1000 steps; 1001 steps' worth is refused up front, nothing stepped."""
    assert 1e-4 / 1e-7 > 1000.0
    plant = CompiledPlant(Scene(), Settings(solver=plant_module.Solver.RK4, max_step=1e-7), library)
    plant._plant.max_steps_per_dostep = 1000.0
    assert library.vk_do_step(plant.address, 0.0, 1e-4) == 0
    assert plant.n_steps == 1000 and plant.t == 1e-4
    assert library.vk_do_step(plant.address, 1e-4, 1e-4 + 1e-7) == compiled.VK_TOO_MANY_STEPS
    assert plant.n_steps == 1000 and plant.t == 1e-4
