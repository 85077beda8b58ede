"""Forged FMU states (issue 25): serialized states whose content a forger changed and whose checksum he recomputed,
restored into a running instance and stepped, in the probe host's subprocess (`python -m vibrofmu.hosts.probe forged
FMU N SEED`), so that a crash or a hang is counted rather than suffered.

A native state is a header (format name, size, FNV-1a checksum: fmu_src/native/fmi2_native.c) and the State's
bytes; a pythonfmu state is "vibrofmu-state <version> <sha256>\\n<JSON>" (vibromodel.snapshot), whose compiled model
is the hex of its C structure.  Each forgery changes one place: an 8-byte word of the State (or of the compiled
model) set to a value chosen to break an index, a size or a divisor (0, -1, 1, 2**31, 2**62, -2**63, NaN, +-inf,
1e308, 5e-324 ...), or one bit flipped; the pythonfmu states also get a changed JSON number.  Per state one JSON line:
{"case": k, "where", "deserialize", "set", "step"} (statuses; -1: not reached), then {"summary": counts}.
"""
from __future__ import annotations

import ctypes
import json
import random
import struct

WORDS = [0, 1, -1, 2, 7, 20, 2**31, 2**31 - 1, 2**62, -2**63, 2**63 - 1, 10**8]
DOUBLES = [0.0, -0.0, 1.0, -1.0, 1e308, -1e308, 5e-324, 1e-300, float("nan"), float("inf"), float("-inf"), 1e6]
NATIVE_HEADER = 64 + 8 + 8  # StateHeader: format[64], size, checksum


def fnv1a(data: bytes) -> int:
    h = 14695981039346656037
    for byte in data:
        h = ((h ^ byte) * 1099511628211) & 0xFFFFFFFFFFFFFFFF
    return h


def _change_word(data: bytearray, rng: random.Random) -> str:
    """One aligned 8-byte word set to a breaking integer or double, or one bit flipped."""
    choice = rng.random()
    if choice < 0.15:
        bit = rng.randrange(8 * len(data))
        data[bit // 8] ^= 1 << (bit % 8)
        return f"bit {bit}"
    offset = 8 * rng.randrange(len(data) // 8)
    if choice < 0.6:
        value = rng.choice(WORDS)
        data[offset:offset + 8] = struct.pack("<q", value)
        return f"word {offset} = {value}"
    value = rng.choice(DOUBLES)
    data[offset:offset + 8] = struct.pack("<d", value)
    return f"word {offset} = {value!r}"


def forge_native(serialized: bytes, rng: random.Random) -> tuple[bytes, str]:
    header, payload = bytearray(serialized[:NATIVE_HEADER]), bytearray(serialized[NATIVE_HEADER:])
    where = _change_word(payload, rng)
    header[72:80] = struct.pack("<Q", fnv1a(bytes(payload)))
    return bytes(header + payload), where


SWEEP = [2**62, -1, float("nan")]  # a huge index or size, a negative one, a divisor that is not a number


def sweep_native(serialized: bytes, k: int) -> tuple[bytes, str]:
    """The k-th forgery of a sweep over the State's words: word k % n set to SWEEP[k // n % 3] (every field that
    indexes, sizes or divides gets each breaking value once in 3 n forgeries)."""
    header, payload = bytearray(serialized[:NATIVE_HEADER]), bytearray(serialized[NATIVE_HEADER:])
    words = len(payload) // 8
    offset, value = 8 * (k % words), SWEEP[k // words % len(SWEEP)]
    payload[offset:offset + 8] = struct.pack("<d" if isinstance(value, float) else "<q", value)
    header[72:80] = struct.pack("<Q", fnv1a(bytes(payload)))
    return bytes(header + payload), f"word {offset} = {value!r}"


def forge_python(serialized: bytes, rng: random.Random) -> tuple[bytes, str]:
    from vibromodel import snapshot

    state = snapshot.from_bytes(serialized)
    model = state.get("model") or {}
    if "kernel" in model and rng.random() < 0.7:
        kernel = bytearray(bytes.fromhex(model["kernel"]))
        where = "kernel " + _change_word(kernel, rng)
        model["kernel"] = bytes(kernel).hex()
    else:
        leaves = list(_numbers(state, ()))
        path = rng.choice(leaves)
        target = state
        for key in path[:-1]:
            target = target[key]
        value = rng.choice(DOUBLES + WORDS[:8] + ["text", None, [1.0]])
        target[path[-1]] = value
        where = "json " + "/".join(map(str, path)) + f" = {value!r}"
    return snapshot.to_bytes(state), where


def _numbers(node, path):
    """Paths of every number (and boolean) in a JSON tree."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _numbers(value, (*path, key))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            yield from _numbers(value, (*path, index))
    elif isinstance(node, (int, float)) and path:
        yield path


def emit(**fields) -> None:
    """One JSON line of the probe's output, flushed (a crash after it leaves it readable)."""
    print(json.dumps(fields), flush=True)


def scenario_forged(probe, n: int, seed: int, sweep: bool = False) -> None:
    """n forged states (seeded), or with sweep (native only) the first n of sweep_native's (n = 0: all of them,
    every word with each value)."""
    f, v = probe.lib, ctypes.c_void_p
    native = not probe.md.coSimulation.needsExecutionTool
    c = probe.start(stop=1e6)
    if not c:
        emit(summary=None, log=probe.take_log())
        return
    h, before = 0.1, 6
    probe.steps(c, 0.0, before, h)
    good = v()
    f.fmi2GetFMUstate(c, ctypes.byref(good))
    size = ctypes.c_size_t(0)
    f.fmi2SerializedFMUstateSize(c, good, ctypes.byref(size))
    buffer = ctypes.create_string_buffer(size.value)
    f.fmi2SerializeFMUstate(c, good, buffer, size.value)
    serialized = buffer.raw
    rng = random.Random(seed)
    if sweep and native and n <= 0:
        n = len(SWEEP) * ((len(serialized) - NATIVE_HEADER) // 8)
    counts = {"refused": 0, "accepted": 0, "fatal": 0}
    for k in range(n):
        if sweep and native:
            data, where = sweep_native(serialized, k)
        else:
            data, where = (forge_native if native else forge_python)(serialized, rng)
        state = v()
        result = {"case": k, "where": where, "deserialize": f.fmi2DeSerializeFMUstate(c, data, len(data),
                                                                                         ctypes.byref(state)),
                  "set": -1, "step": -1}
        if result["deserialize"] == 0:
            result["set"] = f.fmi2SetFMUstate(c, state)
            if result["set"] == 0:
                result["step"] = probe.steps(c, before * h, 2, h)[0]
            f.fmi2FreeFMUstate(c, ctypes.byref(state))
        statuses = [result[key] for key in ("deserialize", "set", "step")]
        outcome = "fatal" if 4 in statuses else "accepted" if result["set"] == 0 else "refused"
        counts[outcome] += 1
        if outcome == "fatal":
            emit(**result, log=probe.take_log()[-3:])
            break  # the instance is lost (pythonfmu): nothing more to learn from it
        restore = f.fmi2SetFMUstate(c, good)  # the instance as it was for the next forgery
        if restore != 0:
            emit(**result, restore=restore, log=probe.take_log()[-3:])
            break
        if k % 500 == 0:
            emit(**result, log=probe.take_log()[-1:])
        probe.take_log()
    emit(summary=counts, n=n, seed=seed, native=native, sweep=sweep, size=len(serialized))
    f.fmi2FreeFMUstate(c, ctypes.byref(good))
    f.fmi2FreeInstance(c)


def summary(lines: list[dict]) -> dict | None:
    return next((line["summary"] for line in lines if "summary" in line), None)
