/* oafm_eval.c -- see oafm_eval.h for the formulas and the recurrences. */
#include <math.h>

#include "oafm_eval.h"

#define MAX_ITEMS 256

/* Powers 0..top of exp(i b s) in re/im by recurrence: F^n = F^(n-1) F (angle addition). */
static void freq_powers(double b, double s, int64_t top, double *re, double *im)
{
    double c = cos(b * s), sn = sin(b * s);
    re[0] = 1.0;
    im[0] = 0.0;
    for (int64_t n = 1; n <= top; n++) {
        re[n] = re[n - 1] * c - im[n - 1] * sn;
        im[n] = re[n - 1] * sn + im[n - 1] * c;
    }
}

/* Powers -top..top of exp(-d s) at index n + top, by recurrence from E and 1/E = exp(d s). */
static void decay_powers(double d, double s, int64_t top, double *out)
{
    double e = exp(-d * s), inverse = top > 0 ? exp(d * s) : 1.0;
    double *zero = out + top;
    zero[0] = 1.0;
    for (int64_t n = 1; n <= top; n++) {
        zero[n] = zero[n - 1] * e;
        zero[-n] = zero[-n + 1] * inverse;
    }
}

static void piece_state(const OePiece *P, double s, double *xva)
{
    double fre[OE_BASES][OE_POWERS], fim[OE_BASES][OE_POWERS], dp[OE_BASES][2 * OE_POWERS - 1];
    double wre[MAX_ITEMS], wim[MAX_ITEMS], D[MAX_ITEMS];
    for (int64_t j = 0; j < P->n_freq_bases; j++) freq_powers(P->freq_base[j], s, P->freq_top[j], fre[j], fim[j]);
    for (int64_t j = 0; j < P->n_decay_bases; j++) decay_powers(P->decay_base[j], s, P->decay_top[j], dp[j]);
    for (int64_t w = 0; w < P->n_freqs; w++) {  /* W_w = prod_j F_j^n_j */
        const int64_t *n = P->freq_power + w * OE_BASES;
        double re = 1.0, im = 0.0;
        for (int64_t j = 0; j < P->n_freq_bases; j++) {
            if (n[j] == 0) continue;
            int64_t k = n[j] > 0 ? n[j] : -n[j];
            double br = fre[j][k], bi = n[j] > 0 ? fim[j][k] : -fim[j][k];
            double r = re * br - im * bi;
            im = re * bi + im * br;
            re = r;
        }
        wre[w] = re;
        wim[w] = im;
    }
    for (int64_t g = 0; g < P->n_decays; g++) {  /* D_g = prod_j E_j^n_j */
        const int64_t *n = P->decay_power + g * OE_BASES;
        double value = 1.0;
        for (int64_t j = 0; j < P->n_decay_bases; j++)
            if (n[j] != 0) value *= dp[j][n[j] + P->decay_top[j]];
        D[g] = value;
    }
    double x = 0.0, v = 0.0, a = 0.0;
    int64_t k = 0;
    for (int64_t g = 0; g < P->n_groups; g++) {  /* Re sum c W over the group, times its D (and s) */
        double gx = 0.0, gv = 0.0, ga = 0.0;
        for (; k < P->group_end[g]; k++) {
            const double *c = P->term_coefficient + 6 * k;
            double re = wre[P->term_freq[k]], im = wim[P->term_freq[k]];
            gx += c[0] * re - c[1] * im;
            gv += c[2] * re - c[3] * im;
            ga += c[4] * re - c[5] * im;
        }
        double f = D[P->group_decay[g]];
        if (P->group_secular[g]) f *= s;
        x += f * gx;
        v += f * gv;
        a += f * ga;
    }
    xva[0] = x;
    xva[1] = v;
    xva[2] = a;
}

void oe_state(const OeSolution *S, double tau, double *xva)
{
    int64_t i = 0;
    while (i + 1 < S->n_pieces && S->pieces[i + 1].start <= tau) i++;  /* oafm.AnalyticSolution._index */
    piece_state(&S->pieces[i], tau - S->pieces[i].start, xva);
}
