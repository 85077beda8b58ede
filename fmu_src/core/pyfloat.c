/*
 * pyfloat.c -- Python's float semantics (pyfloat.h).
 * Build: no FMA contraction, never -ffast-math (harness/vibrofmu/fmus/kernel.py holds the command).
 */
#include "pyfloat.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* iv ** iw as Python's float ** gives it, for the exponents used here (-1/8, 1/9) of error ratios iv >= 0 or NaN:
 * C's pow (the libm call CPython's float_pow makes for them), a NaN base returned as it is, and the faults where
 * Python raises: 0 ** negative (ZeroDivisionError) and an infinite result from a finite base (OverflowError;
 * found from the value, not from errno). */
double py_pow(double iv, double iw, int *fault)
{
    if (isnan(iv)) return iv;
    if (iv == 0.0 && iw < 0.0) {
        *fault = FAULT_ZERO_DIVISION;
        return 0.0;
    }
    const double ix = pow(iv, iw);
    if (isinf(ix) && isfinite(iv)) *fault = FAULT_OVERFLOW;
    return ix;
}

/* math.hypot(*values): CPython's math_hypot and vector_norm (Modules/mathmodule.c, 3.11), n <= PY_HYPOT_MAX. */
double py_hypot(const double *values, int n)
{
    const double T27 = 134217729.0;  /* ldexp(1.0, 27) + 1.0 */
    double vec[PY_HYPOT_MAX];
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
const char *py_g(number_text buf, double x, int precision)
{
    if (isnan(x)) return "nan";
    snprintf(buf, sizeof(number_text), "%.*g", precision, x);
    return buf;
}

/* The `precision` significant digits of ax > 0 rounded to nearest, or with `up` the next such decimal above
 * them, and their decimal exponent; true if they read back as ax. */
static int decimal_digits(double ax, int precision, int up, char *digits, int *exponent)
{
    char text[40];
    int n = 0;
    snprintf(text, sizeof text, "%.*e", precision - 1, ax);
    for (const char *c = text; *c != 'e'; c++)
        if (*c != '.') digits[n++] = *c;
    digits[n] = '\0';
    *exponent = atoi(strchr(text, 'e') + 1);
    if (up) {
        int i = n - 1;
        for (; i >= 0 && digits[i] == '9'; i--) digits[i] = '0';
        if (i >= 0) {
            digits[i] += 1;
        } else {  /* 99..9 -> 100..0 */
            digits[0] = '1';
            *exponent += 1;
        }
    }
    snprintf(text, sizeof text, "%c.%se%d", digits[0], digits + 1, *exponent);
    return strtod(text, NULL) == ax;
}

/* repr(x) (float_repr_style 'short'): the fewest significant digits that read back as x, of those the
 * nearest to x (the nearest decimal, or for a power of two, whose rounding interval reaches twice as far
 * above as below, possibly the next one above); positional notation when the decimal point falls within
 * -4 < point <= 16 of the digits' start, else d.ddde+XX. */
const char *py_repr(number_text buf, double x)
{
    char digits[20], *out = buf;
    int n, precision, exponent, point, i;
    if (isnan(x)) return "nan";
    if (isinf(x)) return x > 0 ? "inf" : "-inf";
    if (x == 0.0) return signbit(x) ? "-0.0" : "0.0";
    for (precision = 1; precision < 17; precision++) {
        if (decimal_digits(fabs(x), precision, 0, digits, &exponent)) break;
        if (decimal_digits(fabs(x), precision, 1, digits, &exponent)) break;
    }
    if (precision == 17) decimal_digits(fabs(x), precision, 0, digits, &exponent);
    n = (int)strlen(digits);
    point = exponent + 1;
    if (x < 0) *out++ = '-';
    if (point <= -4 || point > 16) {
        *out++ = digits[0];
        if (n > 1) *out++ = '.';
        for (i = 1; i < n; i++) *out++ = digits[i];
        snprintf(out, sizeof(number_text) - (size_t)(out - buf), "e%c%02d", exponent < 0 ? '-' : '+', abs(exponent));
        return buf;
    }
    if (point <= 0) {
        *out++ = '0';
        *out++ = '.';
        for (i = 0; i < -point; i++) *out++ = '0';
        for (i = 0; i < n; i++) *out++ = digits[i];
    } else {
        for (i = 0; i < point || i < n; i++) {
            if (i == point) *out++ = '.';
            *out++ = i < n ? digits[i] : '0';
        }
        if (point >= n) {
            *out++ = '.';
            *out++ = '0';
        }
    }
    *out = '\0';
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
    default:  /* FAULT_OVERFLOW: PyErr_SetFromErrno(OverflowError) raises OverflowError(ERANGE, strerror(ERANGE)) */
        snprintf(buf, size, "OverflowError: %d %s", ERANGE, strerror(ERANGE));
        break;
    }
}
