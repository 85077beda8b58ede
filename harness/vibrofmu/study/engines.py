"""The two engines a study case runs on, and the outcome of one case.

- `fmu`: the built plant FMU under FMPy (what users validate); a worker keeps its instances and starts each
  settled point with fmi2Reset (FmuEngine);
- `core`: the compiled kernel directly (vibrofmu.api.Simulation: a window of steps per C call), no FMI layer.

Both run the plant at fidelity 0 (exact contact force, adaptive DOP853, rtol 1e-8) through the same
settling loop (sweep.settle_loop: the complex first harmonic settled over windows of forcing periods), so
the FMU's C fast path and the core step the same kernel and give the same bits
(tests/studies/test_study.py::test_engines_give_the_same_bits).

An engine is made once per worker process (`engine_for`) and kept: the FMU is unpacked once per process,
the kernel compiled/loaded once per process.
"""
from __future__ import annotations

import hashlib
import math
import os
import tempfile
import time
from dataclasses import asdict, dataclass

import numpy as np
from vibromodel.forces import contact_indentation
from vibromodel.integrate import IntegrationError, TerminalEvent
from vibromodel.parameters import ParameterError, Scene
from vibromodel.plant import Settings

from vibrofmu import api, interrupts
from vibrofmu.analyses.sweep import settle_loop

try:
    from fmpy.fmi1 import FMICallException as FmiError
except ImportError:  # pragma: no cover - fmpy is a dependency
    FmiError = RuntimeError

ENGINES = ("fmu", "core")
SETTINGS = Settings()  # fidelity 0, adaptive DOP853, rtol 1e-8: the FMU's defaults
CONTACT_LOSS_X = -1.5  # 1 + 2x/3 = 0: the Hertzian contact opens (Eq. 3)


@dataclass
class Outcome:
    """What one settled run gives (one Parquet row's outcome columns)."""

    r: float = math.nan  # first-harmonic amplitude |c| over the last window
    A: float = math.nan  # c = A - iB: x - mean ~ A cos(omega t) + B sin(omega t) over the last window
    B: float = math.nan
    mean: float = math.nan  # mean of x over the last window
    settled: bool = False
    periods: int = 0  # forcing periods simulated
    x_end: float = math.nan
    v_end: float = math.nan
    contact_loss: bool = False  # some sampled state had 1 + 2x/3 <= 0 (in_contact false)
    pull_in: bool = False  # the run stopped at the pull-in event
    failed: bool = False  # the run stopped for another reason (message says which)
    message: str = ""  # the FMU's (or the kernel's) message when the run stopped early
    cost_s: float = 0.0  # wall seconds of this run on its worker

    def row(self) -> dict:
        return asdict(self)


def _finish(outcome: Outcome, c: complex, mean: float, settled: bool, periods: int) -> None:
    outcome.r, outcome.A, outcome.B = abs(c), c.real, -c.imag
    outcome.mean, outcome.settled, outcome.periods = mean, settled, periods


def _stopped(outcome: Outcome, message: str) -> Outcome:
    outcome.pull_in = "pull-in" in message
    outcome.failed = not outcome.pull_in
    outcome.message = message
    return outcome


class RunRefused(Exception):
    """An engine refused to start a run (the message says why)."""


class CoreRun:
    """One run of the compiled kernel from a scene's start state (vibrofmu.api.Simulation): window(k, h, count)
    -> x after each step; end_state(); release()."""

    errors = (TerminalEvent, IntegrationError, ParameterError, ArithmeticError)

    def __init__(self, library, scene: Scene):
        self.library, self.scene, self.simulation, self.contact_loss = library, scene, None, False
        self.x_end = self.v_end = math.nan

    def window(self, k: int, h: float, count: int) -> np.ndarray:
        """The x after each of `count` steps of h from k h (settle_loop's window); raises the kernel's error."""
        if self.simulation is None:  # the interval is the settling loop's: known at its first window
            self.simulation = api.Simulation(self.scene, interval=h, settings=SETTINGS, library=self.library)
        if self.simulation.k != k or self.simulation.interval != h:
            raise RuntimeError(f"CoreRun: window from step {k} of {h!r}, the plant is at step "
                               f"{self.simulation.k} of {self.simulation.interval!r}")
        run = self.simulation.advance(count)
        if not run.in_contact.all():
            self.contact_loss = True
        if len(run.x):
            self.x_end, self.v_end = run.x[-1], run.v[-1]
        if run.error is not None:
            raise run.error
        return run.x

    step = None  # settle_loop takes the window

    def end_state(self) -> tuple[float, float]:
        return self.x_end, self.v_end

    @staticmethod
    def reason(error) -> str:
        return f"{type(error).__name__}: {error}"

    def release(self, ok: bool = True) -> None:
        pass


class Engine:
    """What both engines share: `settle` on top of the engine's `open(scene)` (a run object as CoreRun)."""

    name = ""

    def open(self, scene: Scene):  # pragma: no cover - overridden
        raise NotImplementedError

    def settle(self, scene: Scene, accept=None, rate: float | None = None) -> Outcome:
        """Run from the scene's start state until settled (sweep.settle_loop with accept and rate)."""
        started = time.perf_counter()
        outcome = Outcome()
        run, ok = None, False
        try:
            run = self.open(scene)
            _finish(outcome, *settle_loop(run.step, scene, accept, rate, getattr(run, "window", None)))
            outcome.x_end, outcome.v_end = run.end_state()
            ok = True
        except RunRefused as error:
            _stopped(outcome, str(error))
        except (*CoreRun.errors, FmiError) as error:
            _stopped(outcome, run.reason(error) if run is not None else f"{type(error).__name__}: {error}")
        finally:
            if run is not None:
                outcome.contact_loss = run.contact_loss
                run.release(ok)
        outcome.cost_s = time.perf_counter() - started
        return outcome


class CoreEngine(Engine):
    """The compiled kernel stepped directly (vibrofmu.api.Simulation)."""

    name = "core"

    def __init__(self):
        from pathlib import Path

        import vibromodel
        from vibromodel.compiled import load_library

        from vibrofmu.fmus.kernel import kernel_library, kernel_sources

        if kernel_sources():
            self.library = kernel_library()
        else:
            # vibromodel came from a plant FMU's resources (a worker spawned by a process that had loaded the
            # FMU inherits its sys.path): use the kernel compiled into that FMU, next to it
            self.library, why = load_library([Path(vibromodel.__file__).resolve().parents[1]])
            if self.library is None:
                raise RuntimeError(f"no compiled kernel for the core engine: {why}")

    def open(self, scene: Scene) -> CoreRun:
        return CoreRun(self.library, scene)


class FmuRun:
    """One run of a plant FMU instance from a scene's start state (initialised here); release() returns the
    instance to its engine's pool."""

    def __init__(self, engine: "FmuEngine", instance, scene: Scene):
        import ctypes

        from vibrofmu.analyses.simulate import start_values

        self.engine, self.instance = engine, instance
        self.fmu = instance.fmu
        self.contact_loss = False
        self.x_ref, self.v_ref, _ = engine.refs
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        instance.set(start_values(scene, SETTINGS))
        self.fmu.exitInitializationMode()
        # the FMI functions FMPy loaded, called without its per-call wrapper (argument logging, list
        # conversion: two thirds of a step's cost in Python); the status is checked here as FMPy checks it
        functions = self.fmu._functions
        self._do_step, self._get_real = functions["fmi2DoStep"], functions["fmi2GetReal"]
        self._component = self.fmu.component
        self._x_vr = (ctypes.c_uint * 1)(self.x_ref)
        self._x = (ctypes.c_double * 1)()

    def step(self, t: float, h: float) -> float:
        status = self._do_step(self._component, t, h, 1)
        if status > 1:  # above fmi2Warning
            raise FmiError(function="fmi2DoStep", status=status)
        status = self._get_real(self._component, self._x_vr, 1, self._x)
        if status > 1:
            raise FmiError(function="fmi2GetReal", status=status)
        x = self._x[0]
        # the FMU's in_contact output is contact_indentation(x) > 0 of this x (plant.c, plant.py): computed
        # here with the same expression instead of a third FMI call
        if not contact_indentation(x) > 0.0:
            self.contact_loss = True
        return x

    def end_state(self) -> tuple[float, float]:
        x, v = self.fmu.getReal([self.x_ref, self.v_ref])
        return x, v

    def reason(self, error) -> str:
        from vibrofmu.hosts.run import call_failure_reason

        return call_failure_reason(error, self.engine.log, self.instance.name)

    def release(self, ok: bool = True) -> None:
        self.engine.give_back(self.instance)


class FmuEngine(Engine):
    """The plant FMU under FMPy; `fmu_bytes` is the .fmu file's content (sent to the workers once), unpacked
    into a per-process temporary folder.

    Instances are reused: a run takes an idle instance and calls fmi2Reset on it (FMI 2.0 §2.1.6: back to
    the state after fmi2Instantiate; pythonfmu builds a fresh slave object), instead of reading the model
    description and instantiating again for every settled point (that was 40-60 ms a case). An instance
    whose reset fails is freed. The instances share one FmuLog (FMPy's logger is process-wide) and are told
    apart by instance name."""

    name = "fmu"

    def __init__(self, fmu_bytes: bytes):
        from fmpy import extract

        from vibrofmu.hosts.run import FmuLog

        self.folder = tempfile.mkdtemp(prefix="vibrofmu-study-")
        self.fmu_path = os.path.join(self.folder, "plant.fmu")
        with open(self.fmu_path, "wb") as file:
            file.write(fmu_bytes)
        self.unzip_dir = extract(self.fmu_path, os.path.join(self.folder, "unzipped"))
        self.log = FmuLog()
        self.idle: list = []
        self.made = 0
        self.refs = None

    def _instance(self):
        from fmpy.fmi1 import FMICallException

        from vibrofmu.hosts.run import FmuInstance

        while self.idle:
            instance = self.idle.pop()
            try:
                instance.fmu.reset()
                return instance
            except FMICallException:
                interrupts.check()
                self._free(instance)
        self.made += 1
        instance = FmuInstance(self.fmu_path, instance_name=f"study{self.made}", log=self.log,
                               unzip_dir=self.unzip_dir)
        instance.name = f"study{self.made}"
        if self.refs is None:
            self.refs = instance.value_references(["x", "v", "in_contact"])
        return instance

    @staticmethod
    def _free(instance) -> None:
        try:
            instance.fmu.freeInstance()
        except Exception:  # noqa: BLE001 - an instance in a bad state: nothing more to do with it
            pass

    def give_back(self, instance) -> None:
        self.idle.append(instance)

    def open(self, scene: Scene) -> FmuRun:
        instance = self._instance()
        self.log.messages.clear()
        self.log.instances.clear()
        try:
            return FmuRun(self, instance, scene)
        except FmiError as error:  # the start values were refused: the FMU's log says why
            from vibrofmu.hosts.run import call_failure_reason

            self.give_back(instance)
            raise RunRefused(call_failure_reason(error, self.log, instance.name)) from None



_ENGINES: dict = {}  # per process: (name, FMU digest) -> engine


def engine_for(name: str, fmu_bytes: bytes | None = None):
    """The process's engine `name` (made on first use)."""
    key = (name, hashlib.sha256(fmu_bytes).hexdigest() if fmu_bytes else None)
    if key not in _ENGINES:
        _ENGINES[key] = CoreEngine() if name == "core" else FmuEngine(fmu_bytes)
    return _ENGINES[key]
