"""The controller FMU on the compiled controller (fmu_src/core/controller.c) and the shim's C fast path: with
kernel = 0 the shim runs doStep and answers the output getters without Python. It must change nothing but the
speed: controller.c performs control.py's operations in the same order (control._dot: sums left to right), so every
output equals the pure-Python FMU (kernel = 1) bit for bit, also across an FMU state round trip (the compiled
state is the kernel structure's bytes), and the fast path must actually be used."""
import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from vibrofmu.fmus.kernel import kernel_library
from vibrofmu.hosts.run import FmuInstance
from vibromodel.closedloop import ERRATA_SCENE
from vibromodel.compiled_loop import CompiledEstimator, declare
from vibromodel.control import ERRATA_INITIAL_ESTIMATES, ESTIMATE_NAMES, Gains, HeldInputEstimator, Law

OUTPUTS = ["U", "e1", "e2", "V", *ESTIMATE_NAMES]


@pytest.mark.parametrize("law", list(Law))
def test_compiled_estimator_equals_python_bit_for_bit(law):
    """Random held inputs, steps and gains: theta^ and t after every advance, and the outputs, the same bits."""
    library = kernel_library()
    assert declare(library) is None
    rng = np.random.default_rng(int(law))
    gains = Gains(lambdas=(3.0, 0.7) + tuple(rng.uniform(0.5, 2.0, 9)), k_damping=0.8)
    python = HeldInputEstimator(ERRATA_SCENE, gains, law, ERRATA_INITIAL_ESTIMATES)
    compiled = CompiledEstimator(ERRATA_SCENE, gains, law, ERRATA_INITIAL_ESTIMATES, library)
    t = 0.0
    for _ in range(300):
        x, v = rng.uniform(-0.1, 0.1, 2)
        ref = tuple(rng.uniform(-0.1, 0.1, 3))
        h = rng.uniform(0.01, 1.0)
        python.advance(t, h, x, v, ref)
        compiled.advance(t, h, x, v, ref)
        t += h
        # core/controller.c performs HeldInputEstimator's operations in the same order (-ffp-contract=off, no
        # -ffast-math: kernel.GCC_COMMAND): the same bits
        assert np.array_equal(python.theta_hat, compiled.theta_hat) and python.t == compiled.t
        for name, value in zip(("x", "v", "x_ref", "v_ref", "a_ref"), (x, v, *ref)):
            compiled.set_value(name, value)
        compiled.publish()
        c = python.controller
        e1, e2 = c.errors(x, v, ref)
        expected = [c.control(python.t, x, v, ref, python.theta_hat), e1, e2, c.lyapunov(e1, e2, python.theta_hat),
                    *python.theta_hat]
        assert [compiled.value(name) for name in OUTPUTS] == expected


def drive(controller_fmu, kernel: int, steps: int = 300):
    """The inputs set before every step (a plant-like signal), outputs and a parameter read together (a getReal
    the fast path must forward), one FMU state round trip; returns (rows, fast steps)."""
    with FmuInstance(controller_fmu, f"kernel{kernel}") as instance:
        fmu = instance.fmu
        fmu.setupExperiment(startTime=0.0, stopTime=steps * 0.1)
        fmu.enterInitializationMode()
        instance.set({"kernel": kernel, "law": 1})
        fmu.exitInitializationMode()
        refs = instance.value_references([*OUTPUTS, "lambda3"])
        inputs = instance.value_references(["x", "v", "x_ref", "v_ref", "a_ref"])

        def signal(i):
            t = 0.1 * i
            return [0.05 * math.cos(1.1 * t), -0.055 * math.sin(1.1 * t), 0.04 * math.cos(t), -0.04 * math.sin(t),
                    -0.04 * math.cos(t)]

        rows, saved = [], None
        for i in range(steps):
            fmu.setReal(inputs, signal(i))
            if i == steps // 2:
                saved = fmu.serializeFMUstate(fmu.getFMUstate())
            fmu.doStep(i * 0.1, 0.1)
            rows.append(fmu.getReal(refs))
        fmu.setFMUstate(fmu.deSerializeFMUstate(saved))  # back to the middle: the rest must repeat exactly
        for i in range(steps // 2, steps):
            fmu.setReal(inputs, signal(i))
            fmu.doStep(i * 0.1, 0.1)
            assert fmu.getReal(refs[:-1]) == rows[i][:-1]
        return np.array(rows), instance.fast_path_steps()


def test_controller_fast_path_equals_the_python_fmu(controller_fmu):
    compiled, n_fast = drive(controller_fmu, 0)
    python, n_python = drive(controller_fmu, 1)
    # the compiled controller is bit-identical to the Python one (test above), and the shim copies doubles: equal
    assert np.array_equal(compiled, python)
    assert n_fast == 300 + 150  # every doStep went through the fast path, also after fmi2SetFMUstate
    assert n_python == 0


def test_refused_step_on_the_fast_path_is_reported_by_the_slave(controller_fmu):
    """A non-finite input: vk_controller_do_step refuses without changing anything, the shim forwards, the slave reports it
    (fmi2Error naming the input)."""
    with FmuInstance(controller_fmu) as instance:
        fmu = instance.fmu
        fmu.setupExperiment(startTime=0.0, stopTime=10.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 0.1)
        assert instance.fast_path_steps() == 1
        with pytest.raises(FMICallException):  # issue 15: an input out of its range is refused when it is set
            fmu.setReal(instance.value_references(["x"]), [math.inf])
        with pytest.raises(FMICallException):
            fmu.doStep(0.1, 0.1)
        assert instance.fast_path_steps() == 1
        assert any("x = inf" in m and "must be a finite number" in m for m in instance.log.errors())
