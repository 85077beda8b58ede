/*
 * roots.c -- scipy.optimize.brentq and the Bernstein-bisection event search (roots.h).
 */
#include "roots.h"

#include <math.h>
#include <string.h>

#include "pyfloat.h"

/* brentq(f, xa, xb, xtol=ROOT_XTOL, rtol=ROOT_RTOL, maxiter=ROOT_MAXITER) */
#define ROOT_XTOL 1e-15
#define ROOT_RTOL 1e-15
#define ROOT_MAXITER 100

#define MIN(a, b) ((a) < (b) ? (a) : (b))
#define CALL_F(x, f) do { int code_ = function(context, (x), &(f)); if (code_) return code_; } while (0)

/* scipy.optimize.brentq(f, xa, xb, xtol=ROOT_XTOL, rtol=ROOT_RTOL): scipy/optimize/Zeros/brentq.c (Charles
 * Harris) line for line, with _zerosmodule.c's errors: a sign error and non-convergence raise. */
int brentq(RootFunction function, void *context, double xa, double xb, double *root, int *iterations)
{
    const double xtol = ROOT_XTOL, rtol = ROOT_RTOL;
    *iterations = 0;
    double xpre = xa, xcur = xb;
    double xblk = 0., fpre, fcur, fblk = 0., spre = 0., scur = 0., sbis;
    double delta;  /* the tolerance is 2*delta */
    double stry, dpre, dblk;
    int i;

    CALL_F(xpre, fpre);
    CALL_F(xcur, fcur);
    if (fpre * fcur > 0)
        return ROOT_SIGN_ERROR;
    if (fpre == 0) {
        *root = xpre;
        return 0;
    }
    if (fcur == 0) {
        *root = xcur;
        return 0;
    }
    for (i = 0; i < ROOT_MAXITER; i++) {
        if (fpre != 0 && fcur != 0 && (signbit(fpre) != signbit(fcur))) {
            xblk = xpre;
            fblk = fpre;
            spre = scur = xcur - xpre;
        }
        if (fabs(fblk) < fabs(fcur)) {
            xpre = xcur;
            xcur = xblk;
            xblk = xpre;

            fpre = fcur;
            fcur = fblk;
            fblk = fpre;
        }

        delta = (xtol + rtol * fabs(xcur)) / 2;
        sbis = (xblk - xcur) / 2;
        if (fcur == 0 || fabs(sbis) < delta) {
            *root = xcur;
            return 0;
        }

        if (fabs(spre) > delta && fabs(fcur) < fabs(fpre)) {
            if (xpre == xblk) {
                /* interpolate */
                stry = -fcur * (xcur - xpre) / (fcur - fpre);
            } else {
                /* extrapolate */
                dpre = (fpre - fcur) / (xpre - xcur);
                dblk = (fblk - fcur) / (xblk - xcur);
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre));
            }
            if (2 * fabs(stry) < MIN(fabs(spre), 3 * fabs(sbis) - delta)) {
                /* good short step */
                spre = scur;
                scur = stry;
            } else {
                /* bisect */
                spre = sbis;
                scur = sbis;
            }
        } else {
            /* bisect */
            spre = sbis;
            scur = sbis;
        }

        xpre = xcur;
        fpre = fcur;
        if (fabs(scur) > delta) {
            xcur += scur;
        } else {
            xcur += (sbis > 0 ? delta : -delta);
        }

        CALL_F(xcur, fcur);
    }
    *iterations = i;
    return ROOT_NO_CONVERGENCE;
}

#undef CALL_F
#undef MIN

int bernstein_monotone(const double *b, int degree)
{
    int rising = 1, falling = 1;
    for (int k = 0; k < degree; k++) {
        rising = rising && b[k + 1] > b[k];
        falling = falling && b[k + 1] < b[k];
    }
    return rising || falling;
}

void bernstein_split(const double *b_in, int degree, double *left, double *right)
{
    double b[ROOT_MAX_DEGREE + 1];
    memcpy(b, b_in, sizeof(double) * (size_t)(degree + 1));
    left[0] = b[0];
    right[degree] = b[degree];
    for (int r = 1; r <= degree; r++) {
        for (int k = 0; k <= degree - r; k++) b[k] = 0.5 * (b[k] + b[k + 1]);
        left[r] = b[0];
        right[degree - r] = b[degree - r];
    }
}

typedef struct {
    double s_a, s_b;
    int depth;
    double b[ROOT_MAX_DEGREE + 1];
} Piece;

int bernstein_search(const double *b, int degree, int positive, double tol, BeyondFunction beyond, void *context, int *found,
                     double *s_a, double *s_b, int *at_start)
{
    Piece stack[ROOT_EVENT_MAX_DEPTH + 2];
    int top = 1, code, past, examined = 0;
    *found = 0;
    stack[0].s_a = 0.0;
    stack[0].s_b = 1.0;
    stack[0].depth = 0;
    memcpy(stack[0].b, b, sizeof(double) * (size_t)(degree + 1));
    while (top > 0) {
        Piece piece = stack[--top];
        double lo = piece.b[0], hi = piece.b[0];
        for (int k = 1; k <= degree; k++) {  /* min(b), max(b): left to right */
            lo = py_min(lo, piece.b[k]);
            hi = py_max(hi, piece.b[k]);
        }
        if (positive ? lo > 0.0 : !(hi > 0.0)) continue;  /* the hull of g on the piece is on the start side */
        if (examined++ == ROOT_EVENT_MAX_PIECES) return ROOT_EVENT_UNSETTLED;
        int resolved = piece.depth >= ROOT_EVENT_MAX_DEPTH || hi - lo <= tol;
        code = beyond(context, piece.s_b, &past);
        if (code) return code;
        if (past && (resolved || bernstein_monotone(piece.b, degree))) {
            code = beyond(context, piece.s_a, &past);  /* a rounding of the hull's verdict on the piece before? */
            if (code) return code;
            *found = 1;
            *at_start = past;
            *s_a = piece.s_a;
            *s_b = piece.s_b;
            return 0;
        }
        if (!resolved) {
            double middle = 0.5 * (piece.s_a + piece.s_b);
            Piece *right = &stack[top++], *left = &stack[top++];
            bernstein_split(piece.b, degree, left->b, right->b);
            right->s_a = middle;
            right->s_b = piece.s_b;
            left->s_a = piece.s_a;
            left->s_b = middle;
            right->depth = left->depth = piece.depth + 1;
        }
    }
    return 0;
}
