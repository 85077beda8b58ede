"""Drive one FMU under FMPy's FMU2Slave: set start values, doStep loop, collect outputs and log.

A run never raises for a failing FMU: it keeps what was computed, records the status and the FMU's
log messages, and says why it stopped before the stop time.
"""
from __future__ import annotations

import math
import shutil
import time
import ctypes
import weakref
from ctypes import byref
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, printLogMessage)
from fmpy.logging import addLoggerProxy

from vibrofmu import interrupts

STATUS_NAMES = ["ok", "warning", "discard", "error", "fatal", "pending"]
FMI2_FATAL = STATUS_NAMES.index("fatal")


@dataclass
class RunResult:
    time: np.ndarray
    outputs: dict[str, np.ndarray]
    stop_time: float
    completed: bool
    stop_reason: str | None
    log: list[str] = field(default_factory=list)
    wall_time: float = 0.0  # doStep loop incl. getters
    instantiate_time: float = 0.0  # unpack, load, instantiate, initialise
    status: int | None = None  # the failing call's status (3 fmi2Error, 4 fmi2Fatal), None if none failed
    after_failure: dict[str, float] | None = None  # every output read after the failing call (not after a fatal)

    @property
    def end_time(self) -> float:
        return float(self.time[-1]) if len(self.time) else math.nan

    @property
    def message(self) -> str | None:
        """The last error message (the stop reason) or else the last warning, or None."""
        for prefix in ("[error]", "[warning]"):
            lines = [m for m in self.log if m.startswith(prefix) and "not allowed after an error" not in m]
            if lines:
                return lines[-1]
        return None

    def warnings(self) -> list[str]:
        return [m for m in self.log if m.startswith("[warning]")]

    def all_finite(self) -> bool:
        """Every output at every point reached, and after the failing call, is finite (an FMU never shows NaN)."""
        values = list(self.outputs.values()) + ([] if self.after_failure is None else [list(self.after_failure.values())])
        return all(bool(np.all(np.isfinite(np.asarray(v, dtype=float)))) for v in values)


# FMPy's native logger proxy (fmpy/logging: logMessage formats the message, then calls ONE process-wide Python
# callback, s_logger, set by the last addLoggerProxy) keeps pointing at the callback of the last logger it was given
# after that logger's ctypes objects are freed: the next message of ANY FMU, in a run without a logger of its own
# (FMPy's default callbacks already hold logMessage, so they do not re-point it), jumps into freed memory
# (SIGSEGV or SIGILL; issue 25's "second-run crash", reproduced with the native FMUs too: FMPy's, not the FMUs').
# So the proxy only ever points at _dispatch, which lives as long as the process and passes each message to the
# current FmuLog while it lives, else to FMPy's own printer.
_current_log: weakref.ref | None = None


def _dispatch(env, instance, status, category, message):
    log = _current_log() if _current_log is not None else None
    if log is not None:
        log._receive(instance, status, message)
    else:
        printLogMessage(env, instance, status, category, message)


_DISPATCH = fmi2CallbackLoggerTYPE(_dispatch)  # module-level: never freed


def restore_fmpy_logger() -> None:
    """Point FMPy's logger proxy at a callback that lives as long as the process. Call it after an
    fmpy.simulate_fmu(..., logger=f) whose f is about to be freed (FMPy keeps pointing at it; see above)."""
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _DISPATCH
    addLoggerProxy(byref(callbacks))  # sets the proxy's target to _DISPATCH (callbacks.logger becomes the proxy)


class FmuLog:
    """FMI logger callback that keeps the messages.

    FMPy's native logger proxy is process-wide: the last FmuLog created receives the messages of every
    instance, so FMUs that run together share one FmuLog and tell their messages apart by instance name."""

    def __init__(self):
        global _current_log
        self.messages: list[str] = []
        self.instances: list[str] = []  # the instance name of each message
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = _DISPATCH
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(self.callbacks))  # the proxy -> _DISPATCH (never a callback that can be freed)
        _current_log = weakref.ref(self)

    def _receive(self, instance, status, message):
        label = STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else str(status)
        self.messages.append(f"[{label}] {(message or b'').decode(errors='replace')}")
        self.instances.append(instance.decode(errors="replace") if instance else "")

    def of(self, instance: str) -> list[str]:
        return [m for m, name in zip(self.messages, self.instances) if name == instance]

    def errors(self, instance: str | None = None) -> list[str]:
        messages = self.messages if instance is None else self.of(instance)
        return [m for m in messages if m.startswith(("[error]", "[fatal]", "[discard]"))]


class FmuUnusable(RuntimeError):
    """An FMU this run cannot use: the message names the FMU and why (the command line prints it in one line)."""


class FmuInstantiationError(FmuUnusable):
    """fmi2Instantiate returned NULL: the message names the FMU and carries the FMU's own log lines (why)."""


class FmuVariableMissing(FmuUnusable, KeyError):
    """A variable the run needs is not in the FMU's modelDescription (an FMU of another vibrofmu version)."""

    def __str__(self) -> str:  # (KeyError's would quote the message)
        return str(self.args[0])


class FmuInstance:
    """One instantiated co-simulation FMU with name-based access to its variables."""

    def __init__(self, fmu_path: Path | str, instance_name: str = "instance", log: FmuLog | None = None,
                 unzip_dir: Path | str | None = None):
        """log: shared by several instances (FMPy's logger is process-wide); unzip_dir: an FMU already
        extracted there (kept on close); by default a fresh one per instance."""
        self.path = fmu_path
        self.model_description = read_model_description(str(fmu_path))
        self.variables = {v.name: v for v in self.model_description.modelVariables}
        self.owns_unzip_dir = unzip_dir is None
        self.unzip_dir = extract(str(fmu_path)) if unzip_dir is None else str(unzip_dir)
        self.log = log or FmuLog()
        self.fmu = FMU2Slave(guid=self.model_description.guid, unzipDirectory=self.unzip_dir,
                             modelIdentifier=self.model_description.coSimulation.modelIdentifier,
                             instanceName=instance_name)
        seen = len(self.log.messages)
        try:
            self.fmu.instantiate(callbacks=self.log.callbacks, loggingOn=True)
        except Exception as error:  # FMPy: "Failed to instantiate model" (NULL), nothing else said
            if self.owns_unzip_dir:
                shutil.rmtree(self.unzip_dir, ignore_errors=True)
            why = "; ".join(" ".join(m.split()) for m in self.log.messages[seen:]) or "the FMU logged nothing"
            raise FmuInstantiationError(f"{fmu_path}: fmi2Instantiate failed ({error}): {why}") from None

    def set(self, values: dict):
        for name, value in values.items():
            variable = self.variable(name)
            if variable.type == "Integer":
                self.fmu.setInteger([variable.valueReference], [int(value)])
            elif variable.type == "Boolean":
                self.fmu.setBoolean([variable.valueReference], [bool(value)])
            else:
                self.fmu.setReal([variable.valueReference], [float(value)])

    def value_references(self, names):
        return [self.variable(n).valueReference for n in names]

    def variable(self, name: str):
        """The model variable `name`; FmuVariableMissing naming the FMU when it has none of that name."""
        try:
            return self.variables[name]
        except KeyError:
            raise FmuVariableMissing(f"{self.path}: the FMU has no variable {name!r} (an FMU built by another "
                                     "version of vibrofmu? rebuild it: vibrofmu build)") from None

    def output_names(self):
        return [v.name for v in self.model_description.modelVariables if v.causality == "output"]

    def output_columns(self) -> list[str]:
        """The Real outputs, then the Integer ones (the plant's fidelity_chosen), then the Boolean ones: the order of
        read_outputs."""
        names = self.output_names()
        return [n for kind in ("Real", "Integer", "Boolean") for n in names if self.variables[n].type == kind]

    def read_outputs(self) -> list[float]:
        """Every output's current value (Integers as floats, Booleans as 0.0/1.0), in the order of output_columns."""
        if not hasattr(self, "_output_refs"):
            columns = self.output_columns()
            self._output_refs = tuple(self.value_references([n for n in columns if self.variables[n].type == kind])
                                      for kind in ("Real", "Integer", "Boolean"))
        reals, integers, booleans = self._output_refs
        return (self.fmu.getReal(reals) + ([float(i) for i in self.fmu.getInteger(integers)] if integers else [])
                + [float(b) for b in self.fmu.getBoolean(booleans)])

    def fast_path_steps(self) -> int:
        """doSteps the status shim's C fast path has done for this instance (fmi2_status_shim.c)."""
        steps = self.fmu.dll.vibro_fast_path_steps
        steps.restype, steps.argtypes = ctypes.c_ulonglong, [ctypes.c_void_p]
        return steps(self.fmu.component)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        try:
            self.fmu.terminate()
        except FMICallException:
            pass
        self.fmu.freeInstance()
        if self.owns_unzip_dir:
            shutil.rmtree(self.unzip_dir, ignore_errors=True)


def run_fmu(fmu_path: Path | str, start_values: dict, stop_time: float, output_interval: float,
            tolerance: float | None = None, progress=None) -> RunResult:
    """Simulate from 0 to stop_time with communication step output_interval."""
    t0 = time.perf_counter()
    instance = FmuInstance(fmu_path)
    fmu = instance.fmu
    columns = instance.output_columns()
    read_outputs = instance.read_outputs
    n_steps = int(round(stop_time / output_interval))

    # preallocated (8 bytes per value: a long run's memory is bounded and known up front, cf. simulate's
    # --max-output-mb), filled up to `filled` rows
    times, data = np.empty(n_steps + 1), np.empty((n_steps + 1, len(columns)))
    stop_reason = status = None
    try:
        try:
            fmu.setupExperiment(tolerance=tolerance, startTime=0.0, stopTime=stop_time)
            fmu.enterInitializationMode()
            instance.set(start_values)
            fmu.exitInitializationMode()
        except FMICallException as error:
            stop_reason, status = call_failure_reason(error, instance.log), error.status
        instantiate_time = time.perf_counter() - t0

        t_loop = time.perf_counter()
        filled, stop_reason, status = _steps(instance, times, data, n_steps, output_interval, stop_time, progress,
                                             stop_reason, status)
    except KeyboardInterrupt:
        instance.close()  # (its extracted folder removed) and the interrupt goes on
        raise
    wall_time = time.perf_counter() - t_loop
    after_failure = dict(zip(columns, read_outputs())) if status is not None and status != FMI2_FATAL else None
    instance.close()

    data = data[:filled]
    outputs = {name: data[:, j] for j, name in enumerate(columns)}
    return RunResult(time=times[:filled], outputs=outputs, stop_time=stop_time,
                     completed=stop_reason is None, stop_reason=stop_reason, log=instance.log.messages,
                     wall_time=wall_time, instantiate_time=instantiate_time, status=status,
                     after_failure=after_failure)


def _steps(instance, times, data, n_steps, output_interval, stop_time, progress, stop_reason, status):
    """The doStep loop of run_fmu (fills times and data); returns (rows filled, stop_reason, status)."""
    fmu, read_outputs = instance.fmu, instance.read_outputs
    if stop_reason is not None:
        return 0, stop_reason, status
    times[0], data[0] = 0.0, read_outputs()
    filled = 1
    for i in range(n_steps):
        t, h = i * output_interval, output_interval
        if t + h > stop_time + 1e-9 * max(1.0, abs(stop_time)):  # FMI 2.0: no step beyond the stop time
            h = stop_time - t  # (a stop time that is not a multiple of the interval: the last step is shorter)
        try:
            fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            row = read_outputs()
        except FMICallException as error:
            return filled, call_failure_reason(error, instance.log), error.status
        times[filled], data[filled] = t + h, row  # the FMU's own clock: t + h
        filled += 1
        if progress is not None:
            progress(i + 1, n_steps)
    return filled, stop_reason, status


def call_failure_reason(error: FMICallException, log: FmuLog, instance: str | None = None) -> str:
    """Why an FMI call failed; a call failed by the user's Ctrl-C raises KeyboardInterrupt instead (every host
    answers a failed call through here)."""
    interrupts.check()
    messages = log.errors(instance)
    detail = messages[-1] if messages else "no log message"
    return f"{str(error).rstrip('.')}: {detail}"
