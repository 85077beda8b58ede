"""The two engines a study case runs on, and the outcome of one case.

- `fmu`: the built plant FMU under FMPy (what users validate), one instance per settled point;
- `core`: the compiled kernel directly (vibromodel.compiled.CompiledPlant), no FMI layer.

Both run the plant at fidelity 0 (exact contact force, adaptive DOP853, rtol 1e-8) through the same
settling loop (sweep.settle_loop: the complex first harmonic settled over windows of forcing periods), so
the FMU's C fast path and the core step the same kernel and give the same bits (tests/test_study_engines.py).

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

from vibromodel.integrate import IntegrationError, TerminalEvent
from vibromodel.parameters import ParameterError, Scene
from vibromodel.plant import Settings

from ..sweep import settle_loop

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


class CoreEngine:
    """The compiled kernel (CompiledPlant) stepped directly."""

    name = "core"

    def __init__(self):
        from pathlib import Path

        import vibromodel
        from vibromodel.compiled import load_library

        from ..kernel import kernel_library, kernel_sources

        if kernel_sources():
            self.library = kernel_library()
        else:
            # vibromodel came from a plant FMU's resources (a worker spawned by a process that had loaded the
            # FMU inherits its sys.path): use the kernel compiled into that FMU, next to it
            self.library, why = load_library([Path(vibromodel.__file__).resolve().parents[1]])
            if self.library is None:
                raise RuntimeError(f"no compiled kernel for the core engine: {why}")

    def settle(self, scene: Scene, accept=None, rate: float | None = None) -> Outcome:
        """Run from the scene's start state until settled (sweep.settle_loop with accept and rate)."""
        from vibromodel.compiled import CompiledPlant

        started = time.perf_counter()
        outcome = Outcome()
        try:
            plant = CompiledPlant(scene, SETTINGS, self.library)

            def step(t, h):
                out = plant.do_step(t, h, 0.0)
                if not out.in_contact:
                    outcome.contact_loss = True
                return out.x

            _finish(outcome, *settle_loop(step, scene, accept, rate))
            outcome.x_end, outcome.v_end = plant.output(0), plant.output(1)
        except (TerminalEvent, IntegrationError, ParameterError, ArithmeticError) as error:
            _stopped(outcome, f"{type(error).__name__}: {error}")
        outcome.cost_s = time.perf_counter() - started
        return outcome


class FmuEngine:
    """The plant FMU under FMPy; `fmu_bytes` is the .fmu file's content (sent to the workers once), unpacked
    into a per-process temporary folder."""

    name = "fmu"

    def __init__(self, fmu_bytes: bytes):
        from fmpy import extract

        self.folder = tempfile.mkdtemp(prefix="vibrofmu-study-")
        self.fmu_path = os.path.join(self.folder, "plant.fmu")
        with open(self.fmu_path, "wb") as file:
            file.write(fmu_bytes)
        self.unzip_dir = extract(self.fmu_path, os.path.join(self.folder, "unzipped"))

    def settle(self, scene: Scene, accept=None, rate: float | None = None) -> Outcome:
        """Run from the scene's start state until settled (sweep.settle_loop with accept and rate)."""
        from fmpy.fmi1 import FMICallException

        from ..run import FmuInstance, _reason
        from ..simulate import start_values

        started = time.perf_counter()
        outcome = Outcome()
        instance = FmuInstance(self.fmu_path, unzip_dir=self.unzip_dir)
        fmu = instance.fmu
        x_ref, v_ref, contact_ref = instance.value_references(["x", "v", "in_contact"])
        try:
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            instance.set(start_values(scene, SETTINGS))
            fmu.exitInitializationMode()

            def step(t, h):
                fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
                if not fmu.getBoolean([contact_ref])[0]:
                    outcome.contact_loss = True
                return fmu.getReal([x_ref])[0]

            _finish(outcome, *settle_loop(step, scene, accept, rate))
            outcome.x_end, outcome.v_end = fmu.getReal([x_ref, v_ref])
        except FMICallException as error:
            _stopped(outcome, _reason(error, instance.log))
        finally:
            instance.close()
        outcome.cost_s = time.perf_counter() - started
        return outcome


_ENGINES: dict = {}  # per process: (name, FMU digest) -> engine


def engine_for(name: str, fmu_bytes: bytes | None = None):
    """The process's engine `name` (made on first use)."""
    key = (name, hashlib.sha256(fmu_bytes).hexdigest() if fmu_bytes else None)
    if key not in _ENGINES:
        _ENGINES[key] = CoreEngine() if name == "core" else FmuEngine(fmu_bytes)
    return _ENGINES[key]
