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

typedef struct {
    double start;                      /* tau_0 of the piece */
    int64_t n_decay_bases, n_freq_bases;
    double decay_base[OE_BASES];       /* d_j: E_j = exp(-d_j s) */
    double freq_base[OE_BASES];        /* b_j: F_j = exp(i b_j s) */
    int64_t decay_top[OE_BASES];       /* largest |n| of E_j used (<= OE_POWERS - 1) */
    int64_t freq_top[OE_BASES];        /* largest |n| of F_j used */
    int64_t n_decays, n_freqs, n_groups;
    const int64_t *decay_power;        /* [n_decays][OE_BASES]: n_j of each distinct decay */
    const int64_t *freq_power;         /* [n_freqs][OE_BASES]: n_j of each distinct frequency */
    const int64_t *group_decay;        /* [n_groups]: the decay of the group's terms */
    const int64_t *group_secular;      /* [n_groups]: 1 if the group's terms carry the factor s */
    const int64_t *group_end;          /* [n_groups]: terms of group g are group_end[g-1] .. group_end[g]-1 */
    const int64_t *term_freq;          /* [n_terms]: the frequency of each term */
    const double *term_coefficient;    /* [n_terms][6]: Re, Im of c for x, x', x'' */
} OePiece;

typedef struct {
    int64_t n_pieces;
    const OePiece *pieces;             /* by start, ascending; times before the first start use the first */
} OeSolution;

/* (x, x', x'') at tau into xva[0..2]. */
void oe_state(const OeSolution *solution, double tau, double *xva);

#endif
