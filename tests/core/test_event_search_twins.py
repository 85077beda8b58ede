"""The one event search in both languages (core/roots.c bernstein_search, integrate.bernstein_search): the same
pieces on the same coefficients, a bound on the pieces it examines, and its constants stated once per language and
kept equal here. roots.c is compiled alone into a small library and called through ctypes with Python callbacks,
so the C search sees exactly the `beyond` verdicts the Python one sees."""
import ctypes
import math
import re
import subprocess

import numpy as np
import pytest

from vibrofmu.fmus import kernel, toolchain
from vibromodel import integrate

ROOTS_H = kernel.CORE / "roots.h"
BEYOND = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.POINTER(ctypes.c_int))
ROOT_EVENT_UNSETTLED = -3


@pytest.fixture(scope="module")
def roots(tmp_path_factory):
    out = tmp_path_factory.mktemp("roots") / "roots.so"
    command = [*toolchain.c_compiler(), "-std=c11", "-O2", *toolchain.IEEE, "-fPIC", "-shared", "-o", str(out),
               str(kernel.CORE / "roots.c"), "-lm"]
    subprocess.run(command, check=True, capture_output=True, text=True)
    library = ctypes.CDLL(str(out))
    library.bernstein_search.restype = ctypes.c_int
    library.bernstein_search.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.c_int, ctypes.c_int, ctypes.c_double,
                                         BEYOND, ctypes.c_void_p, *[ctypes.POINTER(ctypes.c_int)],
                                         ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double),
                                         ctypes.POINTER(ctypes.c_int)]
    return library


def c_search(roots, b, positive, beyond, tol):
    """(code, None or (s_a, s_b, at_start), the fractions beyond was asked about)"""
    asked = []

    def callback(_context, s, out):
        asked.append(s)
        out[0] = int(bool(beyond(s)))
        return 0

    found, at_start = ctypes.c_int(), ctypes.c_int()
    s_a, s_b = ctypes.c_double(), ctypes.c_double()
    array = (ctypes.c_double * len(b))(*b)
    code = roots.bernstein_search(array, len(b) - 1, int(positive), tol, BEYOND(callback), None, ctypes.byref(found),
                                  ctypes.byref(s_a), ctypes.byref(s_b), ctypes.byref(at_start))
    return code, ((s_a.value, s_b.value, bool(at_start.value)) if found.value else None), asked


def py_search(b, positive, beyond, tol):
    asked = []

    def counting(s):
        asked.append(s)
        return beyond(s)

    try:
        return 0, integrate.bernstein_search(list(b), positive, counting, tol), asked
    except RuntimeError as error:
        assert str(error) == integrate.EVENT_UNSETTLED
        return ROOT_EVENT_UNSETTLED, None, asked


def header_value(name):
    match = re.search(rf"#define {name} (.+?)(?:  /\*|$)", ROOTS_H.read_text(), re.M)
    assert match, name
    return match.group(1).strip()


def test_the_constants_are_the_same_in_both_languages():
    assert int(header_value("ROOT_EVENT_MAX_DEPTH")) == integrate.EVENT_MAX_DEPTH
    assert int(header_value("ROOT_EVENT_MAX_PIECES")) == integrate.EVENT_MAX_PIECES
    assert float.fromhex(header_value("ROOT_EVENT_ROUNDING")) == integrate.EVENT_ROUNDING
    text = re.search(r'#define ROOT_EVENT_UNSETTLED_TEXT ((?:"[^"]*"\s*\\?\s*)+)', ROOTS_H.read_text()).group(1)
    assert "".join(re.findall(r'"([^"]*)"', text)) == integrate.EVENT_UNSETTLED


def polynomial_beyond(b, positive):
    """beyond(s) from the polynomial itself (de Casteljau at s): a search whose hull and interpolant agree"""
    def value(s):
        points = list(b)
        for _ in range(1, len(points)):
            points = [(1 - s) * points[k] + s * points[k + 1] for k in range(len(points) - 1)]
        return points[0]
    return lambda s: (not value(s) > 0.0) if positive else value(s) > 0.0


def test_both_twins_find_the_same_piece(roots):
    """Random polynomials of degree 3 and 7, their own beyond, random tol (0 included): the same code, piece and
    sequence of questions, bit for bit."""
    rng = np.random.default_rng(11)
    for trial in range(600):
        degree = (3, 7)[trial % 2]
        b = list(rng.normal(size=degree + 1) * 10.0 ** rng.uniform(-12, 3))
        positive = bool(trial % 3)
        tol = 0.0 if trial % 4 == 0 else float(10.0 ** rng.uniform(-16, 0)) * max(map(abs, b))
        beyond = polynomial_beyond(b, positive)
        assert c_search(roots, b, positive, beyond, tol) == py_search(b, positive, beyond, tol), (b, positive, tol)


def test_an_interpolant_that_contradicts_its_hull_is_given_up_after_the_bound(roots):
    """The hull says the event is everywhere (every coefficient beyond, never monotone) while the interpolant says
    nowhere: with tol 0 nothing stops the split but the depth, 2^40 pieces. Both twins examine EVENT_MAX_PIECES
    pieces and give up with the same code."""
    b = [-1.0, -2.0] * 4
    for search in (lambda *a: c_search(roots, *a), py_search):
        code, piece, asked = search(b, True, lambda s: False, 0.0)
        assert (code, piece, len(asked)) == (ROOT_EVENT_UNSETTLED, None, integrate.EVENT_MAX_PIECES)


def test_tol_stops_the_split_where_g_is_within_rounding(roots):
    """The same contradiction, but the coefficients span no more than tol: the first piece is resolved at once
    (one question), no event."""
    b = [-1e-17, 1e-17] * 4
    for search in (lambda *a: c_search(roots, *a), py_search):
        assert search(b, True, lambda s: False, 4e-17)[:2] == (0, None)
        assert len(search(b, True, lambda s: False, 4e-17)[2]) == 1


def test_a_real_crossing_is_found_whatever_tol():
    """g = 1 - 2s on [0, 1] (zero at 1/2): monotone, found on the first piece, with any tol."""
    b = [1.0 - 2.0 * k / 7 for k in range(8)]
    for tol in (0.0, 1e-16, 1e-3, 10.0):
        assert py_search(b, True, polynomial_beyond(b, True), tol)[1] == (0.0, 1.0, False)


def test_graze_searches_stay_far_below_the_bound(monkeypatch):
    """A touch of the contact from inside within rounding (x_max 3e-16 past the contact, rtol 1e-12): the search
    examined 964,111 pieces in one step before tol; now every search of the run examines at most a few dozen, two
    orders below EVENT_MAX_PIECES. The graze sweep's depths 1e-1 ... 1e-15 at four tolerances measured at most 17."""
    from vibrofmu.analyses.campaigns import graze_reference, graze_scene, run_plant
    from vibromodel.plant import Plant, Settings

    counts = []
    original = integrate.bernstein_search

    def counting(b, positive, beyond, tol):
        n = len(counts)
        counts.append(0)

        def asked(s):
            counts[n] += 1
            return beyond(s)
        return original(b, positive, asked, tol)

    monkeypatch.setattr(integrate, "bernstein_search", counting)
    for depth in (10.0 ** -15.5, 1e-12, 1e-6):
        times, _, error = run_plant(Plant(graze_scene(graze_reference(depth)), Settings(rtol=1e-12)), 20.0, 0.5)
        assert error is None and math.isclose(times[-1], 20.0)
    assert counts and max(counts) <= integrate.EVENT_MAX_PIECES // 100
