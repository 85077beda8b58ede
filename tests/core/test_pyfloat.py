"""core/pyfloat.c's py_pow: Python's float ** for the kernel's exponents (-1/8, 1/9) of error ratios >= 0 or NaN,
the same bits and, where Python raises, the matching fault (found from the value, without errno)."""
import ctypes
import math
import struct

import pytest

from vibrofmu.fmus import kernel

FAULTS = {0: None, 1: ZeroDivisionError, 2: ValueError, 3: OverflowError}  # pyfloat.h's FAULT_* order


@pytest.fixture(scope="module")
def py_pow():
    function = kernel.kernel_library().py_pow
    function.restype, function.argtypes = ctypes.c_double, [ctypes.c_double, ctypes.c_double,
                                                              ctypes.POINTER(ctypes.c_int)]
    return function


def python_pow(iv, iw):
    try:
        return iv ** iw, None
    except ArithmeticError as error:
        return None, type(error)


@pytest.mark.parametrize("iw", [-1.0 / 8.0, 1.0 / 9.0])
@pytest.mark.parametrize("iv", [0.0, 5e-324, 2.2250738585072014e-308, 1e-300, 1e-15, 0.3, 1.0, 7.5, 1e13, 1e300,
                                1.7976931348623157e308, math.inf, math.nan])
def test_py_pow_is_pythons_float_pow(py_pow, iv, iw):
    fault = ctypes.c_int(0)
    value = py_pow(iv, iw, ctypes.byref(fault))
    expected, raised = python_pow(iv, iw)
    assert FAULTS[fault.value] is raised
    if raised is None:
        # bit identity is free: both are the one libm pow call on the same arguments (NaN: the base itself)
        assert struct.pack("<d", value) == struct.pack("<d", expected)
