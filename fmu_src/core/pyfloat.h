/*
 * pyfloat.h -- Python's float semantics in C, for the compiled twins of vibromodel (model.c, dop853.c, plant.c):
 * the operations whose result or error differs from C's (min/max with NaN, division by zero, math.cos of an
 * infinity, float ** with its OverflowError, math.hypot), and the text of numbers in messages.
 * A function that can raise in Python sets *fault (left unchanged otherwise).
 */
#ifndef VIBRO_PYFLOAT_H
#define VIBRO_PYFLOAT_H

/* What a Python operation raised (nothing: FAULT_NONE). */
enum { FAULT_NONE = 0, FAULT_ZERO_DIVISION, FAULT_MATH_DOMAIN, FAULT_OVERFLOW, FAULT_COMPLEX };

#define VK_PYTHON_HYPOT_MAX 32

/* The small ones are inline (they sit in the solvers' inner loops). */
#include <math.h>

/* Python's min(a, b) and max(a, b): a unless b compares smaller (larger). */
static inline double py_min(double a, double b) { return b < a ? b : a; }
static inline double py_max(double a, double b) { return b > a ? b : a; }
/* a / b (float_div): FAULT_ZERO_DIVISION for b == 0 */
static inline double py_div(double a, double b, int *fault)
{
    if (b == 0.0) {
        *fault = FAULT_ZERO_DIVISION;
        return 0.0;
    }
    return a / b;
}
/* math.cos, math.sin (CPython's math_1): a NaN from a non-NaN argument (an infinity) is FAULT_MATH_DOMAIN */
static inline double py_cos(double x, int *fault)
{
    double r = cos(x);
    if (isnan(r) && !isnan(x)) *fault = FAULT_MATH_DOMAIN;
    return r;
}
static inline double py_sin(double x, int *fault)
{
    double r = sin(x);
    if (isnan(r) && !isnan(x)) *fault = FAULT_MATH_DOMAIN;
    return r;
}
/* q * q, FAULT_OVERFLOW where it overflows from a finite q, as q ** 2 raises (integrate._square) */
static inline double py_square(double q, int *fault)
{
    double square = q * q;
    if (isinf(square) && !isinf(q)) *fault = FAULT_OVERFLOW;
    return square;
}
/* iv ** iw (Python's float **): FAULT_ZERO_DIVISION, FAULT_OVERFLOW, FAULT_COMPLEX (a negative iv to a non-integer
   iw: Python's result is complex); x ** 0 is 1 (pyfloat.c) */
double vk_python_pow(double iv, double iw, int *fault);
/* math.hypot(*values[0..n-1]), bit for bit: a port of CPython's vector_norm, kept because neither libm's
   hypot nor sqrt of the summed squares gives math.hypot's bits (tests/core/test_pyfloat.py), and DOP853's initial
   step and RK4's stability check norm with it */
double vk_python_hypot(const double *values, int n);

/* Text of numbers in messages */
typedef char number_text[40];
const char *g_number_text(number_text buf, double x, int precision);  /* f"{x:.{precision}g}" */
/* x exactly (the first of %.15g .. %.17g that reads back as x), in C's spelling */
const char *exact_number_text(number_text buf, double x);
/* "<exception type>: <text>" of the exception a fault raises in Python (the type is Python's; the text says what
   happened in the C twin's words) */
void py_fault_text(int fault, char *buf, unsigned long size);

#endif
