/*
 * roots.h -- scipy.optimize.brentq(f, xa, xb, xtol=1e-15, rtol=1e-15) (maxiter 100): scipy/optimize/Zeros/brentq.c
 * (Charles Harris) line for line, the root finder of vibromodel/integrate.py's event location.
 */
#ifndef VIBRO_ROOTS_H
#define VIBRO_ROOTS_H

/* f(x) into *f; returns 0, or a nonzero code that brentq returns at once */
typedef int (*RootFunction)(void *context, double x, double *f);

enum {
    ROOT_SIGN_ERROR = -1,     /* ValueError: f(a) and f(b) must have different signs */
    ROOT_NO_CONVERGENCE = -2  /* RuntimeError: Failed to converge after *iterations iterations. */
};

/* 0 and the root, or ROOT_SIGN_ERROR / ROOT_NO_CONVERGENCE, or the code function returned */
int brentq(RootFunction function, void *context, double xa, double xb, double *root, int *iterations);

#endif
