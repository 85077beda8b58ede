/*
 * closedloop.c -- the closed loop of closedloop.h.
 */
#include "closedloop.h"

#include <math.h>

/* AnalyticSolution._index: the last piece starting at or before tau (the first one before all) */
static int64_t piece_index(const VlReference *r, double tau)
{
    int64_t i = 0;
    while (i + 1 < r->n_pieces && r->start[i + 1] <= tau) i++;
    return i;
}

void vl_reference_state(const VlReference *r, double tau, double *xva)
{
    int64_t i = piece_index(r, tau);
    double s = tau - r->start[i];
    double sum[3] = {0.0, 0.0, 0.0};
    for (int64_t k = r->first[i]; k < r->first[i + 1]; k++) {
        double decay = exp(-r->sigma[k] * s), c = cos(r->nu[k] * s), sn = sin(r->nu[k] * s);
        double zr = decay * c, zi = decay * sn;
        if (r->secular[k]) {
            zr *= s;
            zi *= s;
        }
        for (int row = 0; row < 3; row++) sum[row] += zr * r->re[row * r->K + k] - zi * r->im[row * r->K + k];
    }
    xva[0] = sum[0];
    xva[1] = sum[1];
    xva[2] = sum[2];
}
