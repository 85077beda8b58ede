"""The closed loop on the compiled kernel (fmu_src/core/closedloop.c: core's DOP853/RK4, model.c, controller.c,
oafm_eval.c for the reference) against its pure-Python twin vibromodel.closedloop.ClosedLoop, and the closed-loop
FMU's C fast path against the pure-Python FMU (kernel = 1)."""
import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from vibrofmu.fmus.kernel import kernel_library
from vibrofmu.hosts.run import FmuInstance, run_fmu
from vibromodel.closedloop import ERRATA_SCENE, ClosedLoop, LoopSettings
from vibromodel.compiled_loop import CompiledClosedLoop, make_closed_loop
from vibromodel.control import Law
from vibromodel.parameters import ParameterError
from vibromodel.plant import Settings, Solver
from vibromodel.tracking import ReferenceKind, ReferenceSettings

H = 0.1
STEPS = {Solver.ADAPTIVE: 200, Solver.RK4: 60}  # the pure-Python RK4 loop is slow (11 states, h = 0.01)


def pair(scene, settings, loop, stop=50.0):
    python = ClosedLoop(scene, settings, loop, stop_time=stop)
    compiled = make_closed_loop(scene, settings, loop, 0.0, stop, (), (kernel_library(), ""))
    assert isinstance(compiled, CompiledClosedLoop), compiled.notes
    return python, compiled


@pytest.mark.parametrize("solver", list(Solver))
@pytest.mark.parametrize("fidelity", [0, 1])
@pytest.mark.parametrize("law", list(Law))
def test_equal_bit_for_bit_with_an_exactly_evaluated_reference(solver, fidelity, law):
    """With Delta = gamma = 0 and the reference started at rest, x~ = 0 has only zero coefficients: both twins
    evaluate it to exactly 0. Everything else -- model, control law, update law, solver, events, outputs -- is
    done with the same operations in the same order, so every output and the solver's counters are equal."""
    scene = ERRATA_SCENE.with_values(Delta=0.0, gamma=0.0)
    loop = LoopSettings(law=law, reference=ReferenceSettings(kind=ReferenceKind.ERRATA, x_start=0.0, v_start=0.0))
    python, compiled = pair(scene, Settings(fidelity=fidelity, solver=solver, rtol=1e-9), loop)
    assert python.reference.state(1.234) == (0.0, 0.0, 0.0)
    assert compiled.outputs() == python.outputs()
    for i in range(STEPS[solver]):
        assert compiled.do_step(i * H, H) == python.do_step(i * H, H), i
    assert (compiled.integrator.nfev, compiled.integrator.n_steps) == (python.integrator.nfev,
                                                                         python.integrator.n_steps)


@pytest.mark.parametrize("solver", list(Solver))
@pytest.mark.parametrize("kind", list(ReferenceKind))
def test_equal_to_rounding_with_every_reference(solver, kind):
    """The real references: oafm_eval.c sums x~ by recurrence, numpy by one complex exp per term; they differ by
    rounding, <= 1e-16 relative (rungs' recurrence_error_bound). The loop is stable (V does not rise), so such a
    perturbation stays a perturbation: observed <= 1e-14 on outputs of size <= 1. Asserted: |difference| <= 1e-12 x
    (1 + |output|) -- a 100-fold margin, and 4 orders below the solver's rtol (1e-8): a wrong term or coefficient
    shows far above it. The step sequence (nfev, steps) is the same: an ulp-level change of the right-hand side
    flips an accept/reject decision only if the error estimate lies within ~1e-15 of 1."""
    python, compiled = pair(ERRATA_SCENE, Settings(solver=solver), LoopSettings(reference=ReferenceSettings(kind=kind)),
                            stop=200.0)
    for i in range(STEPS[solver]):
        a, b = python.do_step(i * H, H), compiled.do_step(i * H, H)
        for name in a:
            assert np.all(np.abs(np.subtract(a[name], b[name])) <= 1e-12 * (1.0 + np.abs(a[name]))), (i, name)
    assert (compiled.integrator.nfev, compiled.integrator.n_steps) == (python.integrator.nfev,
                                                                         python.integrator.n_steps)


def test_fmu_fast_path_equals_the_python_fmu(closed_loop_fmu):
    """The FMU at its defaults (exact model, DOP853, corrected paper reference), tau in [0, 20]: every doStep on the fast
    path (no Python), outputs equal to the pure-Python FMU within the rounding tolerance above."""
    runs = {kernel: run_fmu(closed_loop_fmu, {"kernel": kernel}, 20.0, H) for kernel in (0, 1)}
    assert all(run.completed for run in runs.values())
    for name, values in runs[1].outputs.items():
        assert np.all(np.abs(runs[0].outputs[name] - values) <= 1e-12 * (1.0 + np.abs(values))), name


def drive(closed_loop_fmu, kernel, steps=150, values=None):
    """doStep + getReal of every output (and a parameter: a getReal the fast path forwards), one serialized FMU
    state round trip in the middle; returns (rows, fast-path steps)."""
    with FmuInstance(closed_loop_fmu, f"kernel{kernel}") as instance:
        fmu = instance.fmu
        fmu.setupExperiment(startTime=0.0, stopTime=steps * H)
        fmu.enterInitializationMode()
        instance.set({"kernel": kernel, **(values or {})})
        fmu.exitInitializationMode()
        refs = instance.value_references([*instance.output_names(), "lambda1"])
        rows, saved = [], None
        for i in range(steps):
            if i == steps // 2:
                saved = fmu.serializeFMUstate(fmu.getFMUstate())
            fmu.doStep(i * H, H)
            rows.append(fmu.getReal(refs))
        fmu.setFMUstate(fmu.deSerializeFMUstate(saved))  # back to the middle: the rest repeats exactly
        for i in range(steps // 2, steps):
            fmu.doStep(i * H, H)
            assert fmu.getReal(refs) == rows[i]
        return np.array(rows), instance.fast_path_steps()


@pytest.mark.parametrize("solver", list(Solver))
def test_fast_path_with_state_round_trip(closed_loop_fmu, solver):
    rows, fast = drive(closed_loop_fmu, 0, values={"solver": int(solver)})
    assert fast == 150 + 75  # every doStep on the fast path, also after fmi2SetFMUstate
    python, none = drive(closed_loop_fmu, 1, steps=40, values={"solver": int(solver)})
    assert none == 0
    assert np.all(np.abs(rows[:40] - python) <= 1e-12 * (1.0 + np.abs(python)))


def test_refused_step_and_pull_in_on_the_fast_path(closed_loop_fmu):
    """A step at the wrong time: vk_loop_do_step refuses without changing anything, the slave reports it. A pull-in
    met on the fast path: the slave raises the pending TerminalEvent (fmi2Error with the pull-in message)."""
    with FmuInstance(closed_loop_fmu) as instance:
        fmu = instance.fmu
        fmu.setupExperiment(startTime=0.0, stopTime=10.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, H)
        assert instance.fast_path_steps() == 1
        with pytest.raises(FMICallException):
            fmu.doStep(5.0, H)
        assert instance.fast_path_steps() == 1
        assert any("currentCommunicationPoint" in m for m in instance.log.errors())
    result = run_fmu(closed_loop_fmu, {"R": 0.2, "alpha": 0.05, "x_start": 0.25, "v_start": 0.5}, 20.0, H)
    python = run_fmu(closed_loop_fmu, {"R": 0.2, "alpha": 0.05, "x_start": 0.25, "v_start": 0.5, "kernel": 1},
                     20.0, H)
    assert not result.completed and "pull-in" in result.stop_reason
    assert result.stop_reason == python.stop_reason and result.end_time == python.end_time
    assert math.isfinite(result.end_time)


@pytest.mark.parametrize("solver", list(Solver))
def test_the_loop_refuses_a_step_needing_more_than_a_million_solver_steps_like_the_plant(solver):
    """max_step = 1e-308 hung the closed loop's doStep (> 150 s); the plant refuses such a step up front
    (settings.check_step). The Python loop and the compiled one refuse it with the plant's words, nothing changed."""
    settings = Settings(solver=solver, max_step=1e-300)
    python, compiled = pair(ERRATA_SCENE, settings, LoopSettings())
    for loop in (python, compiled):
        with pytest.raises(ParameterError) as refusal:
            loop.do_step(0.0, H)
        assert refusal.value.name == "communicationStepSize" and "needs more than 1000000 steps" in str(refusal.value)
        assert loop.t == 0.0


@pytest.mark.fmu
@pytest.mark.parametrize("fmu_name", ["closed_loop_fmu", "native_closed_loop_fmu"])
def test_the_loop_fmus_refuse_the_endless_step(request, fmu_name):
    """Both FMU kinds: fmi2Error naming communicationStepSize and max_step, at once (no solver step taken)."""
    result = run_fmu(request.getfixturevalue(fmu_name), {"max_step": 1e-308}, 1.0, H)
    assert not result.completed and result.end_time == 0.0
    assert "communicationStepSize" in result.stop_reason and "max_step" in result.stop_reason
