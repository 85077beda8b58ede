/*
 * roots.h -- the event search of every solver: scipy.optimize.brentq(f, xa, xb, xtol=1e-15, rtol=1e-15) (maxiter
 * 100), scipy/optimize/Zeros/brentq.c (Charles Harris) line for line, the root finder of vibromodel/integrate.py's
 * event location; and the one Bernstein-bisection search (integrate.bernstein_search) that brackets the first zero
 * of an event on a step's interpolant (DOP853's dense output, a fixed step's cubic Hermite): docs/events.md.
 */
#ifndef VIBRO_ROOTS_H
#define VIBRO_ROOTS_H

/* f(x) into *f; returns 0, or a nonzero code that brentq returns at once */
typedef int (*RootFunction)(void *context, double x, double *f);

enum {
    ROOT_SIGN_ERROR = -1,     /* ValueError: f(a) and f(b) must have different signs */
    ROOT_NO_CONVERGENCE = -2, /* RuntimeError: Failed to converge after *iterations iterations. */
    ROOT_EVENT_UNSETTLED = -3 /* bernstein_search: RuntimeError: ROOT_EVENT_UNSETTLED_TEXT */
};

/* 0 and the root, or ROOT_SIGN_ERROR / ROOT_NO_CONVERGENCE, or the code function returned */
int brentq(RootFunction function, void *context, double xa, double xb, double *root, int *iterations);

/* Bernstein coefficients b[0..degree] (degree <= ROOT_MAX_DEGREE) of a polynomial on an interval: whether they rise
   or fall strictly (then the polynomial is monotone there: integrate._monotone); their halves by de Casteljau at the
   middle (integrate._split). */
#define ROOT_MAX_DEGREE 7
#define ROOT_EVENT_MAX_DEPTH 40  /* integrate.EVENT_MAX_DEPTH: pieces of 2^-40 of a step are not split */
#define ROOT_EVENT_ROUNDING 0x1p-46  /* integrate.EVENT_ROUNDING: tol per unit of the magnitudes b rounds against */
#define ROOT_EVENT_MAX_PIECES 4096  /* integrate.EVENT_MAX_PIECES: pieces one search examines at most */
#define ROOT_EVENT_UNSETTLED_TEXT "event search gave up after 4096 pieces of the step: the Bernstein hull of the " \
    "event function and the dense output disagree (the step's values exceed the arithmetic)"
int bernstein_monotone(const double *b, int degree);
void bernstein_split(const double *b, int degree, double *left, double *right);

/* Whether the event function at the step fraction s is beyond the event (past it, seen from the side the step
   starts on) into *beyond; returns 0, or a nonzero code that bernstein_search returns at once */
typedef int (*BeyondFunction)(void *context, double s, int *beyond);

/* integrate.bernstein_search: the first piece [*s_a, *s_b] of [0, 1] (left half first) whose end s_b is beyond the
   event and on which g is monotone (or which is 2^-ROOT_EVENT_MAX_DEPTH long, or on which b spans no more than tol:
   the rounding of b and of g's evaluation, ROOT_EVENT_ROUNDING times their magnitudes), g given by its Bernstein coefficients
   b[0..degree] on [0, 1]; pieces whose hull lies on the start side (positive: all > 0; else none > 0) are skipped.
   *found = 0 if there is none; else *found = 1 and *at_start = whether s_a is beyond already (then the event is at
   s_a, else one zero lies in the piece). 0, ROOT_EVENT_UNSETTLED once ROOT_EVENT_MAX_PIECES pieces were examined
   (g evaluated at their ends) in vain, or the code `beyond` returned. */
int bernstein_search(const double *b, int degree, int positive, double tol, BeyondFunction beyond, void *context, int *found,
                     double *s_a, double *s_b, int *at_start);

#endif
