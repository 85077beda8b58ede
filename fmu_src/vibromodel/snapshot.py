"""Snapshots of an object's plain data, for saving and restoring a simulation's state (FMU states).

Plain data: None, bool, int, float, str, numeric numpy arrays, and tuples, lists and str-keyed dicts
of plain data. Everything else an object holds (an integrator's right-hand side and events, a model,
a fitted solution) is rebuilt by the object's owner from the scene and settings; the snapshot is then
put back on top of the rebuilt object. to_bytes/from_bytes round-trip a snapshot exactly through
JSON (floats by repr, so bit for bit, inf and nan included; tuples and arrays keep their type).
"""
from __future__ import annotations

import copy
import json

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
    missing = set(vars(obj)) - set(rebuilt) - set(snapshot)
    foreign = set(rebuilt) & set(snapshot)
    if missing or foreign:
        raise ValueError(f"not a snapshot of this {type(obj).__name__}: "
                         f"missing {sorted(missing)}, unexpected {sorted(foreign)}")
    vars(obj).update(copy.deepcopy(snapshot))


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


def to_bytes(snapshot) -> bytes:
    return json.dumps(_tag(snapshot)).encode("utf-8")


def from_bytes(data: bytes):
    """Raises ValueError for bytes that are not a snapshot's JSON."""
    return json.loads(data.decode("utf-8"), object_hook=_untag)
