"""hosts.fmpy_loop.FmpyLoop (one extracted copy, one instance reset between runs, the FMI functions called
directly): run after run, the plant FMU's x is the bits of vibrofmu.api.simulate on the same host grid
(start + k interval: the FMU's C fast path steps the kernel the API runs), and a refused start value is an
FMICallException that the next run recovers from. (fmpy.simulate_fmu steps from n interval by the difference of
consecutive points, another grid, so it agrees only to the solver's tolerance.)"""
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from vibrofmu import api
from vibrofmu.hosts.fmpy_loop import FmpyLoop
from vibromodel.parameters import Scene
from vibromodel.plant import Settings

SCENES = [({"Delta": 0.001}, Settings()), ({"x_start": -1.3, "v_start": -0.8, "R": 2.0}, Settings(rtol=1e-6)),
          ({}, Settings())]


def test_runs_reusing_one_instance_give_the_apis_bits(plant_fmu):
    with FmpyLoop(plant_fmu) as runner:
        for values, settings in SCENES * 2:  # each scene again after the others: a reset leaves nothing behind
            x = runner.run({**values, "rtol": settings.rtol}, 20.0, 0.1)
            expected = api.simulate(Scene(**values), 20.0, 0.1, settings).x[1:]
            assert len(x) == 200 and np.array_equal(x, expected), values


def test_a_refused_start_value_raises_and_the_next_run_goes_on(plant_fmu):
    with FmpyLoop(plant_fmu) as runner:
        with pytest.raises(FMICallException):
            runner.run({"mu": -1.0}, 1.0, 0.1)
        assert any("parameter mu = -1.0" in message for message in runner.log.messages)
        x = runner.run({}, 1.0, 0.1)
        assert np.array_equal(x, api.simulate(Scene(), 1.0, 0.1).x[1:])
