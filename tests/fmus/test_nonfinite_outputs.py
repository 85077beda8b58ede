"""Issue 15 (left-over holes): a step whose outputs are not all finite fails with fmi2Error naming the output, in
every path -- the pure-Python models, the compiled core (closedloop.c, controller.c) behind the slaves and the
status shim's C fast path, and the native FMUs -- and the outputs read afterwards are the last finite ones.

Before: the compiled closed loop and controller kept their previous outputs and returned fmi2OK.
"""
import math

import pytest
from fmpy.fmi1 import FMICallException
from message_text import canonical_tree

from vibrofmu.fmus.kernel import kernel_library
from vibrofmu.hosts.run import FmuInstance
from vibromodel.closedloop import ERRATA_SCENE, ClosedLoop, LoopSettings
from vibromodel.compiled_loop import LOOP_OUTPUTS, CompiledClosedLoop, make_closed_loop
from vibromodel.control import ESTIMATE_NAMES
from vibromodel.parameters import NonFiniteOutput
from vibromodel.plant import Settings, Solver
from vibromodel.tracking import ReferenceKind, ReferenceSettings

ERROR = 3


def _flat(outputs: dict) -> dict:
    return {**{name: outputs[name] for name in LOOP_OUTPUTS[:9]}, **dict(zip(ESTIMATE_NAMES, outputs["estimates"]))}


@pytest.mark.parametrize("solver", list(Solver))
def test_compiled_closed_loop_names_the_non_finite_output_as_the_python_loop(solver):
    """Both twins (equal bit for bit on this scene) with the Lyapunov weight of mu_hat put at infinity after three
    steps: V (and V') overflow while the dynamics (which use lambda2 Lambda^-1, computed at set-up) stay as they
    were. The compiled loop raises NonFiniteOutput naming the first output that is not finite in the pure-Python
    loop's outputs of the same step, with the same value; its published outputs stay the last finite ones."""
    # the scene of test_closed_loop_kernel's bit-for-bit test: the reference is exactly 0 in both twins
    scene = ERRATA_SCENE.with_values(Delta=0.0, gamma=0.0)
    loop = LoopSettings(reference=ReferenceSettings(kind=ReferenceKind.ERRATA, x_start=0.0, v_start=0.0))
    settings = Settings(fidelity=0, solver=solver, rtol=1e-9)
    python = ClosedLoop(scene, settings, loop, stop_time=10.0)
    compiled = make_closed_loop(scene, settings, loop, 0.0, 10.0, (), (kernel_library(), ""))
    assert isinstance(compiled, CompiledClosedLoop), compiled.notes
    for k in range(3):
        assert _flat(compiled.do_step(0.1 * k, 0.1)) == _flat(python.do_step(0.1 * k, 0.1))
    before = _flat(compiled.outputs())
    python.controller.Lambda = (math.inf, *python.controller.Lambda[1:])
    compiled._l.controller.Lambda[0] = math.inf
    expected = _flat(python.do_step(0.3, 0.1))
    bad = next(name for name, value in expected.items() if not math.isfinite(value))
    assert bad == "V"
    with pytest.raises(NonFiniteOutput) as raised:
        compiled.do_step(0.3, 0.1)
    assert (raised.value.name, repr(raised.value.value)) == (bad, repr(float(expected[bad])))
    assert str(raised.value).startswith("output V = inf is not finite")
    assert _flat(compiled._outputs()) == before


def _controller_overflow(fmu, start):
    """A step of 1e300 (no stop time) with v = 1e8 drives the estimates' increment to infinity: the status of two
    steps, the outputs after each, the errors logged."""
    instance = FmuInstance(fmu, "c")
    f = instance.fmu
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    instance.set(start)
    f.exitInitializationMode()
    instance.set({"x": 0.03, "x_ref": 0.04, "v": 1e8})
    trace = [f.getReal(instance.value_references(instance.output_names()))]
    for _ in range(2):
        try:
            f.doStep(0.0, 1e300)
            trace.append("ok")
        except FMICallException as error:
            trace.append(error.status)
        trace.append(f.getReal(instance.value_references(instance.output_names())))
    errors = [m for m in instance.log.messages if m.startswith("[error]")]
    instance.close()
    return trace, errors


def test_controller_step_to_a_non_finite_output_fails_alike_in_every_path(controller_fmu, native_controller_fmu):
    """Compiled (C fast path) and pure-Python kernels of the pythonfmu FMU and the native FMU: fmi2Error naming U,
    the outputs read afterwards equal to those before the step (the last finite ones)."""
    compiled = _controller_overflow(controller_fmu, {})
    python = _controller_overflow(controller_fmu, {"kernel": 1})
    native = _controller_overflow(native_controller_fmu, {})
    trace, errors = python
    assert trace[1] == ERROR and trace[2] == trace[0] and trace[4] == trace[0]
    assert "NonFiniteOutput(\"output U = -inf is not finite" in errors[0]
    assert compiled == python
    assert canonical_tree(native) == canonical_tree(python)  # the same words and numbers (message_text)
