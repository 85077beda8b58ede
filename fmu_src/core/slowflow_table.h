/*
 * slowflow_table.h -- fidelity 3's set-up in C: the averaged slow flow integrated and tabulated as cubic Hermite
 * cells (vibromodel/slowflow.py, SlowFlowSolution.extend with the kernel; the table slowflow_eval.h reads).
 *
 * The slow flow A' = -mu/2 A - nu(r) B, B' = -mu/2 B + nu(r) A + drive, nu(r) = detuning - r^2 (kappa2 + kappa4 r^2),
 * r = (A^2 + B^2)^0.5 (averaging.SlowFlow.rhs), is integrated with the core's DOP853 (dop853.h: scipy's tableau and
 * dense output, the PI step controller of integrate.py) from (t_start, z0).  The grid's nodes t_start + spacing k,
 * k = 0..n, and midpoints node + spacing/2 are read from the dense output in time order, the steps never cut at a
 * node (so the steps do not depend on the grid).  Cell k holds the cubic Hermite coefficients of A and B in powers
 * of s in [0, 1] (a0..a3, b0..b3: Z_k, dZ_k, 3 (Z_k+1 - Z_k) - 2 dZ_k - dZ_k+1, 2 (Z_k - Z_k+1) + dZ_k + dZ_k+1, with
 * dZ = spacing Z'), as slowflow._hermite_cells computes them; its error is its value at s = 1/2 against the dense
 * output there.  spacing <= 0: the grid is refined as slowflow._refined_cells does, n = ceil(span) doubled until the
 * largest error <= rtol max|Z at the nodes| + atol (at most max_refinements grids); else the n cells of that spacing.
 */
#ifndef SLOWFLOW_TABLE_H
#define SLOWFLOW_TABLE_H

#include <stdint.h>

enum { SF_MU, SF_DETUNING, SF_DRIVE, SF_KAPPA2, SF_KAPPA4, SF_FLOW };  /* flow[] */
enum { ST_SPACING, ST_CELLS, ST_A_END, ST_B_END, ST_ERROR, ST_TOLERANCE, ST_STEPS, ST_OUTPUTS };  /* out[] */
enum { ST_OK = 0, ST_CAPACITY = 1, ST_FAILED = 2 };

/* Tabulate [t_start, t_start + span] into cells[8 k .. 8 k + 7] (room for `capacity` cells); Z at t_start + span into
   out[ST_A_END], out[ST_B_END].  ST_CAPACITY: the grid needs more than capacity cells (out[ST_CELLS] says how many);
   ST_FAILED: the integration failed (message, DOP_MESSAGE bytes). */
int vk_slowflow_tabulate(const double *flow, double t_start, const double *z0, double span, double rtol, double atol,
                         double max_step, double spacing, int64_t n, int64_t max_refinements, int64_t capacity,
                         double *cells, double *out, char *message);

/* Fidelity 3's error estimate's samples (vibromodel.error_estimates.averaged_terms): x~, x~', x~'' of the table at
   n >= 2 times t0 + span i/(n - 1) (numpy.linspace's: i span/(n - 1), the last span itself), the residual
   R = accel(x~, x~') - x~'' of Eq. 3 (error_estimates.exact_accel: scene[] below) and e of e'' + mu e' + k1 e = R
   advanced exactly from sample to sample with R piecewise linear (error_estimates.linear_response: z_k+1 =
   step z_k + R_k phi1 + (R_k+1 - R_k) phi2, e = Im(z)/p; filter[] below).  The cosines and sines of omega t and
   Omega t advance by rotation, recomputed every SR_RESYNC samples (their drift, a few ulps per sample, stays below
   1e-13 of the amplitude; the estimate is published to 3 digits).  out[SR_PROPAGATED] = max|e|, out[SR_RESIDUAL]
   = max|R|.  Returns 0, or 1 when a time lies outside the table (nothing written). */
enum { SR_MU, SR_DELTA, SR_OMEGA, SR_ALPHA, SR_BETA, SR_GAMMA, SR_R, SR_BIG_OMEGA, SR_SCENE };  /* scene[] */
enum { SR_STEP, SR_PHI1 = 2, SR_PHI2 = 4, SR_P = 6, SR_FILTER };  /* filter[]: complex as (re, im) */
enum { SR_PROPAGATED, SR_RESIDUAL, SR_OUTPUTS };  /* out[] */
#define SR_RESYNC 16

int vk_slowflow_residual(const void *table, const double *scene, double t0, double span, int64_t n,
                         const double *filter, double *out);

#endif
