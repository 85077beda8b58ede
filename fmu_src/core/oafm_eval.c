/* oafm_eval.c -- see oafm_eval.h for the formulas and the recurrences. */
#define _GNU_SOURCE  /* sincos */
#include <math.h>
#include <string.h>

#include "oafm_eval.h"

typedef double v2 __attribute__((vector_size(16)));  /* (x, x') */

/* F_j(s) into (fre, fim), E_j(s) and 1/E_j(s) into (e, inverse), evaluated directly. */
static void bases(const OePiece *P, double s, double *fre, double *fim, double *e, double *inverse)
{
    for (int64_t j = 0; j < P->n_freq_bases; j++) sincos(P->freq_base[j] * s, &fim[j], &fre[j]);
    for (int64_t j = 0; j < P->n_decay_bases; j++) {
        e[j] = P->decay_top[j] > 0 ? exp(-P->decay_base[j] * s) : 1.0;
        inverse[j] = P->decay_bottom[j] > 0 ? exp(P->decay_base[j] * s) : 1.0;
    }
}

/* Every item at local time s into (wre, wim) and D: the bases directly, then their powers and the chain rows;
   base_cos != NULL: cos(b_base s) as computed (sincos) into it. */
static void items(const OePiece *P, double s, double *wre, double *wim, double *D, int64_t base, double *base_cos)
{
    double fre[OE_BASES], fim[OE_BASES], e[OE_BASES], inverse[OE_BASES];
    bases(P, s, fre, fim, e, inverse);
    for (int64_t j = 0; j < P->n_freq_bases; j++) {  /* F_j^n = F_j^(n-1) F_j: angle addition */
        double c = fre[j], sn = fim[j], *re = wre + P->freq_zero[j], *im = wim + P->freq_zero[j];
        if (j == base && base_cos != NULL) *base_cos = c;
        re[0] = 1.0;
        im[0] = 0.0;
        for (int64_t n = 1; n <= P->freq_top[j]; n++) {
            re[n] = re[n - 1] * c - im[n - 1] * sn;
            im[n] = re[n - 1] * sn + im[n - 1] * c;
        }
    }
    for (int64_t j = 0; j < P->n_decay_bases; j++) {  /* E_j^n, n = -bottom .. top */
        double *zero = D + P->decay_zero[j];
        zero[0] = 1.0;
        for (int64_t n = 1; n <= P->decay_top[j]; n++) zero[n] = zero[n - 1] * e[j];
        for (int64_t n = 1; n <= P->decay_bottom[j]; n++) zero[-n] = zero[-n + 1] * inverse[j];
    }
    for (int64_t r = 0, w = P->n_freq_table; r < P->n_freq_rows; r++, w++) {  /* W = W[parent] F^(sign n) */
        const int64_t *chain = P->freq_chain + 4 * r;
        const int64_t power = P->freq_zero[chain[1]] + chain[2];
        double br = wre[power], bi = (double)chain[3] * wim[power];
        double pr = wre[chain[0]], pi = wim[chain[0]];
        wre[w] = pr * br - pi * bi;
        wim[w] = pr * bi + pi * br;
    }
    for (int64_t r = 0, g = P->n_decay_table; r < P->n_decay_rows; r++, g++) {  /* D = D[parent] E^(sign n) */
        const int64_t *chain = P->decay_chain + 4 * r;
        D[g] = D[chain[0]] * D[P->decay_zero[chain[1]] + chain[3] * chain[2]];
    }
}

/* The items at s into the cache: by one product with the items at the step h where the cache allows it (W(s) =
   W(s - h) W(h), D(s) = D(s - h) D(h)), else directly, setting up the items at h at the second step of a size. */
static void cached_items(const OePiece *P, int64_t piece, double s, OeCache *C)
{
    double h = s - C->s, slack = OE_STEP_SLACK * 2.220446049250313e-16 * fabs(s);
    int same = C->piece == piece && h > 0.0;
    int64_t nw = P->n_freq_table + P->n_freq_rows, nd = P->n_decay_table + P->n_decay_rows;
    if (same && C->count >= 1 && C->count < OE_RESYNC && C->rotation_h > 0.0 && fabs(h - C->rotation_h) <= slack) {
        int64_t i = 0;
        for (; i + 1 < nw; i += 2) {  /* two items per SSE2 operation, the same IEEE operations as the tail's */
            v2 wr, wi, rr, ri;
            memcpy(&wr, C->wre + i, sizeof wr);
            memcpy(&wi, C->wim + i, sizeof wi);
            memcpy(&rr, C->rwre + i, sizeof rr);
            memcpy(&ri, C->rwim + i, sizeof ri);
            v2 re = wr * rr - wi * ri, im = wr * ri + wi * rr;
            memcpy(C->wre + i, &re, sizeof re);
            memcpy(C->wim + i, &im, sizeof im);
        }
        for (; i < nw; i++) {
            double r = C->wre[i] * C->rwre[i] - C->wim[i] * C->rwim[i];
            C->wim[i] = C->wre[i] * C->rwim[i] + C->wim[i] * C->rwre[i];
            C->wre[i] = r;
        }
        for (i = 0; i < nd; i++) C->D[i] *= C->rD[i];
        C->count++;
    } else {
        items(P, s, C->wre, C->wim, C->D, 0, NULL);
        if (!same) C->rotation_h = C->seen_h = 0.0;
        else if (!(C->rotation_h > 0.0 && fabs(h - C->rotation_h) <= slack)) {
            if (fabs(h - C->seen_h) <= slack) {  /* the second step of this size: the items at h */
                C->rotation_h = h;
                items(P, h, C->rwre, C->rwim, C->rD, 0, NULL);
            } else {
                C->rotation_h = 0.0;
                C->seen_h = h;
            }
        }
        C->count = 1;
    }
    C->piece = piece;
    C->s = s;
}

/* Whether every item of the piece is 1 or a base itself (no chain rows, no power above 1): the closed loop's
   reference (one forced response and one decaying free response) is such a piece. */
static int plain_items(const OePiece *P)
{
    if (P->n_freq_rows != 0 || P->n_decay_rows != 0) return 0;
    for (int64_t j = 0; j < P->n_freq_bases; j++)
        if (P->freq_top[j] > 1) return 0;
    for (int64_t j = 0; j < P->n_decay_bases; j++)
        if (P->decay_top[j] > 1 || P->decay_bottom[j] != 0) return 0;
    return 1;
}

/* items() of a plain_items piece: the same values (F^0 = 1, F^1 = F, E^0 = 1, E^1 = E), without the power and
   chain loops */
static void plain(const OePiece *P, double s, double *wre, double *wim, double *D, int64_t base, double *base_cos)
{
    for (int64_t j = 0; j < P->n_freq_bases; j++) {
        int64_t z = P->freq_zero[j];
        wre[z] = 1.0;
        wim[z] = 0.0;
        if (P->freq_top[j] > 0) sincos(P->freq_base[j] * s, &wim[z + 1], &wre[z + 1]);
        if (j == base && base_cos != NULL) *base_cos = P->freq_top[j] > 0 ? wre[z + 1] : cos(P->freq_base[j] * s);
    }
    for (int64_t j = 0; j < P->n_decay_bases; j++) {
        int64_t z = P->decay_zero[j];
        D[z] = 1.0;
        if (P->decay_top[j] > 0) D[z + 1] = exp(-P->decay_base[j] * s);
    }
}

static void piece_state(const OePiece *P, int64_t piece, double s, OeCache *cache, double *xva, int64_t base,
                        double *base_cos)
{
    double local_wre[OE_ITEMS], local_wim[OE_ITEMS], local_D[OE_ITEMS];
    const double *wre = local_wre, *wim = local_wim, *D = local_D;
    if (cache) {
        cached_items(P, piece, s, cache);
        wre = cache->wre;
        wim = cache->wim;
        D = cache->D;
    } else if (plain_items(P)) {
        plain(P, s, local_wre, local_wim, local_D, base, base_cos);
    } else {
        items(P, s, local_wre, local_wim, local_D, base, base_cos);
    }
    /* Re sum c W over each group, times its D (and s): (x, x') as a 2-vector (GCC/Clang vector extension: one
       SSE2 operation on x86-64) and x'' alone, even and odd terms in two chains of adds */
    v2 xv = {0.0, 0.0};
    double a = 0.0;
    const double *c = P->term_coefficient;
    int64_t k = 0;
    for (int64_t g = 0; g < P->n_groups; g++) {
        v2 xv0 = {0.0, 0.0}, xv1 = xv0;
        double a0 = 0.0, a1 = 0.0;
        int64_t end = P->group_end[g];
        for (; k + 1 < end; k += 2) {
            const double *c0 = c + 6 * k, *c1 = c0 + 6;
            int64_t w0 = P->term_freq[k], w1 = P->term_freq[k + 1];
            double r0 = wre[w0], i0 = wim[w0], r1 = wre[w1], i1 = wim[w1];
            v2 re0, im0, re1, im1;
            memcpy(&re0, c0, sizeof re0);
            memcpy(&im0, c0 + 2, sizeof im0);
            memcpy(&re1, c1, sizeof re1);
            memcpy(&im1, c1 + 2, sizeof im1);
            xv0 += re0 * r0 - im0 * i0;
            xv1 += re1 * r1 - im1 * i1;
            a0 += c0[4] * r0 - c0[5] * i0;
            a1 += c1[4] * r1 - c1[5] * i1;
        }
        if (k < end) {
            const double *c0 = c + 6 * k;
            int64_t w0 = P->term_freq[k];
            double r0 = wre[w0], i0 = wim[w0];
            v2 re0, im0;
            memcpy(&re0, c0, sizeof re0);
            memcpy(&im0, c0 + 2, sizeof im0);
            xv0 += re0 * r0 - im0 * i0;
            a0 += c0[4] * r0 - c0[5] * i0;
            k++;
        }
        double f = D[P->group_decay[g]];
        if (P->group_secular[g]) f *= s;
        xv += f * (xv0 + xv1);
        a += f * (a0 + a1);
    }
    xva[0] = xv[0];
    xva[1] = xv[1];
    xva[2] = a;
}

static int64_t piece_of(const OeSolution *S, double tau)
{
    int64_t i = 0;
    while (i + 1 < S->n_pieces && S->pieces[i + 1].start <= tau) i++;  /* oafm.AnalyticSolution._index */
    return i;
}

void vk_oafm_state(const OeSolution *S, double tau, double *xva)
{
    int64_t i = piece_of(S, tau);
    piece_state(&S->pieces[i], i, tau - S->pieces[i].start, NULL, xva, 0, NULL);
}

void vk_oafm_state_cos(const OeSolution *S, double tau, double *xva, int64_t base, double *base_cos)
{
    int64_t i = piece_of(S, tau);
    piece_state(&S->pieces[i], i, tau - S->pieces[i].start, NULL, xva, base, base_cos);
}

void vk_oafm_step(OeSolution *S, double tau, double *xva)
{
    int64_t i = piece_of(S, tau);
    piece_state(&S->pieces[i], i, tau - S->pieces[i].start, &S->cache, xva, 0, NULL);
}
