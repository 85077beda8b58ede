"""Snapshots of an object's plain data, for saving and restoring a simulation's state (FMU states).

Plain data: None, bool, int, float, str, numeric numpy arrays, and tuples, lists and str-keyed dicts
of plain data. Everything else an object holds (an integrator's right-hand side and events, a model,
a fitted solution) is rebuilt by the object's owner from the scene and settings; the snapshot is then
put back on top of the rebuilt object. to_bytes/from_bytes round-trip a snapshot exactly through
JSON (floats by repr, so bit for bit, inf and nan included; tuples and arrays keep their type).

Serialized states are tamper-evident: the bytes are a header line "vibrofmu-state <version> <sha256>" and the
JSON. from_bytes refuses another version and any content whose SHA-256 differs from the header's. SHA-256 rather
than CRC32: a CRC detects every burst of up to 32 changed bits but lets 1 in 2^32 other changes through, and a
state is kilobytes to megabytes (fidelity 3's tables); SHA-256 misses no accidental change in practice, is in the
standard library (hashlib) and costs about 2 ms per megabyte, nothing beside the JSON. Neither stops a deliberate
forger, who can recompute it: restore_attributes and the FMU slaves also validate every field (types, shapes,
finiteness, counts) against a freshly built object, and refuse a state whose parameters disagree with its model.
"""
from __future__ import annotations

import copy
import hashlib
import json
import math

import numpy as np

_SCALARS = (type(None), bool, int, float, str)
_TUPLE, _ARRAY, _DTYPE = "__tuple__", "__ndarray__", "dtype"


def is_plain(value) -> bool:
    if isinstance(value, _SCALARS):
        return True
    if isinstance(value, np.ndarray):
        return value.dtype.kind in "biuf"
    if isinstance(value, (tuple, list)):
        return all(is_plain(item) for item in value)
    if isinstance(value, dict):
        return all(isinstance(key, str) and is_plain(item) for key, item in value.items())
    return False


def plain_attributes(obj, rebuilt: tuple[str, ...]) -> dict:
    """A deep copy of obj's attributes, all but the `rebuilt` ones, which the owner makes anew.

    Raises TypeError for any other attribute that is not plain data: it would be lost silently.
    """
    data = {name: value for name, value in vars(obj).items() if name not in rebuilt}
    for name, value in data.items():
        if not is_plain(value):
            raise TypeError(f"{type(obj).__name__}.{name} ({type(value).__name__}) is neither plain data "
                            f"nor rebuilt; add it to the rebuilt attributes or make it plain")
    return copy.deepcopy(data)


def restore_attributes(obj, snapshot: dict, rebuilt: tuple[str, ...]) -> None:
    """Put a snapshot of plain_attributes(obj, rebuilt) back onto obj, freshly built by its owner.

    Raises ValueError when the snapshot lacks an attribute obj has or names a rebuilt one (a snapshot
    of another kind of object).
    """
    if not isinstance(snapshot, dict):
        raise ValueError(f"not a snapshot of a {type(obj).__name__}: {type(snapshot).__name__}")
    missing = set(vars(obj)) - set(rebuilt) - set(snapshot)
    foreign = set(rebuilt) & set(snapshot)
    if missing or foreign:
        raise ValueError(f"not a snapshot of this {type(obj).__name__}: "
                         f"missing {sorted(missing)}, unexpected {sorted(foreign)}")
    for name, value in snapshot.items():  # attributes set only while running (no fresh value) are checked as plain
        check_like(value, vars(obj).get(name), f"{type(obj).__name__}.{name}")
    vars(obj).update(copy.deepcopy(snapshot))


def check_like(value, fresh, path: str) -> None:
    """Raise ValueError unless `value` (from a snapshot) could be what a freshly built object's `fresh` became:
    plain data; every float finite (where fresh holds a non-finite constant, e.g. max_step = inf, that same
    constant); the same type as fresh (None in either is a field not set yet); arrays of fresh's dtype and number of
    dimensions (and shape, where fresh has one that is fixed: not empty); dicts with fresh's keys; integers that
    count (fresh >= 0) not negative."""
    if not is_plain(value):
        raise ValueError(f"{path}: {type(value).__name__} is not plain data")
    if fresh is None or value is None:
        _check_finite(value, path)
        return
    if isinstance(fresh, float) and not math.isfinite(fresh):
        if not (isinstance(value, float) and value == fresh or math.isnan(fresh) and value != value):
            raise ValueError(f"{path} = {value!r}: the model holds the constant {fresh!r} here")
        return
    if _kind(value) != _kind(fresh):
        raise ValueError(f"{path}: a {type(value).__name__} where the model holds a {type(fresh).__name__}")
    if isinstance(fresh, np.ndarray):
        if value.dtype != fresh.dtype or value.ndim != fresh.ndim or (fresh.size and value.shape != fresh.shape):
            raise ValueError(f"{path}: array {value.dtype}{value.shape}, the model's is {fresh.dtype}{fresh.shape}")
        _check_finite(value, path)
    elif isinstance(fresh, dict):
        if set(value) != set(fresh):
            raise ValueError(f"{path}: keys {sorted(value)}, the model's are {sorted(fresh)}")
        for key in value:
            check_like(value[key], fresh[key], f"{path}[{key!r}]")
    elif isinstance(fresh, (tuple, list)) and len(value) == len(fresh):
        for i, (item, fresh_item) in enumerate(zip(value, fresh)):
            check_like(item, fresh_item, f"{path}[{i}]")
    elif isinstance(fresh, int) and not isinstance(fresh, bool) and fresh >= 0 and value < 0:
        raise ValueError(f"{path} = {value!r}: a count cannot be negative")
    else:
        _check_finite(value, path)


def _kind(value) -> type:
    """The plain type value counts as (numpy's float64 as float: JSON gives it back as float)."""
    for kind in (bool, int, float, str, np.ndarray, tuple, list, dict):
        if isinstance(value, kind):
            return kind
    return type(value)


def _check_finite(value, path: str) -> None:
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{path} = {value!r} is not finite")
    if isinstance(value, np.ndarray) and value.dtype.kind == "f" and not np.all(np.isfinite(value)):
        raise ValueError(f"{path}: array with non-finite entries")
    if isinstance(value, (tuple, list)):
        for i, item in enumerate(value):
            _check_finite(item, f"{path}[{i}]")
    if isinstance(value, dict):
        for key, item in value.items():
            _check_finite(item, f"{path}[{key!r}]")


def _tag(value):
    if isinstance(value, tuple):
        return {_TUPLE: [_tag(item) for item in value]}
    if isinstance(value, np.ndarray):
        return {_ARRAY: value.tolist(), _DTYPE: value.dtype.str}
    if isinstance(value, list):
        return [_tag(item) for item in value]
    if isinstance(value, dict):
        return {key: _tag(item) for key, item in value.items()}
    return value


def _untag(mapping: dict):
    if set(mapping) == {_TUPLE}:
        return tuple(mapping[_TUPLE])
    if set(mapping) == {_ARRAY, _DTYPE}:
        return np.array(mapping[_ARRAY], dtype=np.dtype(mapping[_DTYPE]))
    return mapping


MAGIC, VERSION = b"vibrofmu-state", 2  # the header of serialized states; VERSION changes with the layout
# (2: the compiled DOP853 stores its stages and dense output stage-major, k[stage][component])


def to_bytes(snapshot) -> bytes:
    """Header "vibrofmu-state <VERSION> <sha256 of the JSON>", a newline, the JSON."""
    payload = json.dumps(_tag(snapshot)).encode("utf-8")
    return b"%s %d %s\n" % (MAGIC, VERSION, hashlib.sha256(payload).hexdigest().encode("ascii")) + payload


def from_bytes(data: bytes):
    """Raises ValueError for bytes that are not a serialized snapshot of this version with an intact checksum."""
    header, newline, payload = bytes(data).partition(b"\n")
    parts = header.split(b" ")
    if not newline or len(parts) != 3 or parts[0] != MAGIC:
        raise ValueError("not a serialized vibrofmu state (no vibrofmu-state header)")
    if parts[1] != b"%d" % VERSION:
        raise ValueError(f"state format version {parts[1].decode(errors='replace')!r}; this FMU reads {VERSION}")
    if hashlib.sha256(payload).hexdigest().encode("ascii") != parts[2]:
        raise ValueError("checksum mismatch: the state's bytes changed after it was serialized")
    return json.loads(payload.decode("utf-8"), object_hook=_untag)
