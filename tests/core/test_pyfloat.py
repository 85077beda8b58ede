"""core/pyfloat.c's vk_python_pow: Python's float ** for the kernel's exponents (-1/8, 1/9) of error ratios >= 0 or
NaN, and for the error estimate's (core/estimate.c: 0.125, 4, 5, 8, 9, of any sign of base), the same bits and,
where Python raises or gives a complex number, the matching fault (found from the value, without errno); its
vk_python_hypot: math.hypot, the same bits, which neither C's hypot nor a plain norm gives."""
import ctypes
import ctypes.util
import math
import random
import struct

import pytest

from vibrofmu.fmus import kernel

FAULTS = {0: None, 1: ZeroDivisionError, 2: ValueError, 3: OverflowError, 4: complex}  # pyfloat.h's FAULT_* order


@pytest.fixture(scope="module")
def vk_python_pow():
    function = kernel.kernel_library().vk_python_pow
    function.restype, function.argtypes = ctypes.c_double, [ctypes.c_double, ctypes.c_double,
                                                              ctypes.POINTER(ctypes.c_int)]
    return function


def python_pow(iv, iw):
    try:
        value = iv ** iw
    except ArithmeticError as error:
        return None, type(error)
    return (None, complex) if isinstance(value, complex) else (value, None)


@pytest.mark.parametrize("iw", [-1.0 / 8.0, 1.0 / 9.0])
@pytest.mark.parametrize("iv", [0.0, 5e-324, 2.2250738585072014e-308, 1e-300, 1e-15, 0.3, 1.0, 7.5, 1e13, 1e300,
                                1.7976931348623157e308, math.inf, math.nan])
def test_py_pow_is_pythons_float_pow(vk_python_pow, iv, iw):
    fault = ctypes.c_int(0)
    value = vk_python_pow(iv, iw, ctypes.byref(fault))
    expected, raised = python_pow(iv, iw)
    assert FAULTS[fault.value] is raised
    if raised is None:
        # bit identity is free: both are the one libm pow call on the same arguments (NaN: the base itself)
        assert struct.pack("<d", value) == struct.pack("<d", expected)


@pytest.mark.parametrize("iw", [0.0, 0.125, 4.0, 5.0, 8.0, 9.0, -1.0, 0.5, math.inf, -math.inf, math.nan])
@pytest.mark.parametrize("iv", [0.0, -0.0, 1e-300, 0.7, 1.0, -1.0, -2.5, 1e40, -1e40, 1e300, math.inf, -math.inf,
                                math.nan])
def test_py_pow_keeps_pythons_rules_for_the_estimates_exponents(vk_python_pow, iv, iw):
    """The rules core/estimate.c needs beyond the step control's (estimate.c called its own copy before): x ** 0 is
    1 even for a NaN x, a negative base to a non-integer power is Python's complex result (FAULT_COMPLEX: the
    estimate hands the scene back to Python), an infinite exponent is no overflow; the same bits elsewhere."""
    fault = ctypes.c_int(0)
    value = vk_python_pow(iv, iw, ctypes.byref(fault))
    expected, raised = python_pow(iv, iw)
    assert FAULTS[fault.value] is raised, (iv, iw, value)
    if raised is None:
        assert struct.pack("<d", value) == struct.pack("<d", expected) or (math.isnan(value) and math.isnan(expected))


def test_the_hypot_port_is_math_hypot_where_cs_hypot_and_a_plain_norm_are_not():
    """vk_python_hypot (a port of CPython 3.11's vector_norm) is math.hypot bit for bit on random vectors of the
    sizes the solvers norm (2: the plant's DOP853 initial step and RK4's stability check; 11: the closed loop's
    initial step). sqrt of the summed squares and, for 2 values, libm's hypot differ from math.hypot in the last
    bit on some of them: the C twin's initial step, and with it every later step, would then differ from Python's,
    so bit identity needs the port (seed 1: 318 and 581 of 2000 plain norms differ, 18 of 2000 libm hypots)."""
    function = kernel.kernel_library().vk_python_hypot
    function.restype, function.argtypes = ctypes.c_double, [ctypes.POINTER(ctypes.c_double), ctypes.c_int]
    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    libm.hypot.restype, libm.hypot.argtypes = ctypes.c_double, [ctypes.c_double, ctypes.c_double]
    rng = random.Random(1)
    for n in (2, 11):
        plain_differs = libm_differs = 0
        for _ in range(2000):
            values = [rng.uniform(-1.0, 1.0) * 10.0 ** rng.uniform(-3.0, 3.0) for _ in range(n)]
            expected = math.hypot(*values)
            assert struct.pack("<d", function((ctypes.c_double * n)(*values), n)) == struct.pack("<d", expected)
            total = 0.0
            for value in values:
                total += value * value
            plain_differs += math.sqrt(total) != expected
            libm_differs += n == 2 and libm.hypot(*values) != expected
        assert plain_differs > 0
        assert n != 2 or libm_differs > 0
