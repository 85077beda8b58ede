/*
 * closedloop.h -- plant + adaptive controller + reference as one system (vibromodel/closedloop.py), compiled.
 *
 * State y = (x, v, theta^[9]): x' = v, v' = the plant model's x'' (Eq. 3 or Eq. 7) with U the control law,
 * theta^' = the update law (controller.h), the reference x~ a sum of damped harmonics evaluated at every stage.
 * Per stage: reference, U and theta^' (controller.c), then the model's x''. do_step: pre-checks, the integrator
 * to t + h, outputs at t + h (x, v, x~, U, e1, e2, V, V' by the chain rule, the promised V', theta^).
 *
 * Layout: the constants (model, controller, reference pointer, settings) come first and are rebuilt from the
 * parameters; everything from `t` on is the state, and those bytes are the closed-loop FMU's model state.
 */
#ifndef VIBRO_CLOSEDLOOP_H
#define VIBRO_CLOSEDLOOP_H

#include <stddef.h>
#include <stdint.h>

#include "controller.h"

#define VL_DIM 11        /* x, v, theta^[9] */
#define VL_OUTPUTS 18    /* x, v, x_ref, U, e1, e2, V, V_rate, V_rate_promised, theta^[9] */

/* x~ as pieces of sums of damped harmonics (oafm.Piece._stack): on piece i, with s = tau - start[i],
   (x~, x~', x~'')_r = Re sum_k s^m_k e^((-sigma_k + i nu_k) s) (re[r][k] + i im[r][k]), k in [first[i], first[i+1]).
   A stand-in for the fidelity-4 evaluator, behind vl_reference_state. */
typedef struct {
    int64_t n_pieces;
    const double *start;     /* [n_pieces] */
    const int64_t *first;    /* [n_pieces + 1] */
    const double *sigma, *nu;/* [K] */
    const int64_t *secular;  /* [K]: m_k */
    const double *re, *im;   /* [3 * K]: row r at r * K */
    int64_t K;
} VlReference;

/* (x~, x~', x~'') at tau (AnalyticSolution.state). */
void vl_reference_state(const VlReference *r, double tau, double *xva);

#endif
