/*
 * pyfloat.c -- Python's float semantics (pyfloat.h).
 * Build: no FMA contraction, never -ffast-math (harness/vibrofmu/fmus/kernel.py holds the command).
 */
#include "pyfloat.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

/* iv ** iw as Python's float ** gives it (float_pow), for the exponents of DOP853's step control (-1/8, 1/9, the PI
 * controller's) of error ratios iv >= 0 or NaN, and the error estimate's (core/estimate.c): C's pow (the libm call
 * CPython's float_pow makes), with Python's rules where C's differ: x ** 0 is 1 even for a NaN x; a NaN base is
 * returned as it is; and the faults where Python raises: 0 ** negative (ZeroDivisionError) and an infinite result
 * from finite operands (OverflowError; found from the value, not from errno); a negative base to a non-integer
 * power, a complex number in Python, is FAULT_COMPLEX (the caller hands the case back to Python). The step
 * control's calls (iw != 0, iv >= 0 or NaN) meet none of the added rules: their bits are the former ones. */
double vk_python_pow(double iv, double iw, int *fault)
{
    if (iw == 0.0) return 1.0;
    if (isnan(iv)) return iv;
    if (iv == 0.0 && iw < 0.0 && isfinite(iw)) { /* 0 ** -inf is inf */
        *fault = FAULT_ZERO_DIVISION;
        return 0.0;
    }
    if (iv < 0.0 && isfinite(iv) && isfinite(iw) && iw != floor(iw)) { /* a NaN iw gives NaN */
        *fault = FAULT_COMPLEX;
        return NAN;
    }
    const double ix = pow(iv, iw);
    if (isinf(ix) && isfinite(iv) && isfinite(iw)) *fault = FAULT_OVERFLOW;
    return ix;
}

/* math.hypot(*values): CPython's math_hypot and vector_norm (Modules/mathmodule.c, 3.11), n <= VK_PYTHON_HYPOT_MAX.
 * Kept for bit identity: libm's hypot and a plain norm differ from it in the last bit (tests/core/test_pyfloat.py). */
double vk_python_hypot(const double *values, int n)
{
    const double T27 = 134217729.0;  /* ldexp(1.0, 27) + 1.0 */
    double vec[VK_PYTHON_HYPOT_MAX];
    double max = 0.0, scale, csum = 1.0, oldcsum, frac1 = 0.0, frac2 = 0.0, frac3 = 0.0, t, hi, lo, h, x;
    int found_nan = 0, max_e, i;
    for (i = 0; i < n; i++) {
        vec[i] = fabs(values[i]);
        found_nan |= isnan(vec[i]);
        if (vec[i] > max) max = vec[i];
    }
    if (isinf(max)) return max;
    if (found_nan) return NAN;
    if (max == 0.0 || n <= 1) return max;
    frexp(max, &max_e);
    if (max_e >= -1023) {
        scale = ldexp(1.0, -max_e);
        for (i = 0; i < n; i++) {
            x = vec[i] * scale;  /* lossless scaling */
            t = x * T27;         /* Veltkamp-Dekker split */
            hi = t - (t - x);
            lo = x - hi;
            x = hi * hi;
            oldcsum = csum;
            csum += x;
            frac1 += (oldcsum - csum) + x;
            x = 2.0 * hi * lo;
            oldcsum = csum;
            csum += x;
            frac2 += (oldcsum - csum) + x;
            frac3 += lo * lo;
        }
        h = sqrt(csum - 1.0 + (frac1 + frac2 + frac3));
        x = h;
        t = x * T27;
        hi = t - (t - x);
        lo = x - hi;
        x = -hi * hi;
        oldcsum = csum;
        csum += x;
        frac1 += (oldcsum - csum) + x;
        x = -2.0 * hi * lo;
        oldcsum = csum;
        csum += x;
        frac2 += (oldcsum - csum) + x;
        x = -lo * lo;
        oldcsum = csum;
        csum += x;
        frac3 += (oldcsum - csum) + x;
        x = csum - 1.0 + (frac1 + frac2 + frac3);
        return (h + x / (2.0 * h)) / scale;
    }
    /* subnormal max: ldexp(1.0, -max_e) would overflow, divide by max instead */
    for (i = 0; i < n; i++) {
        x = vec[i] / max;
        x = x * x;
        oldcsum = csum;
        csum += x;
        frac1 += (oldcsum - csum) + x;
    }
    return max * sqrt(csum - 1.0 + frac1);
}


/* f"{x:.{precision}g}": C's %.*g, but a NaN prints "nan" whatever its sign bit. */
const char *g_number_text(number_text buf, double x, int precision)
{
    if (isnan(x)) return "nan";
    snprintf(buf, sizeof(number_text), "%.*g", precision, x);
    return buf;
}

/* The text of x in messages: the first of %.15g, %.16g, %.17g that reads back as x (so the message holds x
 * exactly); "nan" for every NaN. Plain C formatting, not Python's repr: a message names the value, not its Python
 * spelling ("2" where Python writes 2.0). */
const char *exact_number_text(number_text buf, double x)
{
    if (isnan(x)) return "nan";
    for (int precision = 15; precision <= 17; precision++) {
        snprintf(buf, sizeof(number_text), "%.*g", precision, x);
        if (strtod(buf, NULL) == x) break;
    }
    return buf;
}


void py_fault_text(int fault, char *buf, unsigned long size)
{
    switch (fault) {
    case FAULT_ZERO_DIVISION:
        snprintf(buf, size, "ZeroDivisionError: float division by zero");
        break;
    case FAULT_MATH_DOMAIN:
        snprintf(buf, size, "ValueError: math domain error");
        break;
    case FAULT_COMPLEX:
        snprintf(buf, size, "complex result: a negative number to a fractional power");
        break;
    default:  /* FAULT_OVERFLOW */
        snprintf(buf, size, "OverflowError: result out of range");
        break;
    }
}
