"""The cheapest way to run a co-simulation FMU many times from Python with FMPy: extract it once, instantiate it
once and reset it between runs (fmi2Reset), and step it in a loop of the FMI functions FMPy loaded, called without
FMPy's per-call wrapper (argument logging and list conversion cost more than the plant FMU's own doStep).

    runner = FmpyLoop("build/HertzEAOscillator.fmu")
    x = runner.run({"Delta": 0.001}, stop_time=200.0, interval=0.1)   # x after each interval (a numpy array)
    runner.close()

`fmpy.simulate_fmu` does all of this per call (extract, read the model description, instantiate, free) and records
every output through its own wrappers; docs/numerics.md (beside other ODE solvers) measures both. The status of each
call is checked as FMPy checks it (FMICallException above fmi2Warning), and the FMU's log is kept (FmuLog).
"""
from __future__ import annotations

import ctypes
import shutil
import tempfile
from pathlib import Path

import numpy as np
from fmpy import extract
from fmpy.fmi1 import FMICallException

from vibrofmu.hosts.run import FmuInstance, FmuLog


class FmpyLoop:
    """One extracted copy and one instance of a co-simulation FMU, reused by every run (module docstring)."""

    def __init__(self, fmu_path: Path | str, output: str = "x"):
        self._folder = tempfile.mkdtemp(prefix="vibrofmu-fmpy-loop-")
        self.log = FmuLog()
        self.instance = FmuInstance(fmu_path, log=self.log, unzip_dir=extract(str(fmu_path), self._folder))
        self.fmu = self.instance.fmu
        functions = self.fmu._functions  # FMPy's loaded FMI functions, without its per-call wrapper
        self._do_step, self._get_real = functions["fmi2DoStep"], functions["fmi2GetReal"]
        self._vr = (ctypes.c_uint * 1)(self.instance.value_references([output])[0])
        self._value = (ctypes.c_double * 1)()
        self._used = False

    def run(self, start_values: dict, stop_time: float, interval: float, start_time: float = 0.0) -> np.ndarray:
        """The output after each interval from start_time (points start_time + k interval, as a host computes
        them) to stop_time, from the start values; raises FMICallException when the FMU refuses (its log says why:
        self.log)."""
        if self._used:
            self.fmu.reset()
        self._used = True
        fmu = self.fmu
        fmu.setupExperiment(startTime=start_time, stopTime=stop_time)
        fmu.enterInitializationMode()
        self.instance.set(start_values)
        fmu.exitInitializationMode()
        n = round((stop_time - start_time) / interval)
        x = np.empty(n)
        do_step, get_real, component, vr, value = self._do_step, self._get_real, fmu.component, self._vr, self._value
        for k in range(n):
            status = do_step(component, start_time + k * interval, interval, 1)
            if status > 1:  # above fmi2Warning
                raise FMICallException(function="fmi2DoStep", status=status)
            status = get_real(component, vr, 1, value)
            if status > 1:
                raise FMICallException(function="fmi2GetReal", status=status)
            x[k] = value[0]
        return x

    def close(self) -> None:
        self.instance.close()
        shutil.rmtree(self._folder, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
