/*
 * oafm_eval.h -- fidelity 4 at run time: x~, x~', x~'' of the OAFM analytic solution (vibromodel/oafm.py).
 *
 * On a piece starting at tau_0 the solution is a closed form in the local time s = tau - tau_0,
 *     (x, x', x'')(s) = Re sum_k c_k s^m_k exp((-sigma_k + i nu_k) s),    m_k in {0, 1},
 * with one complex coefficient per output and term (oafm.Piece._stack).  Set-up (Python,
 * vibromodel/compiled_open_loop.py) writes every decay sigma_k and frequency nu_k as a small integer
 * combination of a few base rates, sigma = sum_j n_j d_j and nu = sum_j n_j b_j.  Per output this file
 * then calls exp once per decay base and cos, sin once per frequency base; every power E^n = e^(-n d s) and
 * F^n = e^(i n b s) follows by repeated multiplication (F^-n = conj F^n), every term's factor by multiplying
 * the powers of its combination (angle addition), with no exp/cos/sin per term.  The rounding error of a
 * term grows about linearly with the number of multiplications and with |n| times the base's phase b s
 * (vibromodel.compiled_open_loop.recurrence_error_bound states the bound the tests use).
 */
#ifndef OAFM_EVAL_H
#define OAFM_EVAL_H

#include <stdint.h>

#define OE_BASES 6        /* bases of each kind (decay, frequency) */
#define OE_POWERS 17      /* powers 0..16 of a base */
#define OE_ITEMS 256      /* decay items, frequency items */

typedef struct {
    double start;                      /* tau_0 of the piece */
    int64_t n_decay_bases, n_freq_bases;
    double decay_base[OE_BASES];       /* d_j: E_j = exp(-d_j s) */
    double freq_base[OE_BASES];        /* b_j: F_j = exp(i b_j s) */
    /* Items.  The decay items D[] start with each base's powers E_j^n, n = -decay_bottom[j] .. decay_top[j], at
       D[decay_zero[j] + n]; then come the products, one per chain row (parent, base, |power|, sign):
       D = D[parent] E_base^(sign |power|).  The frequency items W[] likewise: F_j^n for n = 0 .. freq_top[j] at
       W[freq_zero[j] + n], then the rows W = W[parent] F_base^(sign |power|), with F^-n = conj F^n.  A row's
       parent comes before it. */
    int64_t decay_top[OE_BASES], decay_bottom[OE_BASES], decay_zero[OE_BASES];
    int64_t freq_top[OE_BASES], freq_zero[OE_BASES];
    int64_t n_decay_table, n_decay_rows, n_freq_table, n_freq_rows;
    const int64_t *decay_chain;        /* [n_decay_rows][4] */
    const int64_t *freq_chain;         /* [n_freq_rows][4] */
    int64_t n_groups;
    const int64_t *group_decay;        /* [n_groups]: the decay item of the group's terms */
    const int64_t *group_secular;      /* [n_groups]: 1 if the group's terms carry the factor s */
    const int64_t *group_end;          /* [n_groups]: terms of group g are group_end[g-1] .. group_end[g]-1 */
    const int64_t *term_freq;          /* [n_terms]: the frequency item of each term */
    const double *term_coefficient;    /* [n_terms][6]: Re c of x, x', Im c of x, x', Re, Im c of x'' */
} OePiece;

/* Stepping through time with a constant step h (a host's communication steps), the items need no cos, sin, exp
   and no powers or chain rows at all: W(s + h) = W(s) W(h), D(s + h) = D(s) D(h) (angle addition in time, one
   product per item), with the items at h, W(h) and D(h), built once per step size.  Every OE_RESYNC-th step, at a
   new piece or step size, or after any other call, the items are evaluated directly again, so that rounding
   accumulates over fewer than OE_RESYNC products.  A step counts as "the same h" when it differs from it by at
   most OE_STEP_SLACK ulps of s (a host's times n h differ by such roundings); the phase this ignores is in the
   error bound of compiled_open_loop.py. */
#define OE_RESYNC 16
#define OE_STEP_SLACK 4.0

typedef struct {
    int64_t piece;                     /* the piece the items belong to; -1: none */
    int64_t count;                     /* steps since the items were evaluated directly (1 = just now) */
    double s;                          /* their local time */
    double rotation_h, seen_h;         /* the step of the rotations (0: none); the last step seen */
    double wre[OE_ITEMS], wim[OE_ITEMS], D[OE_ITEMS];     /* the items W and D at s */
    double rwre[OE_ITEMS], rwim[OE_ITEMS], rD[OE_ITEMS];  /* the same at h */
} OeCache;

typedef struct {
    int64_t n_pieces;
    const OePiece *pieces;             /* by start, ascending; times before the first start use the first */
    OeCache cache;                     /* vk_oafm_step's */
} OeSolution;

/* (x, x', x'') at tau into xva[0..2], every base evaluated directly (the cache is neither used nor changed). */
void vk_oafm_state(const OeSolution *solution, double tau, double *xva);
/* vk_oafm_state, and into *base_cos the cosine of frequency base `base` of the piece at tau, cos(b_base (tau - start)),
   as the evaluation computed it (sincos): for a caller that needs the same cosine (closedloop.c) */
void vk_oafm_state_cos(const OeSolution *solution, double tau, double *xva, int64_t base, double *base_cos);
/* The same for the next output of a run: the items by recurrence in time where the cache allows it. */
void vk_oafm_step(OeSolution *solution, double tau, double *xva);

#endif
