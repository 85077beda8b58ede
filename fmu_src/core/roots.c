/*
 * roots.c -- scipy.optimize.brentq (roots.h).
 */
#include "roots.h"

#include <math.h>

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
