/*
 * slowflow_eval.h -- fidelity 3 at run time: one output of the averaged slow flow (vibromodel/slowflow.py).
 *
 * The slow flow (A, B) is tabulated at set-up (Python) as cubic Hermite cells on a uniform grid of spacing
 * g^-1 from t0: cell i holds a0..a3, b0..b3 with A(t) = a0 + s (a1 + s (a2 + s a3)), s = (t - t0) g - i in
 * [0, 1] (and the same for B); A' = g (a1 + s (2 a2 + 3 s a3)), A'' = g^2 (2 a2 + 6 s a3).
 * The reconstruction (docs/model.md, Averaging and slow flow, Eq. 46 for psi):
 *     p = A cos wt + B sin wt,  q = A sin wt - B cos wt,
 *     x = x_e + p + h (p^2 - q^2) - m (A^2 + B^2) + P sin Wt + Q cos 2Wt,
 * with h = k2/(6 k1), m = k2/(2 k1), P = -beta/W^2, Q = gamma/(4 W^2); v and a are its exact first and second
 * time derivatives.  The operations and their order are those of SlowFlowSolution.state/_reconstruct, so that
 * with IEEE doubles as written (no FMA contraction) C and Python give the same bits.
 */
#ifndef SLOWFLOW_EVAL_H
#define SLOWFLOW_EVAL_H

#include <stdint.h>

typedef struct {
    double t0, spacing;          /* grid origin and spacing */
    double omega, x_e, harmonic, mean_shift;
    double Omega, psi_sin, psi_cos;
    int64_t ac;                  /* psi present (beta or gamma != 0) */
    int64_t first;               /* cells dropped from the table's front (a bounded table, slowflow.WINDOW) */
    int64_t n_cells;             /* cells[8 (i - first) .. + 7] = a0..a3, b0..b3 of cell i */
    double t_end;                /* end of the table: later times need the table extended (Python) */
    const double *cells;
} SfTable;

/* (x, x', x'') at t into xva[0..2]; returns 0, or 1 when t is beyond the table's end or before its first cell
   (nothing written). */
int vk_slowflow_state(const SfTable *table, double t, double *xva);

#endif
