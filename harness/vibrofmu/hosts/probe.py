"""A ctypes host that calls one FMU's FMI 2.0 functions with arguments FMPy never passes (NULL, odd resource
locations, a wrong GUID, Model Exchange, forged serialized states), meant to run in a subprocess so that a crash
is a result, not the end of the caller (issue 25).

`python -m vibrofmu.hosts.probe SCENARIO FMU [ARG]` unpacks FMU (or uses the folder), runs the scenario and prints one
JSON line per case, flushed before the next case starts: a crash shows as a non-zero exit code after the line of the
last case that finished (`run_probe` reads it).  Scenarios:
  instantiate   every resource-location form of `resource_forms`, then a wrong and a NULL GUID and Model Exchange:
                {"case", "uri", "accepted", "log"}
  states        fmi2SetFMUstate(NULL), then fmi2Reset and a run; fmi2FreeFMUstate sets the pointer to NULL; NULL
                arguments to the other state calls: {"case", "status", "log", ...}
  pointers      NULL arrays and result pointers in every FMI 2.0 function, freed and foreign instance pointers
                (vibrofmu.hosts.pointers); pointers3: the same in FMI 3.0
  loader OTHER  a pythonfmu FMU's fmi2Instantiate on damaged copies of its resources and on OTHER's resources
  me_block      the Model Exchange block of a native state forged field by field, restored in ME and CS instances
  foreign_states OTHER (foreign_states3: FMI 3.0)  states of FMU OTHER (loaded in the same process) and freed states given to FMU's state calls
  forged N SEED [sweep]  N forged serialized states (see `forge`; sweep: native states, every word in turn):
                each restored and stepped; {"case", "deserialize", "set", "step", "log"} every 500th state, then a
                summary line.
"""
from __future__ import annotations

import ctypes
import json
import os
import shutil
import subprocess
import sys
import tempfile
import urllib.parse
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE, fmi2StepFinishedTYPE)

from vibrofmu.hosts.forge import emit, scenario_forged
from vibrofmu.hosts.pointers import (Probe3, scenario_foreign_states, scenario_foreign_states3, scenario_loader,
                                     scenario_me_block, scenario_pointers, scenario_pointers3)

OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4
MODEL_EXCHANGE, CO_SIMULATION = 0, 1


class Probe:
    """One FMU's binary loaded with ctypes, its log collected."""

    def __init__(self, unzipped: Path):
        self.unzipped = Path(unzipped)
        self.md = read_model_description(str(self.unzipped))
        identifier = self.md.coSimulation.modelIdentifier
        self.lib = ctypes.CDLL(str(self.unzipped / "binaries" / "linux64" / f"{identifier}.so"))
        self.log: list[str] = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._logger)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(lambda n, size: None)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(lambda obj: None)
        self.callbacks.stepFinished = fmi2StepFinishedTYPE(0)
        self.callbacks.componentEnvironment = None
        f = self.lib
        v, p, s = ctypes.c_void_p, ctypes.POINTER, ctypes.c_size_t
        f.fmi2Instantiate.restype = v
        f.fmi2Instantiate.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p,
                                      p(fmi2CallbackFunctions), ctypes.c_int, ctypes.c_int]
        f.fmi2FreeInstance.argtypes = [v]
        f.fmi2FreeInstance.restype = None
        for name in ("fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Reset", "fmi2Terminate"):
            getattr(f, name).argtypes = [v]
        f.fmi2SetupExperiment.argtypes = [v, ctypes.c_int, ctypes.c_double, ctypes.c_double, ctypes.c_int,
                                          ctypes.c_double]
        f.fmi2DoStep.argtypes = [v, ctypes.c_double, ctypes.c_double, ctypes.c_int]
        f.fmi2GetReal.argtypes = [v, p(ctypes.c_uint), s, p(ctypes.c_double)]
        f.fmi2GetFMUstate.argtypes = [v, p(v)]
        f.fmi2SetFMUstate.argtypes = [v, v]
        f.fmi2FreeFMUstate.argtypes = [v, p(v)]
        f.fmi2SerializedFMUstateSize.argtypes = [v, v, p(s)]
        f.fmi2SerializeFMUstate.argtypes = [v, v, ctypes.c_char_p, s]
        f.fmi2DeSerializeFMUstate.argtypes = [v, ctypes.c_char_p, s, p(v)]

    def _logger(self, env, instance, status, category, message):
        self.log.append(f"[{status}] {(message or b'').decode(errors='replace')}")

    def take_log(self) -> list[str]:
        log, self.log = self.log, []
        return log

    def instantiate(self, uri: str | None, guid: str | None = None, kind: int = CO_SIMULATION,
                    name: bytes | None = b"probe"):
        guid = self.md.guid if guid is None else guid
        return self.lib.fmi2Instantiate(name, kind, None if guid == "NULL" else guid.encode(),
                                        None if uri is None else uri.encode(), ctypes.byref(self.callbacks), 0, 0)

    def real_output_vr(self) -> int:
        return next(v.valueReference for v in self.md.modelVariables if v.causality == "output" and v.type == "Real")

    def resources_uri(self) -> str:
        return (self.unzipped / "resources").as_uri()

    def start(self, stop: float = 10.0):
        """An instance in step mode, or None."""
        c = self.instantiate(self.resources_uri())
        if not c:
            return None
        f = self.lib
        f.fmi2SetupExperiment(c, 0, 0.0, 0.0, 1, stop)
        f.fmi2EnterInitializationMode(c)
        if f.fmi2ExitInitializationMode(c) > WARNING:
            f.fmi2FreeInstance(c)
            return None
        return c

    def steps(self, c, t: float, n: int, h: float = 0.1) -> tuple[int, float]:
        """n doSteps from t: (the worst status, the first Real output after them)."""
        worst = OK
        for k in range(n):
            worst = max(worst, self.lib.fmi2DoStep(c, t + k * h, h, 1))
            if worst > WARNING:
                break
        x = ctypes.c_double(float("nan"))
        vr = ctypes.c_uint(next(v.valueReference for v in self.md.modelVariables
                                if v.causality == "output" and v.type == "Real"))  # x, or the controller's U
        self.lib.fmi2GetReal(c, ctypes.byref(vr), 1, ctypes.byref(x))
        return worst, x.value


def resource_forms(unzipped: Path, needs_resources: bool) -> list[tuple[str, str | None, bool]]:
    """(label, fmuResourceLocation, whether FMI 2.0 wants it accepted): every form of a file URI of the resources
    folder, and what is not one. The FMU root is accepted only by an FMU that needs nothing from its resources."""
    resources = (Path(unzipped) / "resources").resolve()
    plain = str(resources)
    spaced = Path(unzipped).parent / f"{Path(unzipped).name} spaced é"  # a copy of resources/ in a folder whose
    if not spaced.exists():                                               # name is escaped
        shutil.copytree(resources, spaced / "resources", symlinks=True)
    escaped = urllib.parse.quote(str(spaced / "resources"))  # ' ' -> %20, 'é' -> %C3%A9
    letters = plain.replace("/resources", "/%72esources")  # an escaped letter
    return [
        ("file:///abs", resources.as_uri(), True),
        ("file:///abs/", resources.as_uri() + "/", True),
        ("file:/abs", "file:" + plain, True),
        ("file:/abs/", "file:" + plain + "/", True),
        ("file://localhost/abs", "file://localhost" + plain, True),
        ("file://localhost/abs/", "file://localhost" + plain + "/", True),
        ("FILE:///abs (scheme case)", "FILE://" + plain, True),
        ("file:///abs with %72", "file://" + letters, True),
        ("file:/abs with %20 and %C3%A9", "file:" + escaped, True),
        ("file:///abs with %20 and %C3%A9/", "file://" + escaped + "/", True),
        ("NULL", None, False),
        ("empty", "", False),
        ("http URI", "http://127.0.0.1" + plain, False),
        ("another host", "file://otherhost" + plain, False),
        ("plain path", plain, False),
        ("relative", "file:resources", False),
        ("missing folder", (resources / "missing").as_uri(), False),
        ("a file, not a folder", (Path(unzipped) / "modelDescription.xml").resolve().as_uri(), False),
        ("bad escape", "file://" + plain + "%zz", False),
        ("NUL escape", "file://" + plain + "%00", False),
        ("query", "file://" + plain + "?x=1", False),
        ("FMU root", Path(unzipped).resolve().as_uri(), not needs_resources),
    ]


def needs_resources(md) -> bool:
    return md.coSimulation.needsExecutionTool  # the pythonfmu FMUs: their Python slave is in resources/


def scenario_instantiate(probe: Probe) -> None:
    forms = resource_forms(probe.unzipped, needs_resources(probe.md))
    cases = [(label, uri, None, CO_SIMULATION, b"probe", accept) for label, uri, accept in forms]
    here = probe.resources_uri()
    cases += [("wrong GUID", here, "{00000000-0000-0000-0000-000000000000}", CO_SIMULATION, b"probe", False),
              ("NULL GUID", here, "NULL", CO_SIMULATION, b"probe", False),
              ("NULL instanceName", here, None, CO_SIMULATION, None, False),
              ("blank instanceName", here, None, CO_SIMULATION, b" \t", False)]
    offers_me = probe.md.modelExchange is not None  # the native plant and closed loop (fmi2_me.c)
    cases.append(("Model Exchange", here, None, MODEL_EXCHANGE, b"probe", offers_me))
    for label, uri, guid, kind, name, accept in cases:
        c = probe.instantiate(uri, guid, kind, name)
        accepted = bool(c)
        if accepted:
            probe.lib.fmi2FreeInstance(c)
        emit(case=label, uri=uri, expected=accept, accepted=accepted, log=probe.take_log())


def scenario_states(probe: Probe) -> None:
    f, v = probe.lib, ctypes.c_void_p
    c = probe.start()
    emit(case="start", ok=bool(c), log=probe.take_log())
    if not c:
        return
    emit(case="setFMUstate(NULL)", status=f.fmi2SetFMUstate(c, None), log=probe.take_log())
    status, x = probe.steps(c, 0.0, 3)
    emit(case="doStep after setFMUstate(NULL)", status=status, x=x, log=probe.take_log())
    emit(case="reset", status=f.fmi2Reset(c), log=probe.take_log())
    f.fmi2SetupExperiment(c, 0, 0.0, 0.0, 1, 10.0)
    f.fmi2EnterInitializationMode(c)
    emit(case="initialise after reset", status=f.fmi2ExitInitializationMode(c), log=probe.take_log())
    status, x = probe.steps(c, 0.0, 3)
    emit(case="doStep after reset", status=status, x=x, log=probe.take_log())
    state = v()
    emit(case="getFMUstate", status=f.fmi2GetFMUstate(c, ctypes.byref(state)), log=probe.take_log())
    size = ctypes.c_size_t(0)
    emit(case="serializedFMUstateSize", status=f.fmi2SerializedFMUstateSize(c, state, ctypes.byref(size)),
         size=size.value, log=probe.take_log())
    emit(case="serializedFMUstateSize(NULL state)", status=f.fmi2SerializedFMUstateSize(c, None, ctypes.byref(size)),
         log=probe.take_log())
    emit(case="serializedFMUstateSize(NULL size)", status=f.fmi2SerializedFMUstateSize(c, state, None),
         log=probe.take_log())
    emit(case="serializeFMUstate(NULL bytes)", status=f.fmi2SerializeFMUstate(c, state, None, size.value),
         log=probe.take_log())
    emit(case="serializeFMUstate(NULL state)",
         status=f.fmi2SerializeFMUstate(c, None, ctypes.create_string_buffer(size.value), size.value),
         log=probe.take_log())
    restored = v()
    emit(case="deSerializeFMUstate(NULL bytes)", status=f.fmi2DeSerializeFMUstate(c, None, 8, ctypes.byref(restored)),
         log=probe.take_log())
    emit(case="deSerializeFMUstate(NULL state)", status=f.fmi2DeSerializeFMUstate(c, b"12345678", 8, None),
         log=probe.take_log())
    emit(case="getFMUstate(NULL)", status=f.fmi2GetFMUstate(c, None), log=probe.take_log())
    emit(case="freeFMUstate", status=f.fmi2FreeFMUstate(c, ctypes.byref(state)), pointer=state.value,
         log=probe.take_log())
    emit(case="freeFMUstate(NULL)", status=f.fmi2FreeFMUstate(c, None), log=probe.take_log())
    emit(case="freeFMUstate(&NULL)", status=f.fmi2FreeFMUstate(c, ctypes.byref(state)), log=probe.take_log())
    status, x = probe.steps(c, 0.3, 3)
    emit(case="doStep at the end", status=status, x=x, log=probe.take_log())
    f.fmi2FreeInstance(c)


def run_probe(scenario: str, fmu: Path, *args: str, timeout: float = 600.0) -> tuple[int, list[dict], str]:
    """Run a scenario in a subprocess: (exit code, the JSON lines, stderr's tail). A negative exit code is the
    signal that killed it (a crash)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(Path(__file__).parents[2]),
                                                                    os.environ.get("PYTHONPATH", "")) if p)}
    proc = subprocess.run([sys.executable, "-m", "vibrofmu.hosts.probe", scenario, str(fmu), *args],
                          capture_output=True, text=True, timeout=timeout, env=env)
    lines = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    return proc.returncode, lines, proc.stderr[-2000:]


def main(argv: list[str]) -> int:
    scenario, fmu, *rest = argv
    with tempfile.TemporaryDirectory(prefix="vibrofmu_probe_") as tmp:
        unzipped = Path(fmu) if Path(fmu).is_dir() else Path(extract(fmu, os.path.join(tmp, "fmu")))
        if scenario == "pointers3":
            scenario_pointers3(Probe3(unzipped, read_model_description(str(unzipped))))
            return 0
        if scenario == "foreign_states3":
            other = Path(rest[0]) if Path(rest[0]).is_dir() else Path(extract(rest[0], os.path.join(tmp, "other")))
            scenario_foreign_states3(Probe3(unzipped, read_model_description(str(unzipped))),
                                     Probe3(other, read_model_description(str(other))))
            return 0
        probe = Probe(unzipped)
        if scenario == "instantiate":
            scenario_instantiate(probe)
        elif scenario == "states":
            scenario_states(probe)
        elif scenario == "pointers":
            scenario_pointers(probe)
        elif scenario == "loader":
            other = Path(rest[0]) if Path(rest[0]).is_dir() else Path(extract(rest[0], os.path.join(tmp, "other")))
            scenario_loader(probe, other)
        elif scenario == "me_block":
            scenario_me_block(probe)
        elif scenario == "foreign_states":
            other = Path(rest[0]) if Path(rest[0]).is_dir() else Path(extract(rest[0], os.path.join(tmp, "other")))
            scenario_foreign_states(probe, Probe(other))
        elif scenario == "forged":
            scenario_forged(probe, int(rest[0]), int(rest[1]), sweep=rest[2:] == ["sweep"])
        else:
            raise SystemExit(f"error: unknown scenario {scenario!r}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
