"""Tests for the FMI 2.0 status shim (harness/vibrofmu/fmus/shim.py, fmu_src/fmi2_status_shim.c).

A tiny pythonfmu slave (tests/data/StatusProbe.py) is built into an FMU, the
shim is installed, and the FMU is driven through fmpy's FMU2Slave.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy import calloc, free
from fmpy.validation import validate_fmu

from vibrofmu.fmus.shim import install_status_shim

DATA = Path(__file__).resolve().parents[1] / "data"
pytestmark = pytest.mark.fmu  # every test here builds the probe FMU
OK, DISCARD, ERROR, FATAL = 0, 2, 3, 4


def _build_shimmed(out: Path, *flags: str):
    """Build StatusProbe.fmu, install the shim; return (fmu path, model description, unzip dir)."""
    subprocess.run(
        ["pythonfmu", "build", "-f", str(DATA / "StatusProbe.py"), "-d", str(out), *flags],
        check=True, capture_output=True, cwd=out,
    )
    fmu = out / "StatusProbe.fmu"
    md = read_model_description(str(fmu))
    status_vr = next(v.valueReference for v in md.modelVariables if v.name == "fmi_status")
    install_status_shim(fmu, status_vr)
    return fmu, read_model_description(str(fmu)), extract(str(fmu))


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    return _build_shimmed(tmp_path_factory.mktemp("fmu"))


class Probe:
    """FMU2Slave instance with a capturing logger and status-returning calls."""

    def __init__(self, md, unzip_dir, p):
        self.logs = []  # (status, message)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(
            lambda env, name, status, cat, msg: self.logs.append((status, msg.decode()))
        )
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.cb = cb  # keep alive
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip_dir,
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName="probe")
        self.fmu.instantiate(callbacks=cb)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.setReal([self.vr["p"]], [p])

    def status(self, name, *args):
        try:
            getattr(self.fmu, name)(*args)
            return OK
        except FMICallException as e:
            return e.status

    def init(self):
        return self.status("enterInitializationMode"), self.status("exitInitializationMode")

    def close(self):
        self.fmu.freeInstance()


def test_zip_layout(probe):
    fmu, md, _ = probe
    names = zipfile.ZipFile(fmu).namelist()
    mid = md.coSimulation.modelIdentifier
    assert f"binaries/linux64/{mid}.so" in names
    assert f"binaries/linux64/{mid}_pythonfmu.so" in names
    assert not [n for n in names if n.startswith("binaries/") and "/linux64/" not in n]


def test_validate_fmu(probe):
    assert validate_fmu(str(probe[0])) == []


def test_wrong_status_vr_is_rejected(probe, tmp_path):
    copy = tmp_path / "copy.fmu"
    copy.write_bytes(probe[0].read_bytes())
    with pytest.raises(ValueError):
        install_status_shim(copy, 12345)


def test_ok_run(probe):
    _, md, d = probe
    pr = Probe(md, d, p=1.0)
    assert pr.init() == (OK, OK)
    t = 0.0
    for _ in range(10):
        assert pr.status("doStep", t, 0.1) == OK
        t += 0.1
    # y = p t with t the sum of ten 0.1 (0.9999999999999999): default rel 1e-6 admits that rounding only
    assert pr.fmu.getReal([pr.vr["y"]])[0] == pytest.approx(1.0)
    assert pr.status("terminate") == OK
    pr.close()


def test_error_in_exit_initialization_mode(probe):
    _, md, d = probe
    pr = Probe(md, d, p=-1.0)
    assert pr.init() == (OK, ERROR)
    assert any(s == ERROR and "p" in m and "-1" in m for s, m in pr.logs), pr.logs
    # after an error only getters / reset / free are forwarded
    assert pr.status("doStep", 0.0, 0.1) == ERROR
    assert any("not allowed after an error" in m for _, m in pr.logs)
    assert pr.fmu.getInteger([pr.vr["fmi_status"]]) == [3]
    # reset recreates the Python slave (p back to its default 1) and clears the error
    assert pr.status("reset") == OK
    assert pr.init() == (OK, OK)
    assert pr.status("doStep", 0.0, 0.1) == OK
    pr.close()


def test_error_in_do_step(probe):
    _, md, d = probe
    pr = Probe(md, d, p=5.0)
    assert pr.init() == (OK, OK)
    statuses, t = [], 0.0
    for _ in range(8):
        statuses.append(pr.status("doStep", t, 0.1))
        t += 0.1
    assert statuses[:5] == [OK] * 5          # steps ending at t <= 0.5
    assert statuses[5:] == [ERROR] * 3       # t > 0.5: flagged error, then refused
    assert any(s == ERROR and "p=5" in m for s, m in pr.logs), pr.logs
    pr.close()


def test_plain_discard(probe):
    _, md, d = probe
    pr = Probe(md, d, p=7.0)
    assert pr.init() == (OK, OK)
    assert pr.status("doStep", 0.0, 0.1) == DISCARD
    assert pr.status("doStep", 0.0, 0.1) == DISCARD   # discard is not an error state
    assert pr.fmu.getInteger([pr.vr["fmi_status"]]) == [0]
    pr.close()


def test_set_fmu_state_recovers_from_error(tmp_path):
    _, md, d = _build_shimmed(tmp_path, "--handle-state", "--serialize-state")
    pr = Probe(md, d, p=5.0)
    assert pr.init() == (OK, OK)
    assert pr.status("doStep", 0.0, 0.5) == OK
    saved = pr.fmu.getFMUstate()
    serialized = pr.fmu.serializeFMUstate(saved)
    assert pr.status("doStep", 0.5, 0.1) == ERROR
    restored = pr.fmu.deSerializeFMUstate(serialized)   # allowed after an error
    assert pr.status("setFMUstate", restored) == OK     # flag restored to 0 -> error cleared
    # y = p t = 5 x 0.5 at the saved state (exact in doubles); approx's default only guards the state's round trip
    assert pr.fmu.getReal([pr.vr["y"]]) == [pytest.approx(2.5)]
    assert pr.status("doStep", 0.5, 0.0) == OK
    pr.fmu.freeFMUstate(saved)
    pr.fmu.freeFMUstate(restored)
    pr.close()


FATAL_SCRIPT = textwrap.dedent("""
    import ctypes, gc, json, sys
    from fmpy import read_model_description, extract
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    fmu_path = sys.argv[1]
    md = read_model_description(fmu_path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu_path),
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.setReal([vr["p"]], [9.0])
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()

    def status(f, *a):
        try:
            f(*a)
            return 0
        except FMICallException as e:
            return e.status

    out = {"doStep": status(fmu.doStep, 0.0, 0.1)}
    gc.collect()  # lets Python really free the slave object pythonfmu released
    out["doStep2"] = status(fmu.doStep, 0.1, 0.1)
    refs = (ctypes.c_uint * 1)(vr["y"])
    vals = (ctypes.c_double * 1)(123.0)
    out["getReal"] = status(fmu.fmi2GetReal, fmu.component, refs, 1, vals)
    out["getReal_untouched"] = vals[0] == 123.0
    out["getInteger"] = status(fmu.getInteger, [vr["fmi_status"]])
    out["setReal"] = status(fmu.setReal, [vr["p"]], [1.0])
    out["reset"] = status(fmu.reset)
    out["terminate"] = status(fmu.terminate)
    fmu.freeInstance()
    gc.collect()
    out["freed"] = True
    print(json.dumps(out))
""")


def test_fatal_never_crashes(probe):
    """p=9 raises in Python: fatal, nothing forwarded afterwards, free is safe.

    Runs in a subprocess so that a crash shows up as a bad return code.
    """
    result = subprocess.run([sys.executable, "-c", FATAL_SCRIPT, str(probe[0])],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert out == {
        "doStep": FATAL, "doStep2": FATAL, "getReal": FATAL, "getReal_untouched": True,
        "getInteger": FATAL, "setReal": FATAL, "reset": FATAL, "terminate": FATAL, "freed": True,
    }


def test_simulate_fmu(probe):
    result = simulate_fmu(str(probe[0]), start_values={"p": 1.0}, stop_time=1.0)
    # FMPy's grid and y = p t at its last point: rounding of a sum of steps only (default rel 1e-6)
    assert result["time"][-1] == pytest.approx(1.0)
    assert result["y"][-1] == pytest.approx(1.0)
