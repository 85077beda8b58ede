/* slowflow_table.c -- see slowflow_table.h. */
#include <math.h>
#include <string.h>

#include "dop853.h"
#include "slowflow_table.h"

/* averaging.SlowFlow.rhs */
static int slow_rhs(void *context, double t, const double *z, double *f)
{
    (void)t;
    const double *flow = context;
    double A = z[0], B = z[1];
    double r = pow(A * A + B * B, 0.5);
    double r2 = r * r;
    double nu = flow[SF_DETUNING] - r2 * (flow[SF_KAPPA2] + flow[SF_KAPPA4] * r2);
    double half_mu = 0.5 * flow[SF_MU];
    f[0] = -half_mu * A - nu * B;
    f[1] = -half_mu * B + nu * A + flow[SF_DRIVE];
    return 0;
}

/* Z at t >= the last point read: the steps advanced until they cover t, then the dense output */
static int value(Dop853 *s, double *flow, double t, double *z, DopReport *report)
{
    if (t > s->t) {
        int code = dop_advance(s, slow_rhs, flow, t, report);
        if (code) return code;
    }
    return dop_value_at(s, slow_rhs, flow, t, z, report);
}

/* One grid of n cells: cells (when room), the largest midpoint error, max|Z| at the nodes, Z at t_start + span */
static int grid(double *flow, double t_start, const double *z0, double span, double rtol, double atol,
                double max_step, double spacing, int64_t n, double *cells, double *error, double *largest,
                double *z_end, double *steps, DopReport *report)
{
    Dop853 s;
    memset(&s, 0, sizeof s);
    s.n = 2;
    s.rtol = rtol;
    s.atol = atol;
    s.max_step = max_step;
    s.step_budget = INFINITY;
    int code = dop_restart(&s, slow_rhs, flow, t_start, z0, report);
    if (code) return code;
    double t_end = t_start + span, z[2], dz[2], z_prev[2] = {0.0, 0.0}, dz_prev[2] = {0.0, 0.0}, mid[2] = {0.0, 0.0};
    int end_read = 0;
    *error = 0.0;
    *largest = 0.0;
    for (int64_t k = 0; k <= n; k++) {
        double node = t_start + spacing * (double)k;
        if (k == n && t_end <= node) {
            if ((code = value(&s, flow, t_end, z_end, report))) return code;
            end_read = 1;
        }
        if ((code = value(&s, flow, node, z, report))) return code;
        slow_rhs(flow, node, z, dz);
        for (int i = 0; i < 2; i++) {
            dz[i] *= spacing;
            double size = fabs(z[i]);
            if (size > *largest || isnan(size)) *largest = size;
        }
        if (k > 0) {
            double *cell = cells + 8 * (k - 1);
            for (int i = 0; i < 2; i++) {
                double c0 = z_prev[i], c1 = dz_prev[i];
                double c2 = 3 * (z[i] - z_prev[i]) - 2 * dz_prev[i] - dz[i];
                double c3 = 2 * (z_prev[i] - z[i]) + dz_prev[i] + dz[i];
                if (cell) {
                    cell[4 * i] = c0;
                    cell[4 * i + 1] = c1;
                    cell[4 * i + 2] = c2;
                    cell[4 * i + 3] = c3;
                }
                double miss = fabs(c0 + 0.5 * c1 + 0.25 * c2 + 0.125 * c3 - mid[i]);
                if (miss > *error || isnan(miss)) *error = miss;
            }
        }
        if (k < n && (code = value(&s, flow, node + 0.5 * spacing, mid, report))) return code;
        z_prev[0] = z[0], z_prev[1] = z[1], dz_prev[0] = dz[0], dz_prev[1] = dz[1];
    }
    if (!end_read && (code = value(&s, flow, t_end, z_end, report))) return code;
    *steps = (double)s.n_steps;
    return DOP_OK;
}

int vk_slowflow_tabulate(const double *flow_in, double t_start, const double *z0, double span, double rtol,
                         double atol, double max_step, double spacing, int64_t n, int64_t max_refinements,
                         int64_t capacity, double *cells, double *out, char *message)
{
    double flow[SF_FLOW], z_end[2] = {0.0, 0.0}, error = 0.0, largest = 0.0, steps = 0.0, tolerance = 0.0;
    memcpy(flow, flow_in, sizeof flow);
    DopReport report;
    memset(&report, 0, sizeof report);
    int refine = !(spacing > 0.0);
    if (refine) n = (int64_t)ceil(span);
    for (int64_t round = 0; round < (refine ? max_refinements : 1); round++) {
        if (refine) spacing = span / (double)n;
        out[ST_CELLS] = (double)n;
        if (n > capacity) return ST_CAPACITY;
        int code = grid(flow, t_start, z0, span, rtol, atol, max_step, spacing, n, cells, &error, &largest, z_end,
                        &steps, &report);
        if (code) {
            memcpy(message, report.message, DOP_MESSAGE);
            message[DOP_MESSAGE - 1] = '\0';
            return ST_FAILED;
        }
        tolerance = rtol * largest + atol;
        if (!refine || error <= tolerance) break;
        if (round + 1 < max_refinements) n *= 2;
    }
    out[ST_SPACING] = spacing;
    out[ST_A_END] = z_end[0];
    out[ST_B_END] = z_end[1];
    out[ST_ERROR] = error;
    out[ST_TOLERANCE] = tolerance;
    out[ST_STEPS] = steps;
    return ST_OK;
}
