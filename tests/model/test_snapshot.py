"""vibromodel.snapshot: plain-data snapshots of objects and their exact byte round trip."""
import math

import numpy as np
import pytest

from vibromodel import snapshot


class Holder:
    def __init__(self):
        self.f = math.sin  # rebuilt by the owner
        self.t, self.h, self.flag, self.name = 0.1 + 0.2, math.inf, True, "contact"
        self.stop = ("pull-in", -0.0, 5e-324, math.nan)
        self.stages = ([1.0, 2.0], [3.0])
        self.side = {"contact": False}
        self.y = np.array([1.0 / 3.0, -2.0])


def test_round_trip_through_bytes_is_exact_and_keeps_types():
    data = snapshot.plain_attributes(Holder(), rebuilt=("f",))
    back = snapshot.from_bytes(snapshot.to_bytes(data))
    assert type(back["stop"]) is tuple and type(back["stages"][0]) is list
    # exact by construction: the bytes carry each double's shortest repr, which round-trips (1/3 included)
    assert back["y"].dtype == np.float64 and back["y"].tolist() == data["y"].tolist()
    assert back["t"] == 0.1 + 0.2 and back["h"] == math.inf and math.copysign(1.0, back["stop"][1]) == -1.0
    assert back["stop"][2] == 5e-324 and math.isnan(back["stop"][3])
    target = Holder()
    target.t = target.y = None
    snapshot.restore_attributes(target, back, rebuilt=("f",))
    assert target.t == 0.1 + 0.2 and target.y.tolist() == [1.0 / 3.0, -2.0] and target.f is math.sin


def test_snapshot_is_a_copy():
    holder = Holder()
    data = snapshot.plain_attributes(holder, rebuilt=("f",))
    holder.stages[0].append(9.0)
    assert data["stages"][0] == [1.0, 2.0]


def test_unlisted_non_plain_attribute_is_an_error_not_a_silent_loss():
    with pytest.raises(TypeError, match="Holder.f"):
        snapshot.plain_attributes(Holder(), rebuilt=())


def test_snapshot_of_another_object_is_refused():
    data = snapshot.plain_attributes(Holder(), rebuilt=("f",))
    del data["t"]
    with pytest.raises(ValueError, match="missing \\['t'\\]"):
        snapshot.restore_attributes(Holder(), data, rebuilt=("f",))
